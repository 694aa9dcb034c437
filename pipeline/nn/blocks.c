/* Building blocks shared by UNet, ControlNet and VAE; semantics of diffusers v0.35.2
 * (resnet.py, attention.py, attention_processor.py, transformer_2d.py, embeddings.py). */
#include "blocks.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "precision.h"

void mx_run_init(mx_run *r, const mx_ctx *c, mx_arena *a, mx_status *st) {
    memset(r, 0, sizeof *r);
    r->c = mx_run_ctx(c, a);
    r->given = r->c;
    r->fp32 = mx_ctx_fp32(r->c);
    r->a = a;
    r->st = st;
}

void mx_run_init_prec(mx_run *r, int net_fp32, const mx_ctx *c, mx_arena *a, mx_status *st) {
    mx_run_init(r, c, a, st);
    if (net_fp32) r->c = &r->fp32;
}

float *mx_run_alloc(mx_run *r, size_t n) { return mx_act_alloc(r->a, n, r->st); }

int mx_run_cached(mx_run *r, size_t n, float **slot) {
    *slot = NULL;
    return r->cache ? mx_step_cache_slot(r->cache, n, mx_act_placeholder(), slot, r->st) : 0;
}

int mx_run_batch(const mx_run *r, int B) { return r->shared ? 1 : B; }

void mx_run_copy_item(mx_run *r, float *x, size_t per) { mx_copy(r->c, x + per, x, per); }

/* ---- parameter groups ---- */

static int path_join(char *buf, size_t cap, const char *path, const char *leaf, mx_status *st) {
    int n = snprintf(buf, cap, "%s.%s", path, leaf);
    if (n < 0 || (size_t)n >= cap) return mx_fail(st, MX_EINTERNAL, "parameter path too long: %s.%s", path, leaf);
    return 0;
}

static int bind_param(mx_binder *b, mx_wptr *out, const char *path, const char *leaf, int ndim, const int64_t *shape,
                      mx_status *st) {
    char name[256];
    if (path_join(name, sizeof name, path, leaf, st)) return -1;
    return b->bind(b, name, ndim, shape, out, st);
}

static int bind_vec(mx_binder *b, mx_wptr *out, const char *path, const char *leaf, int n, mx_status *st) {
    int64_t shape[1] = {n};
    return bind_param(b, out, path, leaf, 1, shape, st);
}

int mx_conv_load(mx_conv *p, mx_binder *b, const char *path, int cin, int cout, int k, int stride, int pad, int bias,
                 mx_status *st) {
    int64_t shape[4] = {cout, cin, k, k};
    p->cin = cin;
    p->cout = cout;
    p->k = k;
    p->stride = stride;
    p->pad = pad;
    p->prec = mx_prec_conv_fp32(path) ? MX_CONV_PREC_FP32 : MX_CONV_PREC_RUN;
    p->b = mx_w_none();
    if (bind_param(b, &p->w, path, "weight", 4, shape, st)) return -1;
    return bias ? bind_vec(b, &p->b, path, "bias", cout, st) : 0;
}

int mx_lin_load(mx_lin *p, mx_binder *b, const char *path, int in, int out, int bias, mx_status *st) {
    int64_t shape[2] = {out, in};
    p->in = in;
    p->out = out;
    p->b = mx_w_none();
    if (bind_param(b, &p->w, path, "weight", 2, shape, st)) return -1;
    return bias ? bind_vec(b, &p->b, path, "bias", out, st) : 0;
}

int mx_gn_load(mx_gn *p, mx_binder *b, const char *path, int c, int groups, float eps, mx_status *st) {
    if (groups <= 0 || c % groups)
        return mx_fail(st, MX_EINPUT, "%s: %d channels are not divisible into %d groups", path, c, groups);
    p->c = c;
    p->groups = groups;
    p->eps = eps;
    if (bind_vec(b, &p->g, path, "weight", c, st)) return -1;
    return bind_vec(b, &p->b, path, "bias", c, st);
}

