/* Building blocks shared by the UNet, the ControlNet and the VAE (diffusers v0.35.2):
 * convolution / linear / norm parameter groups, ResnetBlock2D, Transformer2DModel with
 * BasicTransformerBlock, Downsample2D / Upsample2D and the VAE's single-head attention.
 *
 * Every block has a load function (binds its parameters under a dotted path such as
 * "down_blocks.0.resnets.1") and a forward function that writes into a caller buffer and
 * takes its temporaries from the run's arena (restoring the mark). Forward code only calls
 * ops: in a dry run (measuring arena) the ops compute nothing (ops.h), so the same code
 * allocates exactly as for real. */
#ifndef MX_BLOCKS_H
#define MX_BLOCKS_H

#include "../../ops/ops.h"
#include "params.h"
#include "step_cache.h"

/* One forward pass: ops context (the measuring one in a dry run), activation arena, error
 * sink, FLOP counter. */
typedef struct mx_run {
    const mx_ctx *c;
    mx_ctx fp32; /* c computing in fp32 (mx_ctx_fp32): the layers precision.h keeps in fp32 */
    /* the context the run was given: c, unless the whole network runs in fp32 (mx_run_init_prec);
     * the layers precision.h computes in bf16 even there take it */
    const mx_ctx *given;
    mx_arena *a;
    mx_status *st;
    double flops;
    mx_step_cache *cache; /* NULL, or where results constant over the steps are kept (step_cache.h) */
    /* 1 while a batch of 2 holds two equal items: CFG's [uncond; cond] of one latent, which differ
     * only from the first cross-attention on. Until it, the layers compute item 0 alone
     * (mx_run_batch) and the first cross-attention copies it to item 1 (mx_run_share_out). */
    int shared;
} mx_run;

void mx_run_init(mx_run *r, const mx_ctx *c, mx_arena *a, mx_status *st);
/* The same, computing in fp32 throughout when net_fp32 (the network's mx_prec_net_fp32, read at
 * its load). */
void mx_run_init_prec(mx_run *r, int net_fp32, const mx_ctx *c, mx_arena *a, mx_status *st);
/* Activation floats from the run's arena (mx_act_alloc). NULL only on failure (st filled). */
float *mx_run_alloc(mx_run *r, size_t n);
/* The run's next step-cache slot of n floats: 1 when *slot holds the result already, 0 when the
 * caller computes it into *slot; *slot is NULL without a cache (compute into your own buffer);
 * -1 on error (st). */
int mx_run_cached(mx_run *r, size_t n, float **slot);
/* The items a layer computes of a batch of B: 1 while r->shared, else B. */
int mx_run_batch(const mx_run *r, int B);
/* Item 0 of x (items of `per` floats) copied to item 1: the end of the shared part. */
void mx_run_copy_item(mx_run *r, float *x, size_t per);

/* Where a convolution's precision comes from (precision.h): the run's context, fp32 always, or the
 * run's given context even inside a network that otherwise runs in fp32. */
typedef enum { MX_CONV_PREC_RUN, MX_CONV_PREC_FP32, MX_CONV_PREC_GIVEN } mx_conv_prec;
typedef struct { mx_wptr w, b; int cin, cout, k, stride, pad; mx_conv_prec prec; } mx_conv;
typedef struct { mx_wptr w, b; int in, out; } mx_lin;
typedef struct { mx_wptr g, b; int c, groups; float eps; } mx_gn;
typedef struct { mx_wptr g, b; int c; float eps; } mx_ln;

/* Binders for a parameter group at "<path>.weight" / "<path>.bias". */
int mx_conv_load(mx_conv *p, mx_binder *b, const char *path, int cin, int cout, int k, int stride, int pad,
                 int bias, mx_status *st);
int mx_lin_load(mx_lin *p, mx_binder *b, const char *path, int in, int out, int bias, mx_status *st);
int mx_gn_load(mx_gn *p, mx_binder *b, const char *path, int c, int groups, float eps, mx_status *st);
int mx_ln_load(mx_ln *p, mx_binder *b, const char *path, int c, float eps, mx_status *st);

/* Forward of the groups (no allocation). conv output size: the usual formula. */
void mx_conv_run(mx_run *r, const mx_conv *p, float *y, const float *x, int B, int H, int W);
/* A 3×3, stride 1, pad 1 conv p on the nearest 2× upsample of x [B, cin, H, W]: one op
 * (conv2d_up2x), the upsample never stored; y is [B, cout, 2H, 2W]. */
void mx_conv_up2x_run(mx_run *r, const mx_conv *p, float *y, const float *x, int B, int H, int W);
void mx_lin_run(mx_run *r, const mx_lin *p, float *y, const float *x, int M);
void mx_gn_run(mx_run *r, const mx_gn *p, float *y, const float *x, int B, int HW, int silu);
void mx_ln_run(mx_run *r, const mx_ln *p, float *y, const float *x, int M);
int mx_conv_out_size(const mx_conv *p, int n);

