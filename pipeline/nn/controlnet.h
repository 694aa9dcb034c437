/* ControlNetModel (diffusers v0.35.2): the UNet's encoder half plus a conditioning-image
 * embedding and zero convolutions; returns the residuals the UNet adds to its skip
 * connections and mid block, already multiplied by the conditioning scale.
 * Loading/arena use as in unet.h (prefix "controlnet." or e.g. "controlnet_depth."). */
#ifndef MX_CONTROLNET_H
#define MX_CONTROLNET_H

#include "../../ops/ops.h"
#include "netcfg.h"
#include "params.h"
#include "unet.h"

typedef struct mx_controlnet mx_controlnet;

typedef struct mx_controlnet_input {
    const float *sample;                /* [B, in_channels, H, W] latent */
    const float *timesteps;             /* [B] */
    const float *encoder_hidden_states; /* [B, T, cross_attention_dim] */
    const float *cond;                  /* [B, conditioning_channels, 8H, 8W] control image
                                           (2^(len(cond_emb_channels)-1) × the latent size) */
    int B, H, W, T;
    float scale;                        /* conditioning scale */
    int halves_equal;                   /* as mx_unet_input's, cond included */
} mx_controlnet_input;

/* cfg must come from a ControlNetModel config (cfg->is_controlnet). */
int mx_controlnet_load(mx_controlnet **out, const mx_unet_config *cfg, mx_binder *b, mx_status *st);
void mx_controlnet_free(mx_controlnet *m);
const mx_unet_config *mx_controlnet_cfg(const mx_controlnet *m);

int mx_controlnet_arena_bytes(const mx_controlnet *m, int B, int H, int W, int T, size_t *bytes, mx_status *st);
/* Floats of a step cache for forwards of these sizes (dry run). */
int mx_controlnet_cache_floats(const mx_controlnet *m, int B, int H, int W, int T, size_t *floats, mx_status *st);
/* down[i] (i < mx_unet_num_residuals(cfg)) and mid are caller buffers of the shapes given by
 * mx_unet_residual_shape (times B). When `accumulate` is 1 the scaled residuals are ADDED to
 * the buffers (summing several ControlNets); 0 overwrites them. */
int mx_controlnet_forward(const mx_ctx *c, const mx_controlnet *m, const mx_controlnet_input *in, float *const *down,
                          float *mid, int accumulate, mx_arena *a, mx_status *st);
/* The same with a step cache (step_cache.h) for in's cond and encoder_hidden_states: the hint
 * embedding and the cross-attention K/V are computed by its first forward and reused by the next
 * (NULL: mx_controlnet_forward). */
int mx_controlnet_forward_cached(const mx_ctx *c, const mx_controlnet *m, const mx_controlnet_input *in,
                                 mx_step_cache *cache, float *const *down, float *mid, int accumulate, mx_arena *a,
                                 mx_status *st);
/* Multiply-add count ×2 of one forward (for benchmarks); how: MX_FLOPS_* (unet.h; a replayed
 * step cache holds the hint embedding and the prompt's K/V). */
double mx_controlnet_flops(const mx_controlnet *m, int B, int H, int W, int T, int how);

/* The registry's entry points (registry.h): config parse + load, the run-net adapter. */
int mx_controlnet_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                              mx_status *st);
int mx_controlnet_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_controlnet_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
/* Its slots (registry.h): the static table, and the residual outputs after it. */
extern const mx_net_slot mx_controlnet_slots[];
int mx_controlnet_more_slots(const void *net, mx_net_slots *s, mx_status *st);

#endif