int mx_ln_load(mx_ln *p, mx_binder *b, const char *path, int c, float eps, mx_status *st) {
    p->c = c;
    p->eps = eps;
    if (bind_vec(b, &p->g, path, "weight", c, st)) return -1;
    return bind_vec(b, &p->b, path, "bias", c, st);
}

int mx_conv_out_size(const mx_conv *p, int n) { return (n + 2 * p->pad - p->k) / p->stride + 1; }

/* The context a conv computes in: fp32, the one given to it, or the run's (its precision). */
static const mx_ctx *conv_ctx(mx_run *r, const mx_conv *p) {
    return p->prec == MX_CONV_PREC_FP32 ? &r->fp32 : p->prec == MX_CONV_PREC_GIVEN ? r->given : r->c;
}

void mx_conv_run(mx_run *r, const mx_conv *p, float *y, const float *x, int B, int H, int W) {
    int Ho = mx_conv_out_size(p, H), Wo = mx_conv_out_size(p, W);
    r->flops += mx_conv2d_flops(B, p->cin, Ho, Wo, p->cout, p->k, p->k);
    mx_conv2d(conv_ctx(r, p), y, x, B, p->cin, H, W, p->w, p->b, p->cout, p->k, p->k, p->stride, p->pad);
}

void mx_conv_up2x_run(mx_run *r, const mx_conv *p, float *y, const float *x, int B, int H, int W) {
    r->flops += mx_conv2d_up2x_flops(B, p->cin, H, W, p->cout);
    mx_conv2d_up2x(conv_ctx(r, p), y, x, B, p->cin, H, W, p->w, p->b, p->cout);
}

void mx_lin_run(mx_run *r, const mx_lin *p, float *y, const float *x, int M) {
    r->flops += mx_linear_flops(M, p->out, p->in);
    mx_linear(r->c, y, x, p->w, p->b, M, p->out, p->in);
}

void mx_gn_run(mx_run *r, const mx_gn *p, float *y, const float *x, int B, int HW, int silu) {
    mx_group_norm(r->c, y, x, B, p->c, HW, p->groups, p->g, p->b, p->eps, silu);
}

void mx_ln_run(mx_run *r, const mx_ln *p, float *y, const float *x, int M) {
    mx_layer_norm(r->c, y, x, M, p->c, p->g, p->b, p->eps);
}

static void run_add(mx_run *r, float *y, const float *a, const float *b, size_t n) { mx_add(r->c, y, a, b, n); }

static void run_attention(mx_run *r, float *out, const float *q, const float *k, const float *v, int B, int heads,
                          int Tq, int Tk, int D, int qs, int kvs, int os) {
    r->flops += mx_attention_flops(B, heads, Tq, Tk, D);
    mx_attention(r->c, out, q, k, v, B, heads, Tq, Tk, D, qs, kvs, os, 0, (float)(1.0 / sqrt((double)D)));
}

/* ---- ResnetBlock2D ---- */

int mx_resnet_load(mx_resnet *p, mx_binder *b, const char *path, int cin, int cout, int temb_ch, int groups, float eps,
                   float out_scale, mx_status *st) {
    char sub[256];
    memset(p, 0, sizeof *p);
    p->cin = cin;
    p->cout = cout;
    p->out_scale = out_scale;
    p->has_temb = temb_ch > 0;
    p->has_shortcut = cin != cout;
    if (path_join(sub, sizeof sub, path, "norm1", st) || mx_gn_load(&p->norm1, b, sub, cin, groups, eps, st)) return -1;
    if (path_join(sub, sizeof sub, path, "conv1", st) || mx_conv_load(&p->conv1, b, sub, cin, cout, 3, 1, 1, 1, st))
        return -1;
    if (p->has_temb && (path_join(sub, sizeof sub, path, "time_emb_proj", st) ||
                        mx_lin_load(&p->temb_proj, b, sub, temb_ch, cout, 1, st)))
        return -1;
    if (path_join(sub, sizeof sub, path, "norm2", st) || mx_gn_load(&p->norm2, b, sub, cout, groups, eps, st)) return -1;
    if (path_join(sub, sizeof sub, path, "conv2", st) || mx_conv_load(&p->conv2, b, sub, cout, cout, 3, 1, 1, 1, st))
        return -1;
    if (p->has_shortcut && (path_join(sub, sizeof sub, path, "conv_shortcut", st) ||
                            mx_conv_load(&p->shortcut, b, sub, cin, cout, 1, 1, 0, 1, st)))
        return -1;
    return 0;
}

