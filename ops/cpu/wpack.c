/* The packed-weight cache (wpack.h): an open-addressing table of keys and their panels. The
 * panels are cut one after the other from chunks of at least WPACK_CHUNK bytes, host blocks
 * advised to transparent huge pages (mx_host_block): a first call packs ~1.6 GB (bf16 UNet),
 * and one fault per 4 KiB page of it cost seconds of system time on the VMs measured (1.45 M
 * faults in a UNet bench). One 2 MiB page per entry instead would hold up to 2 MiB more per
 * entry (+700 MB for the SD1.5 set, measured); cut from shared chunks nothing is rounded but
 * the part of each chunk's last 2 MiB page past its last entry (a chunk's untouched rest is
 * never backed). */
#include "wpack.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "../../runtime/arena.h"

typedef struct {
    mx_wpack_key key;
    float *panels; /* NULL: an empty slot */
    size_t bytes;  /* the panels' size, as asked of mx_wpack_add */
} wpack_entry;

#define WPACK_CHUNK ((size_t)256 << 20)

typedef struct {
    char *base;
    size_t size, used;
} wpack_chunk;

struct mx_wpack {
    wpack_entry *slots;
    size_t cap, used; /* cap: a power of two, at least twice used */
    size_t bytes, extra, extra_budget; /* panels held; their excess over the weights (wpack.h) */
    int sources_mapped;
    wpack_chunk *chunks;
    int nchunks, chunk_cap;
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
    for (int i = 0; i < w->nchunks; i++) free(w->chunks[i].base);
    free(w->chunks);
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

const float *mx_wpack_find_sized(const mx_wpack *w, const mx_wpack_key *key, size_t *bytes) {
    const wpack_entry *e = slot_of(w->slots, w->cap, key);
    *bytes = e->panels ? e->bytes : 0;
    return e->panels;
}

size_t mx_wpack_slots(const mx_wpack *w) { return w ? w->cap : 0; }

const float *mx_wpack_slot(const mx_wpack *w, size_t i, mx_wpack_key *key, size_t *bytes) {
    const wpack_entry *e = &w->slots[i];
    if (e->panels) *key = e->key, *bytes = e->bytes;
    return e->panels;
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

/* A new chunk of at least `bytes`, or -1. */
static int add_chunk(mx_wpack *w, size_t bytes) {
    if (w->nchunks == w->chunk_cap) {
        int cap = w->chunk_cap ? 2 * w->chunk_cap : 16;
        wpack_chunk *c = realloc(w->chunks, (size_t)cap * sizeof *c);
        if (!c) return -1;
        w->chunks = c;
        w->chunk_cap = cap;
    }
    size_t size = bytes > WPACK_CHUNK ? bytes : WPACK_CHUNK; /* bytes: a multiple of 64 */
    char *p = mx_host_block(size);
    if (!p) return -1;
    w->chunks[w->nchunks++] = (wpack_chunk){.base = p, .size = size};
    return 0;
}

/* `bytes` (64-byte aligned) cut from the first chunk with room, or from a new one. */
static float *take_panels(mx_wpack *w, size_t bytes) {
    bytes = (bytes + 63) / 64 * 64;
    wpack_chunk *c = NULL;
    for (int i = 0; i < w->nchunks && !c; i++)
        if (w->chunks[i].size - w->chunks[i].used >= bytes) c = &w->chunks[i];
    if (!c) {
        if (add_chunk(w, bytes)) return NULL;
        c = &w->chunks[w->nchunks - 1];
    }
    float *p = (float *)(void *)(c->base + c->used);
    c->used += bytes;
    return p;
}

float *mx_wpack_add(mx_wpack *w, const mx_wpack_key *key, size_t bytes, size_t panel_elem, size_t source_elem,
                    size_t grown) {
    size_t elems = bytes / panel_elem, own = elems > grown ? elems - grown : 0;
    size_t extra = (panel_elem > source_elem ? own * (panel_elem - source_elem) : 0) + grown * panel_elem;
    if (bytes == 0 || extra > w->extra_budget - w->extra) return NULL;
    if (2 * (w->used + 1) > w->cap && grow(w)) return NULL;
    wpack_entry *e = slot_of(w->slots, w->cap, key);
    if (e->panels) return NULL; /* already there: the caller looks up first */
    float *p = take_panels(w, bytes);
    if (!p) return NULL;
    *e = (wpack_entry){.key = *key, .panels = p, .bytes = bytes};
    w->used++;
    w->bytes += bytes;
    w->extra += extra;
    return p;
}

/* The file's readahead of source[0 .. source_bytes), all of it at once: what the packers would
 * otherwise fault in a readahead window at a time, each fault waiting for its read (when the
 * file is not in the page cache: the first job after a boot, or evicted since). */
void mx_wpack_fetch_source(const mx_wpack *w, const void *source, size_t source_bytes) {
    if (!w->sources_mapped || source_bytes == 0) return;
    uintptr_t page = (uintptr_t)sysconf(_SC_PAGESIZE), lo = (uintptr_t)source / page * page;
    /* advice only: a failure changes nothing but the time the packers wait */
    (void)madvise((void *)lo, (uintptr_t)source + source_bytes - lo, MADV_WILLNEED);
}

/* MADV_DONTNEED, not MADV_PAGEOUT: both drop the pages from this process (its RSS), but PAGEOUT also
 * evicts them from the page cache, so that the next context or job (or the digest of its load) read
 * the whole file from the disk again (3.6 GB: 10.6 s on the VM measured, 0.34 GB/s), where
 * DONTNEED leaves them cached, clean pages the kernel reclaims first when memory runs short. */
void mx_wpack_release_source(const mx_wpack *w, const void *source, size_t source_bytes) {
    if (!w->sources_mapped) return;
    uintptr_t page = (uintptr_t)sysconf(_SC_PAGESIZE), lo = ((uintptr_t)source + page - 1) / page * page,
              hi = ((uintptr_t)source + source_bytes) / page * page;
    /* only whole pages of this weight: its neighbours may not be packed yet. Advice only: a
     * failure changes nothing but the memory held */
    if (hi > lo) (void)madvise((void *)lo, hi - lo, MADV_DONTNEED);
}

size_t mx_wpack_bytes(const mx_wpack *w) { return w ? w->bytes : 0; }

size_t mx_wpack_extra_bytes(const mx_wpack *w) { return w ? w->extra : 0; }
