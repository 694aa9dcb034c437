/* A context's weights packed once (issue 25): the GEMM engine (gemm.c) keeps the panels it
 * packs from a weight operand (conv2d's A, linear's B) here, keyed by the weight and by how it
 * was packed, and reuses them on every later call instead of widening and repacking the
 * weights each time. Owned by the context that enabled it (mx_ctx_pack_weights); used by the
 * thread that calls the ops. Entries are never freed before the cache: the weights must stay
 * unchanged at their addresses while the context lives.
 * Memory: the panels replace their weight (with sources_mapped, the weights being pages of a
 * read-only file mapping, a weight's pages are dropped from the process once packed,
 * MADV_DONTNEED: they stay in the page cache for the next job, read back if ever needed), so
 * what counts is what widening adds: bf16 pairs of fp16 weights add nothing, fp32 panels of fp16 weights one more
 * weight (the panels' edge padding, ~1 %, is not counted). That excess, summed over the entries,
 * stays within `extra_budget` bytes; a weight past it is packed per call as without a cache. */
#ifndef MX_OPS_CPU_WPACK_H
#define MX_OPS_CPU_WPACK_H

#include <stddef.h>

#include "../../runtime/status.h"

typedef struct mx_wpack mx_wpack;

/* What identifies packed panels: the weight and every input of its packing. */
typedef struct mx_wpack_key {
    const void *data;   /* the weight's first element */
    int dtype;          /* its stored type */
    const void *packer; /* the pack function */
    const void *kernel; /* the micro-kernel's description (its panel format) */
    int rows, K;        /* rows packed into panels, and the length of the sums */
    size_t ld;          /* the weight's row stride, in elements */
} mx_wpack_key;

int mx_wpack_create(mx_wpack **out, size_t extra_budget, int sources_mapped, mx_status *st);
void mx_wpack_destroy(mx_wpack *w);

/* The panels stored under key, or NULL. */
const float *mx_wpack_find(const mx_wpack *w, const mx_wpack_key *key);
/* A new entry of `bytes` (64-byte aligned) under key, for the caller to fill at once, of panels
 * whose elements take panel_elem bytes from weights whose elements take source_elem, `grown` of
 * them beyond the weight's own (conv2d_up2x's phase kernels: 16 for every 9 weights; counted in
 * full); NULL when its excess would pass the budget or no memory could be had (the caller packs
 * per call then). */
float *mx_wpack_add(mx_wpack *w, const mx_wpack_key *key, size_t bytes, size_t panel_elem, size_t source_elem,
                    size_t grown);
/* Called before an entry is filled from source[0 .. source_bytes): starts reading the source's
 * pages from the file in one go when the weights are mapped from a file. */
void mx_wpack_fetch_source(const mx_wpack *w, const void *source, size_t source_bytes);
/* Called once an entry is filled from source[0 .. source_bytes): drops the source's whole pages
 * from the process (not from the page cache) when the weights are mapped from a file. */
void mx_wpack_release_source(const mx_wpack *w, const void *source, size_t source_bytes);
/* The entries, for tests that compare two caches: slot i (i < mx_wpack_slots) holds an entry when
 * this returns its panels (NULL: an empty slot), its key then in *key and its size in *bytes. */
size_t mx_wpack_slots(const mx_wpack *w);
const float *mx_wpack_slot(const mx_wpack *w, size_t i, mx_wpack_key *key, size_t *bytes);
/* The panels stored under key and their size in *bytes, or NULL. */
const float *mx_wpack_find_sized(const mx_wpack *w, const mx_wpack_key *key, size_t *bytes);
/* Bytes of panels held, and their excess over the weights they replace (for reports and tests). */
size_t mx_wpack_bytes(const mx_wpack *w);
size_t mx_wpack_extra_bytes(const mx_wpack *w);

#endif