/* The block in diffusers' order with one temporary h of cout channels: norm1's output goes to y
 * while y is free (cin <= cout), or over x when x may be spent (the shortcut then reads x first,
 * into y, and conv2 writes over x); only a kept x wider than y needs a second temporary. Each op
 * gets the values it gets in diffusers' order and the sum is skip + conv2 either way, so the plan
 * never changes the result. */
static int resnet_run(mx_run *r, const mx_resnet *p, float *y, const float *x, float *spent_x, int B, int H, int W,
                      const float *temb_silu) {
    size_t mark = mx_arena_mark(r->a);
    size_t HW = (size_t)H * W, n = (size_t)B * p->cout * HW;
    int over_x = spent_x && p->cin > p->cout;
    float *h = mx_run_alloc(r, n);
    float *t = p->cin <= p->cout ? y : over_x ? spent_x : mx_run_alloc(r, (size_t)B * p->cin * HW);
    if (!h || !t) return -1;
    if (over_x) mx_conv_run(r, &p->shortcut, y, x, B, H, W); /* cin != cout: there is a shortcut */
    mx_gn_run(r, &p->norm1, t, x, B, (int)HW, 1);
    mx_conv_run(r, &p->conv1, h, t, B, H, W);
    if (p->has_temb) {
        float *tp = mx_run_alloc(r, (size_t)B * p->cout);
        if (!tp) return -1;
        mx_lin_run(r, &p->temb_proj, tp, temb_silu, B);
        int64_t hs[3] = {B, p->cout, (int64_t)HW}, ts[3] = {B, p->cout, 1};
        mx_binary(r->c, MX_BIN_ADD, h, h, hs, tp, ts, 3);
    }
    mx_gn_run(r, &p->norm2, h, h, B, (int)HW, 1);
    if (over_x) {
        mx_conv_run(r, &p->conv2, spent_x, h, B, H, W);
        run_add(r, y, y, spent_x, n);
    } else {
        mx_conv_run(r, &p->conv2, y, h, B, H, W);
        const float *skip = x;
        if (p->has_shortcut) {
            mx_conv_run(r, &p->shortcut, h, x, B, H, W);
            skip = h;
        }
        run_add(r, y, y, skip, n); /* conv2 + skip: the same sum as skip + conv2 */
    }
    if (p->out_scale != 1.0f) mx_scale(r->c, y, y, 1.0f / p->out_scale, n);
    mx_arena_reset(r->a, mark);
    return 0;
}

int mx_resnet_run(mx_run *r, const mx_resnet *p, float *y, const float *x, int B, int H, int W,
                  const float *temb_silu) {
    return resnet_run(r, p, y, x, NULL, B, H, W, temb_silu);
}

int mx_resnet_run_spending_x(mx_run *r, const mx_resnet *p, float *y, float *x, int B, int H, int W,
                             const float *temb_silu) {
    return resnet_run(r, p, y, x, x, B, H, W, temb_silu);
}

/* ---- Transformer2DModel / BasicTransformerBlock ---- */

