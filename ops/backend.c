/* The CPU backends and the backend factory.
 *
 * cpu: activations in host memory, the cpuid-chosen kernel table.
 * cpu-strict: the same kernels, but every allocation is its own anonymous mapping that is
 * PROT_NONE except while one of the backend's kernels (or an upload/download) runs, so any
 * read or write of an activation from outside the op layer ends in SIGSEGV. Made for tests:
 * each op pays two mprotect calls per live allocation. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "ops.h"

#ifdef MX_WITH_CUDA
int mx_cuda_backend_create(mx_backend **out, mx_status *st); /* ops/cuda/cuda_backend.cu */
#endif

/* ---- cpu ---- */

static void *host_alloc(mx_backend *be, size_t bytes, mx_status *st) {
    (void)be;
    size_t n = (bytes + MX_ARENA_ALIGN - 1) / MX_ARENA_ALIGN * MX_ARENA_ALIGN;
    void *p = n >= bytes ? aligned_alloc(MX_ARENA_ALIGN, n ? n : MX_ARENA_ALIGN) : NULL;
    if (!p) mx_fail(st, MX_ENOMEM, "out of memory (%zu bytes)", bytes);
    return p;
}

static void host_release(mx_backend *be, void *p) {
    (void)be;
    free(p);
}

static int host_copy(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    (void)be;
    (void)st;
    if (bytes) memcpy(dst, src, bytes);
    return 0;
}

static void plain_destroy(mx_backend *be) { free(be); }

/* ---- cpu-strict ---- */

typedef struct strict_map {
    void *p;
    size_t bytes;
} strict_map;

typedef struct strict_state {
    strict_map *maps;
    size_t n, cap;
    int depth; /* nesting of enter/leave: the memory is open while depth > 0 */
} strict_state;

static void strict_protect(strict_state *s, int prot) {
    for (size_t i = 0; i < s->n; i++)
        if (mprotect(s->maps[i].p, s->maps[i].bytes, prot) != 0) abort(); /* cannot keep the guarantee */
}

static void strict_enter(mx_backend *be) {
    strict_state *s = be->impl;
    if (s->depth++ == 0) strict_protect(s, PROT_READ | PROT_WRITE);
}

static void strict_leave(mx_backend *be) {
    strict_state *s = be->impl;
    if (--s->depth == 0) strict_protect(s, PROT_NONE);
}

static void *strict_alloc(mx_backend *be, size_t bytes, mx_status *st) {
    strict_state *s = be->impl;
    if (s->n == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 64;
        strict_map *m = realloc(s->maps, cap * sizeof *m);
        if (!m) {
            mx_fail(st, MX_ENOMEM, "cpu-strict: out of memory");
            return NULL;
        }
        s->maps = m;
        s->cap = cap;
    }
    size_t n = bytes ? bytes : 1;
    void *p = mmap(NULL, n, s->depth > 0 ? PROT_READ | PROT_WRITE : PROT_NONE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) {
        mx_fail(st, MX_ENOMEM, "cpu-strict: cannot map %zu bytes", bytes);
        return NULL;
    }
    s->maps[s->n].p = p;
    s->maps[s->n++].bytes = n;
    return p;
}

static void strict_release(mx_backend *be, void *p) {
    strict_state *s = be->impl;
    for (size_t i = 0; i < s->n; i++)
        if (s->maps[i].p == p) {
            munmap(p, s->maps[i].bytes);
            s->maps[i] = s->maps[--s->n];
            return;
        }
}

static int strict_copy(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    strict_enter(be);
    host_copy(be, dst, src, bytes, st);
    strict_leave(be);
    return 0;
}

static void strict_destroy(mx_backend *be) {
    strict_state *s = be->impl;
    for (size_t i = 0; i < s->n; i++) munmap(s->maps[i].p, s->maps[i].bytes);
    free(s->maps);
    free(s);
    free(be);
}

/* ---- factory ---- */

static int cpu_backend_create(mx_backend **out, mx_backend_kind kind, mx_isa isa, mx_status *st) {
    mx_backend *be = calloc(1, sizeof *be);
    if (!be) return mx_fail(st, MX_ENOMEM, "backend: out of memory");
    be->kind = kind;
    be->k = mx_kernels_for(isa);
    be->host_visible = 1;
    be->alloc = host_alloc;
    be->release = host_release;
    be->to_device = host_copy;
    be->to_host = host_copy;
    be->destroy = plain_destroy;
    if (kind == MX_BACKEND_CPU_STRICT) {
        if (!(be->impl = calloc(1, sizeof(strict_state)))) {
            free(be);
            return mx_fail(st, MX_ENOMEM, "backend: out of memory");
        }
        be->alloc = strict_alloc;
        be->release = strict_release;
        be->to_device = strict_copy;
        be->to_host = strict_copy;
        be->enter = strict_enter;
        be->leave = strict_leave;
        be->destroy = strict_destroy;
    }
    *out = be;
    return 0;
}

/* "cuda", or a CPU kind with its level: "cpu-strict (avx512)". */
static void backend_label(const mx_backend *be, char *buf, size_t cap) {
    if (be->kind == MX_BACKEND_CUDA)
        snprintf(buf, cap, "%s", mx_backend_name(be->kind));
    else
        snprintf(buf, cap, "%s (%s)", mx_backend_name(be->kind), mx_isa_name(be->k->isa));
}

/* Every backend's table is checked full here, so a missing kernel is one clear line at context
 * creation, never a NULL call in the middle of a run. */
int mx_backend_create(mx_backend **out, mx_backend_kind kind, mx_isa isa, mx_status *st) {
    *out = NULL;
    if (!mx_backend_compiled(kind))
        return mx_fail(st, MX_EUSAGE, "this matex was built without the %s backend (build it with `make %s`)",
                       mx_backend_name(kind), mx_backend_name(kind));
    int rc;
#ifdef MX_WITH_CUDA
    if (kind == MX_BACKEND_CUDA)
        rc = mx_cuda_backend_create(out, st);
    else
#endif
        rc = cpu_backend_create(out, kind, isa, st);
    if (rc) return rc;
    char name[64];
    backend_label(*out, name, sizeof name);
    if (mx_kernels_check((*out)->k, name, st)) {
        mx_backend_destroy(*out);
        *out = NULL;
        return -1;
    }
    return 0;
}

void mx_backend_destroy(mx_backend *be) {
    if (be) be->destroy(be);
}
