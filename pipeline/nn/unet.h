/* UNet2DConditionModel (diffusers v0.35.2 semantics) for the Stable Diffusion 1.5 family.
 *
 * Use (from a weight file, through the registry: registry.h):
 *   mx_binder b;         mx_binder_wf(&b, wf, MX_NET_UNET ".", st);   (or mx_binder_st for safetensors)
 *   mx_unet *u;          mx_net_load_kind(MX_NET_UNET, (void **)&u, wf, NULL, &b, st);
 *                        (or, from a parsed config: mx_unet_load(&u, &cfg, &b, st))
 *   size_t bytes;        mx_unet_arena_bytes(u, B, H, W, T, &bytes, st);
 *   mx_arena a;          mx_arena_create(&a, bytes, st);
 *   mx_unet_forward(ctx, u, &in, out, &a, st);
 *   mx_unet_free(u); mx_binder_free(&b);
 * The binder must outlive the model (weights are not copied). Activations come from the
 * arena only; the forward restores the arena's mark before returning. */
#ifndef MX_UNET_H
#define MX_UNET_H

#include "../../ops/ops.h"
#include "ip_adapter.h"
#include "net_io.h"
#include "netcfg.h"
#include "params.h"
#include "step_cache.h"

/* Enough for layers_per_block <= 7 over 8 levels. */
#define MX_UNET_MAX_RES 64

typedef struct mx_unet mx_unet;

/* The inputs of one call. Batch B items; each item has its own timestep and its own encoder
 * hidden states (CFG runs [uncond, cond] as B = 2). H and W are the latent size and must be
 * multiples of 2^(nlevels-1) (8 for SD1.5). */
typedef struct mx_unet_input {
    const float *sample;                /* [B, in_channels, H, W] */
    const float *timesteps;             /* [B] (float; integer timesteps as floats) */
    const float *encoder_hidden_states; /* [B, T, cross_attention_dim] */
    int B, H, W, T;
    /* Optional ControlNet residuals (already scaled and summed over ControlNets by the
     * caller): down[i] has the shape of mx_unet_residual_shape(i); NULL arrays = none. */
    const float *const *down_residuals; /* mx_unet_num_residuals() pointers, or NULL */
    const float *mid_residual;          /* [B, C_last, H/2^(L-1), W/2^(L-1)] or NULL */
    /* Optional image guidance (IP-Adapter, ip_adapter.h): each item's image tokens
     * ip_tokens [B, ip_n, cross_attention_dim]; every cross-attention adds ip_scale ·
     * attention(q, to_k_ip(tokens), to_v_ip(tokens)). A NULL adapter, ip_n 0 or ip_scale 0 is the
     * plain UNet, bit for bit (the branch is skipped, not multiplied by 0). */
    const mx_ip_adapter *ip;
    const float *ip_tokens;
    int ip_n;
    float ip_scale;
    /* 1 when B is 2 and both items have the same sample and timestep (CFG's batch of one latent):
     * the layers before the first cross-attention then compute one item and copy it, the same
     * result with ~2.5 % fewer FLOPs (an SD1.5 UNet at 64×64). */
    int halves_equal;
} mx_unet_input;

/* Binds every parameter (names as diffusers' state dict). With an enumerating binder it only
 * records the parameter list (the model is still returned; do not run it). */
int mx_unet_load(mx_unet **out, const mx_unet_config *cfg, mx_binder *b, mx_status *st);
void mx_unet_free(mx_unet *u);
const mx_unet_config *mx_unet_cfg(const mx_unet *u);

/* Down-block residual count (12 for SD1.5) and the shape [C, h, w] of residual i (i == count:
 * the mid-block residual) for a latent of H×W. Shared by UNet and ControlNet. */
int mx_unet_num_residuals(const mx_unet_config *cfg);
void mx_unet_residual_shape(const mx_unet_config *cfg, int i, int H, int W, int *C, int *h, int *w);

/* Checks batch, latent size and context length against a UNet/ControlNet config (latent a
 * multiple of 2^(levels-1), sizes within int range); the message says what is wrong. */
int mx_unet_check_sizes(const mx_unet_config *cfg, int B, int H, int W, int T, mx_status *st);

/* Arena bytes a forward with these sizes needs (dry run), without image guidance; with it, the
 * dry run of the call `in` (its sizes and adapter; its pointers are not read). */
int mx_unet_arena_bytes(const mx_unet *u, int B, int H, int W, int T, size_t *bytes, mx_status *st);
int mx_unet_call_arena_bytes(const mx_unet *u, const mx_unet_input *in, size_t *bytes, mx_status *st);
/* Floats of a step cache for forwards of these sizes (dry run). */
int mx_unet_cache_floats(const mx_unet *u, int B, int H, int W, int T, size_t *floats, mx_status *st);
/* Whether the adapter fits this UNet: one to_k_ip/to_v_ip pair per cross-attention layer, of its
 * width, over its cross_attention_dim. The message says what differs. */
int mx_unet_check_ip(const mx_unet *u, const mx_ip_adapter *ad, mx_status *st);
/* out: [B, out_channels, H, W] (caller's buffer). Fails with a message on bad sizes or when
 * the arena is too small. With a measuring arena (mx_arena_measure) nothing is computed. */
int mx_unet_forward(const mx_ctx *c, const mx_unet *u, const mx_unet_input *in, float *out, mx_arena *a,
                    mx_status *st);
/* The same with a step cache (step_cache.h) for in's encoder_hidden_states: the cross-attention
 * K/V are computed by its first forward and reused by the next (NULL: mx_unet_forward). */
int mx_unet_forward_cached(const mx_ctx *c, const mx_unet *u, const mx_unet_input *in, mx_step_cache *cache,
                           float *out, mx_arena *a, mx_status *st);
/* How the call of mx_unet_flops / mx_controlnet_flops runs: a later step of a view, whose step
 * cache replays what is constant over the steps (step_cache.h), and/or CFG's batch of one latent
 * (halves_equal). */
enum { MX_FLOPS_REPLAYED = 1, MX_FLOPS_HALVES_EQUAL = 2 };
/* Multiply-add count ×2 of one forward (for benchmarks); how: MX_FLOPS_* flags. */
double mx_unet_flops(const mx_unet *u, int B, int H, int W, int T, int how);

/* The registry's entry points (registry.h): config parse + load, the run-net adapter and its slots. */
int mx_unet_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st);
int mx_unet_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_unet_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
/* Appends the residual slots of cfg (down_block_res_sample.{i}, then mid_block_res_sample) to s. */
int mx_unet_residual_slots(const mx_unet_config *cfg, int flags, mx_net_slots *s, mx_status *st);
/* run-net unet's slots (registry.h): the static table, and the residuals after it. */
extern const mx_net_slot mx_unet_slots[];
int mx_unet_more_slots(const void *net, mx_net_slots *s, mx_status *st);

#endif