static int attn_load(mx_lin *q, mx_lin *k, mx_lin *v, mx_lin *o, mx_binder *b, const char *path, int dim, int kv_dim,
                     int qkv_bias, mx_status *st) {
    char sub[256];
    if (path_join(sub, sizeof sub, path, "to_q", st) || mx_lin_load(q, b, sub, dim, dim, qkv_bias, st)) return -1;
    if (path_join(sub, sizeof sub, path, "to_k", st) || mx_lin_load(k, b, sub, kv_dim, dim, qkv_bias, st)) return -1;
    if (path_join(sub, sizeof sub, path, "to_v", st) || mx_lin_load(v, b, sub, kv_dim, dim, qkv_bias, st)) return -1;
    if (path_join(sub, sizeof sub, path, "to_out.0", st) || mx_lin_load(o, b, sub, dim, dim, 1, st)) return -1;
    return 0;
}

static int tblock_load(mx_tblock *p, mx_binder *b, const char *path, int dim, int heads, int ctx_dim, mx_status *st) {
    char sub[256];
    p->dim = dim;
    p->heads = heads;
    p->ctx_dim = ctx_dim;
    p->ff_dim = 4 * dim;
    if (path_join(sub, sizeof sub, path, "norm1", st) || mx_ln_load(&p->norm1, b, sub, dim, 1e-5f, st)) return -1;
    if (path_join(sub, sizeof sub, path, "attn1", st) ||
        attn_load(&p->q1, &p->k1, &p->v1, &p->o1, b, sub, dim, dim, 0, st))
        return -1;
    if (path_join(sub, sizeof sub, path, "norm2", st) || mx_ln_load(&p->norm2, b, sub, dim, 1e-5f, st)) return -1;
    if (path_join(sub, sizeof sub, path, "attn2", st) ||
        attn_load(&p->q2, &p->k2, &p->v2, &p->o2, b, sub, dim, ctx_dim, 0, st))
        return -1;
    if (path_join(sub, sizeof sub, path, "norm3", st) || mx_ln_load(&p->norm3, b, sub, dim, 1e-5f, st)) return -1;
    if (path_join(sub, sizeof sub, path, "ff.net.0.proj", st) ||
        mx_lin_load(&p->ff_in, b, sub, dim, 2 * p->ff_dim, 1, st))
        return -1;
    if (path_join(sub, sizeof sub, path, "ff.net.2", st) || mx_lin_load(&p->ff_out, b, sub, p->ff_dim, dim, 1, st))
        return -1;
    return 0;
}

/* K and V of the cross-attention over context[M, ctx_dim]: into kbuf, vbuf, or with a step
 * cache into its slot, computed at a view's first forward and read back at the next ones. */
static int cross_kv(mx_run *r, const mx_tblock *p, const float *context, int M, float *kbuf, float *vbuf,
                    const float **k, const float **v) {
    size_t n = (size_t)M * p->dim, n64 = (n + 15) & ~(size_t)15; /* V 64-byte aligned after K */
    float *slot;
    int have = mx_run_cached(r, n64 + n, &slot);
    if (have < 0) return -1;
    float *kd = slot ? slot : kbuf, *vd = slot ? slot + n64 : vbuf;
    if (!have) {
        mx_lin_run(r, &p->k2, kd, context, M);
        mx_lin_run(r, &p->v2, vd, context, M);
    }
    *k = kd;
    *v = vd;
    return 0;
}

/* hs[B*HW, dim] is updated in place: self-attention, cross-attention, feed-forward, each
 * pre-normed and added back (diffusers BasicTransformerBlock, norm_type "layer_norm"). */
