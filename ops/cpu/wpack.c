/* The packed-weight cache (wpack.h): an open-addressing table of keys and their panels. */
#include "wpack.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

typedef struct {
    mx_wpack_key key;
    float *panels; /* NULL: an empty slot */
} wpack_entry;

struct mx_wpack {
    wpack_entry *slots;
    size_t cap, used; /* cap: a power of two, at least twice used */
    size_t bytes, extra, extra_budget; /* panels held; their excess over the weights (wpack.h) */
    int sources_mapped;
};

int mx_wpack_create(mx_wpack **out, size_t extra_budget, int sources_mapped, mx_status *st) {
    mx_wpack *w = calloc(1, sizeof *w);
    if (w) w->slots = calloc(64, sizeof *w->slots);
    if (!w || !w->slots) {
        free(w);
        return mx_fail(st, MX_ENOMEM, "packed-weight cache: out of memory");
    }
    w->cap = 64;
    w->extra_budget = extra_budget;
    w->sources_mapped = sources_mapped;
    *out = w;
    return 0;
}

void mx_wpack_destroy(mx_wpack *w) {
    if (!w) return;
    for (size_t i = 0; i < w->cap; i++) free(w->slots[i].panels);
    free(w->slots);
    free(w);
}

static int same_key(const mx_wpack_key *a, const mx_wpack_key *b) {
    return a->data == b->data && a->dtype == b->dtype && a->packer == b->packer && a->kernel == b->kernel &&
           a->rows == b->rows && a->K == b->K && a->ld == b->ld;
}

/* The weight's address mixed (its low bits are alignment zeros), with the packing's kernel. */
static size_t key_hash(const mx_wpack_key *k) {
    uint64_t h = (uint64_t)(uintptr_t)k->data ^ ((uint64_t)(uintptr_t)k->kernel << 17) ^ (uint64_t)k->rows;
    h ^= h >> 33;
    h *= 0xff51afd7ed558ccdull;
    h ^= h >> 33;
    return (size_t)h;
}

/* The slot holding key, or the empty slot where it would go. */
static wpack_entry *slot_of(const wpack_entry *slots, size_t cap, const mx_wpack_key *key) {
    size_t i = key_hash(key) & (cap - 1);
    while (slots[i].panels && !same_key(&slots[i].key, key)) i = (i + 1) & (cap - 1);
    return (wpack_entry *)&slots[i];
}

const float *mx_wpack_find(const mx_wpack *w, const mx_wpack_key *key) {
    return slot_of(w->slots, w->cap, key)->panels;
}

static int grow(mx_wpack *w) {
    size_t cap = w->cap * 2;
    wpack_entry *slots = calloc(cap, sizeof *slots);
    if (!slots) return -1;
    for (size_t i = 0; i < w->cap; i++)
        if (w->slots[i].panels) *slot_of(slots, cap, &w->slots[i].key) = w->slots[i];
    free(w->slots);
    w->slots = slots;
    w->cap = cap;
    return 0;
}

float *mx_wpack_add(mx_wpack *w, const mx_wpack_key *key, size_t bytes, size_t panel_elem, size_t source_elem) {
    size_t extra = panel_elem > source_elem ? bytes / panel_elem * (panel_elem - source_elem) : 0;
    if (bytes == 0 || extra > w->extra_budget - w->extra) return NULL;
    if (2 * (w->used + 1) > w->cap && grow(w)) return NULL;
    wpack_entry *e = slot_of(w->slots, w->cap, key);
    if (e->panels) return NULL; /* already there: the caller looks up first */
    float *p = aligned_alloc(64, (bytes + 63) / 64 * 64);
    if (!p) return NULL;
    *e = (wpack_entry){.key = *key, .panels = p};
    w->used++;
    w->bytes += bytes;
    w->extra += extra;
    return p;
}

void mx_wpack_release_source(const mx_wpack *w, const void *source, size_t source_bytes) {
#ifdef MADV_PAGEOUT
    if (!w->sources_mapped) return;
    uintptr_t page = (uintptr_t)sysconf(_SC_PAGESIZE), lo = ((uintptr_t)source + page - 1) / page * page,
              hi = ((uintptr_t)source + source_bytes) / page * page;
    /* only whole pages of this weight: its neighbours may not be packed yet. Advice only: a
     * failure changes nothing but the memory held */
    if (hi > lo) (void)madvise((void *)lo, hi - lo, MADV_PAGEOUT);
#else
    (void)w;
    (void)source;
    (void)source_bytes;
#endif
}

size_t mx_wpack_bytes(const mx_wpack *w) { return w ? w->bytes : 0; }

size_t mx_wpack_extra_bytes(const mx_wpack *w) { return w ? w->extra : 0; }