/* ResnetBlock2D, time_embedding_norm "default". temb_ch 0: no time embedding (VAE). */
typedef struct mx_resnet {
    mx_gn norm1, norm2;
    mx_conv conv1, conv2, shortcut;
    mx_lin temb_proj;
    int cin, cout, has_shortcut, has_temb;
    float out_scale; /* output_scale_factor */
} mx_resnet;
int mx_resnet_load(mx_resnet *p, mx_binder *b, const char *path, int cin, int cout, int temb_ch, int groups,
                   float eps, float out_scale, mx_status *st);
/* y[B, cout, H, W] = block(x[B, cin, H, W], temb_silu[B, temb_ch] = silu(time embedding) or NULL).
 * Its temporaries: B·cout·H·W floats, and B·cin·H·W more when cin > cout and x is kept. */
int mx_resnet_run(mx_run *r, const mx_resnet *p, float *y, const float *x, int B, int H, int W,
                  const float *temb_silu);
/* The same where x is not read afterwards: the block may write over it, and needs no second
 * temporary (the VAE decoder's widest resnets: 256 -> 128 channels at 512x512). */
int mx_resnet_run_spending_x(mx_run *r, const mx_resnet *p, float *y, float *x, int B, int H, int W,
                             const float *temb_silu);

/* BasicTransformerBlock: self-attention, cross-attention, GEGLU feed-forward, pre-LayerNorm. */
typedef struct mx_tblock {
    mx_ln norm1, norm2, norm3;
    mx_lin q1, k1, v1, o1, q2, k2, v2, o2, ff_in, ff_out;
    int dim, heads, ctx_dim, ff_dim;
    int ip_layer; /* its cross-attention's index among the UNet's (ip_adapter.h), set by the UNet */
} mx_tblock;

/* Image guidance of one forward (IP-Adapter, ip_adapter.h): every cross-attention adds
 * scale · attention(q, to_k_ip(tokens), to_v_ip(tokens)) to its text attention, before to_out
 * (diffusers IPAdapterAttnProcessor2_0). NULL: none (the plain block, no extra op). */
typedef struct mx_ip_guide {
    const mx_lin *k, *v;  /* to_k_ip, to_v_ip of each cross-attention layer, by mx_tblock.ip_layer */
    const float *tokens;  /* [B, n, ctx_dim] */
    int n;                /* image tokens per item */
    float scale;          /* non-zero */
} mx_ip_guide;

/* Transformer2DModel (continuous input): GroupNorm (eps 1e-6), proj_in (1×1 conv or linear),
 * transformer blocks, proj_out, residual. */
typedef struct mx_transformer {
    mx_gn norm;
    mx_conv proj_in_conv, proj_out_conv;
    mx_lin proj_in_lin, proj_out_lin;
    mx_tblock *blocks;
    int nblocks, channels, inner, heads, linear_proj;
} mx_transformer;
int mx_transformer_load(mx_transformer *p, mx_binder *b, const char *path, int channels, int heads, int layers,
                        int ctx_dim, int groups, int linear_proj, mx_status *st);
void mx_transformer_free(mx_transformer *p);
/* y[B, C, H, W] = transformer(x, context[B, T, ctx_dim]) with image guidance ip (may be NULL);
 * y may not alias x. */
int mx_transformer_run(mx_run *r, const mx_transformer *p, float *y, const float *x, int B, int H, int W,
                       const float *context, int T, const mx_ip_guide *ip);

/* VAE mid-block attention (one head over channels, GroupNorm, q/k/v/out with bias, residual). */
typedef struct mx_vae_attn {
    mx_gn norm;
    mx_lin q, k, v, o;
    int c;
} mx_vae_attn;
int mx_vae_attn_load(mx_vae_attn *p, mx_binder *b, const char *path, int c, int groups, float eps,
                     mx_status *st);
int mx_vae_attn_run(mx_run *r, const mx_vae_attn *p, float *y, const float *x, int B, int H, int W);

/* Downsample2D: 3×3 stride-2 conv; pad 0 means diffusers' asymmetric (0,1,0,1) zero pad. */
typedef struct { mx_conv conv; int asym_pad; } mx_down;
int mx_down_load(mx_down *p, mx_binder *b, const char *path, int c, int pad, mx_status *st);
int mx_down_run(mx_run *r, const mx_down *p, float *y, const float *x, int B, int H, int W);
/* Upsample2D: nearest 2× then 3×3 conv (one op, mx_conv_up2x_run). */
typedef struct { mx_conv conv; } mx_up;
int mx_up_load(mx_up *p, mx_binder *b, const char *path, int c, mx_status *st);
void mx_up_run(mx_run *r, const mx_up *p, float *y, const float *x, int B, int H, int W);

/* diffusers timestep path: time_proj (sinusoidal) -> linear_1 -> SiLU -> linear_2, then the
 * SiLU that every resnet's time_emb_proj applies (shared). */
typedef struct mx_time_embed {
    mx_lin l1, l2;
    int proj_dim, dim, flip;
    float shift;
} mx_time_embed;
int mx_time_embed_load(mx_time_embed *p, mx_binder *b, int proj_dim, int dim, int flip, float shift,
                       mx_status *st);
/* temb_silu[B, dim] = silu(time_embedding(time_proj(t))). */
int mx_time_embed_run(mx_run *r, const mx_time_embed *p, float *temb_silu, const float *t, int B);

#endif