static int tblock_run(mx_run *r, const mx_tblock *p, float *hs, int B, int HW, const float *context, int T,
                      const mx_ip_guide *ip) {
    size_t mark = mx_arena_mark(r->a);
    int dim = p->dim, D = dim / p->heads, N = B * HW;
    size_t nd = (size_t)N * dim, td = (size_t)B * T * dim, kvd = nd > td ? nd : td;
    if (ip && (size_t)B * ip->n * dim > kvd) kvd = (size_t)B * ip->n * dim;
    float *n = mx_run_alloc(r, nd), *q = mx_run_alloc(r, nd), *a = mx_run_alloc(r, nd);
    float *k = mx_run_alloc(r, kvd), *v = mx_run_alloc(r, kvd);
    if (!n || !q || !a || !k || !v) return -1;

    int Bs = mx_run_batch(r, B), Ns = Bs * HW; /* self-attention: item 0 alone of a shared batch */
    mx_ln_run(r, &p->norm1, n, hs, Ns);
    mx_lin_run(r, &p->q1, q, n, Ns);
    mx_lin_run(r, &p->k1, k, n, Ns);
    mx_lin_run(r, &p->v1, v, n, Ns);
    run_attention(r, a, q, k, v, Bs, p->heads, HW, HW, D, dim, dim, dim);
    mx_lin_run(r, &p->o1, n, a, Ns);
    run_add(r, hs, hs, n, (size_t)Ns * dim);
    if (r->shared) { /* the cross-attention below is where the items part */
        mx_run_copy_item(r, hs, (size_t)HW * dim);
        r->shared = 0;
    }

    mx_ln_run(r, &p->norm2, n, hs, N);
    mx_lin_run(r, &p->q2, q, n, N);
    const float *kc = k, *vc = v;
    if (cross_kv(r, p, context, B * T, k, v, &kc, &vc)) return -1;
    run_attention(r, a, q, kc, vc, B, p->heads, HW, T, D, dim, dim, dim);
    if (ip) { /* a += scale · attention(q, K_ip, V_ip); n is free until to_out */
        mx_lin_run(r, &ip->k[p->ip_layer], k, ip->tokens, B * ip->n);
        mx_lin_run(r, &ip->v[p->ip_layer], v, ip->tokens, B * ip->n);
        run_attention(r, n, q, k, v, B, p->heads, HW, ip->n, D, dim, dim, dim);
        mx_axpy(r->c, a, n, ip->scale, nd);
    }
    mx_lin_run(r, &p->o2, n, a, N);
    run_add(r, hs, hs, n, nd);

    mx_arena_reset(r->a, mark); /* q, k, v, a are dead; the feed-forward buffers reuse them */
    n = mx_run_alloc(r, nd);
    float *f = mx_run_alloc(r, (size_t)N * 2 * p->ff_dim), *g = mx_run_alloc(r, (size_t)N * p->ff_dim);
    if (!n || !f || !g) return -1;
    mx_ln_run(r, &p->norm3, n, hs, N);
    mx_lin_run(r, &p->ff_in, f, n, N);
    mx_geglu(r->c, g, f, N, p->ff_dim);
    mx_lin_run(r, &p->ff_out, n, g, N);
    run_add(r, hs, hs, n, nd);
    mx_arena_reset(r->a, mark);
    return 0;
}

int mx_transformer_load(mx_transformer *p, mx_binder *b, const char *path, int channels, int heads, int layers,
                        int ctx_dim, int groups, int linear_proj, mx_status *st) {
    char sub[256];
    memset(p, 0, sizeof *p);
    if (heads <= 0 || channels % heads)
        return mx_fail(st, MX_EINPUT, "%s: %d channels are not divisible into %d attention heads", path, channels,
                       heads);
    p->channels = channels;
    p->inner = channels; /* heads * (channels / heads) */
    p->heads = heads;
    p->linear_proj = linear_proj;
    if (path_join(sub, sizeof sub, path, "norm", st) || mx_gn_load(&p->norm, b, sub, channels, groups, 1e-6f, st))
        return -1;
    if (path_join(sub, sizeof sub, path, "proj_in", st)) return -1;
    if (linear_proj ? mx_lin_load(&p->proj_in_lin, b, sub, channels, p->inner, 1, st)
                    : mx_conv_load(&p->proj_in_conv, b, sub, channels, p->inner, 1, 1, 0, 1, st))
        return -1;
    p->blocks = calloc((size_t)layers, sizeof *p->blocks);
    if (!p->blocks) return mx_fail(st, MX_ENOMEM, "out of memory loading %s", path);
    p->nblocks = layers;
    for (int i = 0; i < layers; i++) {
        char tb[256];
        snprintf(tb, sizeof tb, "transformer_blocks.%d", i);
        if (path_join(sub, sizeof sub, path, tb, st) || tblock_load(&p->blocks[i], b, sub, p->inner, heads, ctx_dim, st))
            return -1;
    }
    if (path_join(sub, sizeof sub, path, "proj_out", st)) return -1;
    return linear_proj ? mx_lin_load(&p->proj_out_lin, b, sub, p->inner, channels, 1, st)
                       : mx_conv_load(&p->proj_out_conv, b, sub, p->inner, channels, 1, 1, 0, 1, st);
}

