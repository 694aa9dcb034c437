#include "arena.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

static size_t round_up(size_t n) { return (n + MX_ARENA_ALIGN - 1) & ~(size_t)(MX_ARENA_ALIGN - 1); }

void *mx_host_block(size_t n) {
    const uintptr_t huge = (uintptr_t)2 << 20;
    void *p = aligned_alloc(MX_ARENA_ALIGN, n);
#ifdef MADV_HUGEPAGE
    uintptr_t lo = ((uintptr_t)p + huge - 1) & ~(huge - 1), hi = ((uintptr_t)p + n) & ~(huge - 1);
    if (p && n >= 4 * huge && hi > lo) (void)madvise((void *)lo, hi - lo, MADV_HUGEPAGE); /* advice only */
#endif
    return p;
}

int mx_arena_create(mx_arena *a, size_t cap, mx_status *st) { return mx_arena_create_on(a, NULL, cap, st); }

int mx_arena_create_on(mx_arena *a, mx_backend *be, size_t cap, mx_status *st) {
    memset(a, 0, sizeof *a);
    cap = round_up(cap ? cap : MX_ARENA_ALIGN);
    if (be) {
        a->base = be->alloc(be, cap, st);
        if (!a->base) return mx_fail_prefix(st, "arena");
        a->be = be;
        a->cap = cap;
        a->owns = 1;
        return 0;
    }
    a->base = mx_host_block(cap);
    if (!a->base) return mx_fail(st, MX_ENOMEM, "arena: cannot allocate %zu bytes", cap);
    a->cap = cap;
    a->owns = 1;
    return 0;
}

void mx_arena_measure(mx_arena *a) {
    memset(a, 0, sizeof *a);
    a->measuring = 1;
}

void mx_arena_destroy(mx_arena *a) {
    if (a->owns && a->be)
        a->be->release(a->be, a->base);
    else if (a->owns)
        free(a->base);
    memset(a, 0, sizeof *a);
}

void *mx_arena_alloc(mx_arena *a, size_t bytes, mx_status *st) {
    size_t n = round_up(bytes ? bytes : 1);
    if (n < bytes) {
        mx_fail(st, MX_ENOMEM, "arena: allocation of %zu bytes overflows", bytes);
        return NULL;
    }
    if (a->measuring) {
        a->used += n;
        if (a->used > a->peak) a->peak = a->used;
        return NULL;
    }
    if (n > a->cap - a->used) {
        mx_fail(st, MX_ENOMEM, "arena: out of memory (%zu bytes asked, %zu of %zu used)", bytes, a->used,
                a->cap);
        return NULL;
    }
    void *p = a->base + a->used;
    a->used += n;
    if (a->used > a->peak) a->peak = a->used;
    return p;
}

float *mx_arena_floats(mx_arena *a, size_t n, mx_status *st) {
    if (n > SIZE_MAX / sizeof(float)) {
        mx_fail(st, MX_ENOMEM, "arena: %zu floats overflow", n);
        return NULL;
    }
    return mx_arena_alloc(a, n * sizeof(float), st);
}

size_t mx_arena_mark(const mx_arena *a) { return a->used; }

void mx_arena_reset(mx_arena *a, size_t mark) {
    if (mark <= a->used) a->used = mark;
}
