/* The step cache: what a network computes from inputs that stay the same over the denoising
 * steps of one view, computed once per view and reused (issue 21). Two things qualify: the
 * prompt's cross-attention K and V (to_k, to_v of the text tokens: the UNet's 16 and each
 * ControlNet's 7 cross-attentions in SD1.5) and a ControlNet's hint embedding (the control
 * image through controlnet_cond_embedding). Neither depends on the latent or the timestep.
 *
 * One cache serves one network and one fixed set of those inputs (encoder_hidden_states, and
 * the control image): its first complete forward records each result, in call order, into the
 * cache's memory; every later forward reads them back in the same order instead of computing
 * them. The results are those of the same ops on the same inputs, so outputs are bit-identical
 * to forwards without a cache. Sizing: a dry run (measuring arena) with a cache whose memory
 * is NULL counts the floats it needs (mx_unet_cache_floats, mx_controlnet_cache_floats); one
 * whose memory is NULL but marked recorded makes a dry run skip the cached work as a replaying
 * forward does (the FLOPs of a later step: mx_controlnet_flops, mx_unet_flops). */
#ifndef MX_STEP_CACHE_H
#define MX_STEP_CACHE_H

#include <stddef.h>

#include "../../runtime/status.h"

typedef struct mx_step_cache {
    float *mem;    /* backend memory of cap floats, or NULL while sizing */
    size_t cap;    /* floats */
    size_t cursor; /* floats handed out by the current forward (while sizing: the need so far) */
    int recorded;  /* 1 once a real forward recorded every slot: later forwards replay */
} mx_step_cache;

/* At the start of a forward (k may be NULL). */
void mx_step_cache_begin(mx_step_cache *k);
/* At its end: a real forward (not a dry run) that succeeded has recorded the cache. */
void mx_step_cache_end(mx_step_cache *k, int real_and_ok);
/* The next slot of n floats (64-byte aligned): returns 1 when *slot holds the recorded result,
 * 0 when the caller computes it into *slot (recording; while sizing *slot is `placeholder`), or
 * -1 with st filled when the cache is smaller than this forward needs. */
int mx_step_cache_slot(mx_step_cache *k, size_t n, float *placeholder, float **slot, mx_status *st);

#endif