void mx_transformer_free(mx_transformer *p) {
    free(p->blocks);
    p->blocks = NULL;
}

int mx_transformer_run(mx_run *r, const mx_transformer *p, float *y, const float *x, int B, int H, int W,
                       const float *context, int T, const mx_ip_guide *ip) {
    size_t mark = mx_arena_mark(r->a);
    int HW = H * W, C = p->channels, inner = p->inner;
    size_t n = (size_t)B * HW * (C > inner ? C : inner);
    float *t = mx_run_alloc(r, n), *hs = mx_run_alloc(r, n);
    if (!t || !hs) return -1;
    int b = mx_run_batch(r, B); /* x is whole; of a shared batch the first block copies hs */
    mx_gn_run(r, &p->norm, t, x, b, HW, 0);
    /* proj_in: 1×1 conv in NCHW then to tokens, or tokens then linear (use_linear_projection). */
    if (p->linear_proj) {
        mx_transpose_chw_hwc(r->c, y, t, b, C, HW);
        mx_lin_run(r, &p->proj_in_lin, hs, y, b * HW);
    } else {
        mx_conv_run(r, &p->proj_in_conv, y, t, b, H, W);
        mx_transpose_chw_hwc(r->c, hs, y, b, inner, HW);
    }
    for (int i = 0; i < p->nblocks; i++)
        if (tblock_run(r, &p->blocks[i], hs, B, HW, context, T, ip)) return -1;
    if (p->linear_proj) {
        mx_lin_run(r, &p->proj_out_lin, t, hs, B * HW);
        mx_transpose_hwc_chw(r->c, y, t, B, C, HW);
    } else {
        mx_transpose_hwc_chw(r->c, t, hs, B, inner, HW);
        mx_conv_run(r, &p->proj_out_conv, y, t, B, H, W);
    }
    run_add(r, y, y, x, (size_t)B * C * HW);
    mx_arena_reset(r->a, mark);
    return 0;
}

/* ---- VAE attention (Attention with residual_connection, group norm, one head) ---- */

int mx_vae_attn_load(mx_vae_attn *p, mx_binder *b, const char *path, int c, int groups, float eps, mx_status *st) {
    char sub[256];
    p->c = c;
    if (path_join(sub, sizeof sub, path, "group_norm", st) || mx_gn_load(&p->norm, b, sub, c, groups, eps, st))
        return -1;
    return attn_load(&p->q, &p->k, &p->v, &p->o, b, path, c, c, 1, st);
}

int mx_vae_attn_run(mx_run *r, const mx_vae_attn *p, float *y, const float *x, int B, int H, int W) {
    size_t mark = mx_arena_mark(r->a);
    int HW = H * W, C = p->c, N = B * HW;
    size_t n = (size_t)N * C;
    float *t = mx_run_alloc(r, n), *s = mx_run_alloc(r, n), *q = mx_run_alloc(r, n), *k = mx_run_alloc(r, n),
          *v = mx_run_alloc(r, n);
    if (!t || !s || !q || !k || !v) return -1;
    mx_gn_run(r, &p->norm, t, x, B, HW, 0);
    mx_transpose_chw_hwc(r->c, s, t, B, C, HW);
    mx_lin_run(r, &p->q, q, s, N);
    mx_lin_run(r, &p->k, k, s, N);
    mx_lin_run(r, &p->v, v, s, N);
    run_attention(r, t, q, k, v, B, 1, HW, HW, C, C, C, C);
    mx_lin_run(r, &p->o, s, t, N);
    mx_transpose_hwc_chw(r->c, y, s, B, C, HW);
    run_add(r, y, y, x, n);
    mx_arena_reset(r->a, mark);
    return 0;
}

/* ---- Downsample2D / Upsample2D ---- */

int mx_down_load(mx_down *p, mx_binder *b, const char *path, int c, int pad, mx_status *st) {
    char sub[256];
    p->asym_pad = pad == 0;
    if (path_join(sub, sizeof sub, path, "conv", st)) return -1;
    return mx_conv_load(&p->conv, b, sub, c, c, 3, 2, pad, 1, st);
}

int mx_down_run(mx_run *r, const mx_down *p, float *y, const float *x, int B, int H, int W) {
    if (!p->asym_pad) {
        mx_conv_run(r, &p->conv, y, x, B, H, W);
        return 0;
    }
    /* diffusers pads (left 0, right 1, top 0, bottom 1) with zeros, then convolves unpadded. */
    size_t mark = mx_arena_mark(r->a);
    int C = p->conv.cin, Hp = H + 1, Wp = W + 1;
    float *xp = mx_run_alloc(r, (size_t)B * C * Hp * Wp);
    if (!xp) return -1;
    mx_pad2d(r->c, xp, x, B * C, H, W, 0, 1, 0, 1);
    mx_conv_run(r, &p->conv, y, xp, B, Hp, Wp);
    mx_arena_reset(r->a, mark);
    return 0;
}

int mx_up_load(mx_up *p, mx_binder *b, const char *path, int c, mx_status *st) {
    char sub[256];
    if (path_join(sub, sizeof sub, path, "conv", st)) return -1;
    return mx_conv_load(&p->conv, b, sub, c, c, 3, 1, 1, 1, st);
}

void mx_up_run(mx_run *r, const mx_up *p, float *y, const float *x, int B, int H, int W) {
    mx_conv_up2x_run(r, &p->conv, y, x, B, H, W);
}

/* ---- timestep embedding ---- */

int mx_time_embed_load(mx_time_embed *p, mx_binder *b, int proj_dim, int dim, int flip, float shift, mx_status *st) {
    p->proj_dim = proj_dim;
    p->dim = dim;
    p->flip = flip;
    p->shift = shift;
    if (mx_lin_load(&p->l1, b, "time_embedding.linear_1", proj_dim, dim, 1, st)) return -1;
    return mx_lin_load(&p->l2, b, "time_embedding.linear_2", dim, dim, 1, st);
}

int mx_time_embed_run(mx_run *r, const mx_time_embed *p, float *temb_silu, const float *t, int B) {
    size_t mark = mx_arena_mark(r->a);
    float *tp = mx_run_alloc(r, (size_t)B * p->proj_dim), *h = mx_run_alloc(r, (size_t)B * p->dim);
    if (!tp || !h) return -1;
    mx_timestep_embedding(r->c, tp, t, B, p->proj_dim, p->flip, p->shift, 10000.0f);
    mx_lin_run(r, &p->l1, h, tp, B);
    mx_silu(r->c, h, (size_t)B * p->dim);
    mx_lin_run(r, &p->l2, temb_silu, h, B);
    mx_silu(r->c, temb_silu, (size_t)B * p->dim);
    mx_arena_reset(r->a, mark);
    return 0;
}
