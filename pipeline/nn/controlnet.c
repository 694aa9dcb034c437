/* ControlNetModel (diffusers v0.35.2 controlnets/controlnet.py): conditioning embedding,
 * the UNet encoder half, zero convolutions, residuals × conditioning scale. */
#include "controlnet.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "unet_encoder.h"

/* ControlNetConditioningEmbedding: conv_in, SiLU, pairs of (conv, SiLU, stride-2 conv, SiLU),
 * conv_out (a zero convolution in the original). */
typedef struct cond_embed {
    mx_conv conv_in, blocks[2 * (MX_NET_MAX_COND_CH - 1)], conv_out;
    int nblocks;
} cond_embed;

struct mx_controlnet {
    mx_unet_encoder enc;
    cond_embed ce;
    mx_conv zero_down[MX_UNET_MAX_RES];
    mx_conv zero_mid;
};

const mx_unet_config *mx_controlnet_cfg(const mx_controlnet *m) { return &m->enc.cfg; }

static int cond_embed_load(cond_embed *ce, mx_binder *b, const mx_unet_config *c, mx_status *st) {
    const int *e = c->cond_emb_channels;
    int n = c->n_cond_emb;
    char path[128];
    if (mx_conv_load(&ce->conv_in, b, "controlnet_cond_embedding.conv_in", c->conditioning_channels, e[0], 3, 1, 1, 1, st))
        return -1;
    ce->nblocks = 2 * (n - 1);
    for (int i = 0; i < n - 1; i++) {
        snprintf(path, sizeof path, "controlnet_cond_embedding.blocks.%d", 2 * i);
        if (mx_conv_load(&ce->blocks[2 * i], b, path, e[i], e[i], 3, 1, 1, 1, st)) return -1;
        snprintf(path, sizeof path, "controlnet_cond_embedding.blocks.%d", 2 * i + 1);
        if (mx_conv_load(&ce->blocks[2 * i + 1], b, path, e[i], e[i + 1], 3, 2, 1, 1, st)) return -1;
    }
    return mx_conv_load(&ce->conv_out, b, "controlnet_cond_embedding.conv_out", e[n - 1], c->block_out_channels[0], 3,
                        1, 1, 1, st);
}

int mx_controlnet_load(mx_controlnet **out, const mx_unet_config *cfg, mx_binder *b, mx_status *st) {
    *out = NULL;
    if (!cfg->is_controlnet) return mx_fail(st, MX_EINPUT, "mx_controlnet_load: the config is not a ControlNetModel config");
    mx_controlnet *m = calloc(1, sizeof *m);
    if (!m) return mx_fail(st, MX_ENOMEM, "out of memory loading the ControlNet");
    int rc = mx_unet_encoder_load(&m->enc, cfg, b, st);
    if (!rc) rc = cond_embed_load(&m->ce, b, cfg, st);
    int n = mx_unet_num_residuals(cfg), C, h, w;
    for (int i = 0; !rc && i < n; i++) {
        char path[64];
        snprintf(path, sizeof path, "controlnet_down_blocks.%d", i);
        mx_unet_residual_shape(cfg, i, 1, 1, &C, &h, &w);
        rc = mx_conv_load(&m->zero_down[i], b, path, C, C, 1, 1, 0, 1, st);
    }
    if (!rc) {
        mx_unet_residual_shape(cfg, n, 1, 1, &C, &h, &w);
        rc = mx_conv_load(&m->zero_mid, b, "controlnet_mid_block", C, C, 1, 1, 0, 1, st);
    }
    if (rc) {
        mx_fail_prefix(st, "loading the ControlNet");
        mx_controlnet_free(m);
        return -1;
    }
    *out = m;
    return 0;
}

void mx_controlnet_free(mx_controlnet *m) {
    if (!m) return;
    mx_unet_encoder_free(&m->enc);
    free(m);
}

/* emb[B, C0, H, W] from the control image [B, cc, H·f, W·f] (f = 2^(n_cond_emb-1)). */
static int cond_embed_run(mx_run *r, const cond_embed *ce, const mx_unet_config *c, float *emb, const float *cond,
                          int B, int H, int W) {
    size_t mark = mx_arena_mark(r->a);
    int f = 1 << (c->n_cond_emb - 1), h = H * f, w = W * f;
    /* stage i holds cond_emb_channels[i] channels at 1/2^i of the image size */
    size_t need = (size_t)c->conditioning_channels * h * w;
    for (int i = 0; i < c->n_cond_emb; i++) {
        size_t n = (size_t)c->cond_emb_channels[i] * (size_t)(h >> i) * (size_t)(w >> i);
        if (n > need) need = n;
    }
    float *p[2] = {mx_run_alloc(r, (size_t)B * need), mx_run_alloc(r, (size_t)B * need)};
    if (!p[0] || !p[1]) return -1;
    const float *x = cond;
    if (c->cond_bgr) { /* controlnet_conditioning_channel_order "bgr": flip channels */
        int cc = c->conditioning_channels;
        size_t hw = (size_t)h * w;
        for (int bi = 0; bi < B; bi++)
            for (int ci = 0; ci < cc; ci++)
                mx_copy(r->c, p[1] + ((size_t)bi * cc + ci) * hw, cond + ((size_t)bi * cc + cc - 1 - ci) * hw, hw);
        x = p[1];
    }
    mx_conv_run(r, &ce->conv_in, p[0], x, B, h, w);
    int cur = 0;
    size_t n = (size_t)B * c->cond_emb_channels[0] * h * w;
    mx_silu(r->c, p[0], n);
    for (int i = 0; i < ce->nblocks; i++) {
        const mx_conv *cv = &ce->blocks[i];
        mx_conv_run(r, cv, p[1 - cur], p[cur], B, h, w);
        h = mx_conv_out_size(cv, h);
        w = mx_conv_out_size(cv, w);
        cur = 1 - cur;
        mx_silu(r->c, p[cur], (size_t)B * cv->cout * h * w);
    }
    mx_conv_run(r, &ce->conv_out, emb, p[cur], B, h, w);
    mx_arena_reset(r->a, mark);
    return 0;
}

static int controlnet_run(mx_run *r, const mx_controlnet *m, const mx_controlnet_input *in, float *const *down,
                          float *mid_out, int accumulate) {
    const mx_unet_config *c = &m->enc.cfg;
    int B = in->B, n = mx_unet_num_residuals(c), C, h, w;
    float *res[MX_UNET_MAX_RES];
    size_t nemb = (size_t)B * c->block_out_channels[0] * in->H * in->W;
    float *temb = mx_run_alloc(r, (size_t)B * c->time_embed_dim), *emb;
    if (!temb || mx_time_embed_run(r, &m->enc.time, temb, in->timesteps, B)) return -1;
    int have = mx_run_cached(r, nemb, &emb); /* the hint embedding: the same at every step */
    if (have < 0 || (!emb && !(emb = mx_run_alloc(r, nemb)))) return -1;
    if (!have && cond_embed_run(r, &m->ce, c, emb, in->cond, B, in->H, in->W)) return -1;
    for (int i = 0; i <= n; i++) {
        mx_unet_residual_shape(c, i, in->H, in->W, &C, &h, &w);
        if (!(res[i] = mx_run_alloc(r, (size_t)B * C * h * w))) return -1;
    }
    if (mx_unet_encoder_run(r, &m->enc, in->sample, emb, B, in->H, in->W, temb, in->encoder_hidden_states, in->T, NULL, res,
                            res[n]))
        return -1;
    /* zero convolutions, scaled, written or accumulated into the caller's buffers */
    size_t rmax = 0;
    for (int i = 0; i <= n; i++) {
        mx_unet_residual_shape(c, i, in->H, in->W, &C, &h, &w);
        if ((size_t)B * C * h * w > rmax) rmax = (size_t)B * C * h * w;
    }
    float *t = mx_run_alloc(r, rmax);
    if (!t) return -1;
    for (int i = 0; i <= n; i++) {
        mx_unet_residual_shape(c, i, in->H, in->W, &C, &h, &w);
        mx_conv_run(r, i < n ? &m->zero_down[i] : &m->zero_mid, t, res[i], B, h, w);
        float *dst = i < n ? down[i] : mid_out;
        size_t cnt = (size_t)B * C * h * w;
        if (accumulate)
            mx_axpy(r->c, dst, t, in->scale, cnt);
        else
            mx_scale(r->c, dst, t, in->scale, cnt);
    }
    return 0;
}

static int check_cond_sizes(const mx_unet_config *c, const mx_controlnet_input *in, mx_status *st) {
    if (mx_unet_check_sizes(c, in->B, in->H, in->W, in->T, st)) return -1;
    int f = 1 << (c->n_cond_emb - 1), cmax = 0;
    for (int i = 0; i < c->n_cond_emb; i++)
        if (c->cond_emb_channels[i] > cmax) cmax = c->cond_emb_channels[i];
    if ((double)in->B * cmax * in->H * f * in->W * f > 2147483647.0)
        return mx_fail(st, MX_EINPUT, "control image too large: batch %d, %d×%d", in->B, in->H * f, in->W * f);
    return 0;
}

int mx_controlnet_forward_cached(const mx_ctx *c, const mx_controlnet *m, const mx_controlnet_input *in,
                                 mx_step_cache *cache, float *const *down, float *mid, int accumulate, mx_arena *a,
                                 mx_status *st) {
    if (check_cond_sizes(&m->enc.cfg, in, st)) return -1;
    mx_run r;
    mx_run_init(&r, c, a, st);
    r.cache = cache;
    r.shared = in->halves_equal && in->B == 2;
    mx_step_cache_begin(cache);
    size_t mark = mx_arena_mark(a);
    int rc = controlnet_run(&r, m, in, down, mid, accumulate);
    mx_arena_reset(a, mark);
    mx_step_cache_end(cache, rc == 0 && !a->measuring);
    return rc ? mx_fail_prefix(st, "ControlNet forward") : 0;
}

int mx_controlnet_forward(const mx_ctx *c, const mx_controlnet *m, const mx_controlnet_input *in, float *const *down,
                          float *mid, int accumulate, mx_arena *a, mx_status *st) {
    return mx_controlnet_forward_cached(c, m, in, NULL, down, mid, accumulate, a, st);
}

/* Output handles of a dry run. */
static void dry_outputs(float **out, int n) {
    for (int i = 0; i < n; i++) out[i] = mx_act_placeholder();
}

/* A dry run of these sizes: its arena peak, and the floats of `cache` when not NULL. */
static int controlnet_dry_run(const mx_controlnet *m, int B, int H, int W, int T, mx_step_cache *cache, size_t *bytes,
                              mx_status *st) {
    mx_arena a;
    float *out[MX_UNET_MAX_RES + 1];
    dry_outputs(out, MX_UNET_MAX_RES + 1);
    mx_arena_measure(&a);
    mx_controlnet_input in = {NULL, NULL, NULL, NULL, B, H, W, T, 1.0f, 0};
    if (mx_controlnet_forward_cached(NULL, m, &in, cache, out, out[MX_UNET_MAX_RES], 0, &a, st)) return -1;
    *bytes = a.peak + 4 * MX_ARENA_ALIGN;
    return 0;
}

int mx_controlnet_arena_bytes(const mx_controlnet *m, int B, int H, int W, int T, size_t *bytes, mx_status *st) {
    return controlnet_dry_run(m, B, H, W, T, NULL, bytes, st);
}

int mx_controlnet_cache_floats(const mx_controlnet *m, int B, int H, int W, int T, size_t *floats, mx_status *st) {
    mx_step_cache sizing = {0};
    size_t bytes;
    if (controlnet_dry_run(m, B, H, W, T, &sizing, &bytes, st)) return -1;
    *floats = sizing.cursor;
    return 0;
}

double mx_controlnet_flops(const mx_controlnet *m, int B, int H, int W, int T, int how) {
    mx_arena a;
    mx_status st;
    mx_step_cache replay = {.recorded = 1};
    float *out[MX_UNET_MAX_RES + 1];
    dry_outputs(out, MX_UNET_MAX_RES + 1);
    mx_arena_measure(&a);
    mx_controlnet_input in = {NULL, NULL, NULL, NULL, B, H, W, T, 1.0f, 0};
    mx_run r;
    mx_run_init(&r, NULL, &a, &st);
    r.cache = how & MX_FLOPS_REPLAYED ? &replay : NULL;
    r.shared = (how & MX_FLOPS_HALVES_EQUAL) && B == 2;
    if (check_cond_sizes(&m->enc.cfg, &in, &st) || controlnet_run(&r, m, &in, out, out[MX_UNET_MAX_RES], 0))
        return 0.0;
    return r.flops;
}

/* ---- the registry's entry points (registry.h) ---- */

int mx_controlnet_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                              mx_status *st) {
    mx_unet_config cfg;
    if (mx_unet_config_parse(&cfg, text, len, what, st)) return -1;
    if (!cfg.is_controlnet) return mx_fail(st, MX_EINPUT, "%s: not a ControlNetModel config", what);
    return mx_controlnet_load((mx_controlnet **)net, &cfg, b, st);
}

/* run-net controlnet: sample, timestep, encoder_hidden_states, controlnet_cond, optional
 * conditioning_scale -> the residuals (CN_RES + i, the mid block's last). */
enum { CN_SAMPLE, CN_TIMESTEP, CN_HIDDEN, CN_COND, CN_SCALE, CN_RES };
const mx_net_slot mx_controlnet_slots[] = {
    [CN_SAMPLE] = {"sample", MX_SLOT_IN},
    [CN_TIMESTEP] = {"timestep", MX_SLOT_IN},
    [CN_HIDDEN] = {"encoder_hidden_states", MX_SLOT_IN},
    [CN_COND] = {"controlnet_cond", MX_SLOT_IN},
    [CN_SCALE] = {"conditioning_scale", MX_SLOT_IN | MX_SLOT_OPTIONAL},
    [CN_RES] = {NULL, 0},
};

int mx_controlnet_more_slots(const void *net, mx_net_slots *s, mx_status *st) {
    return mx_unet_residual_slots(mx_controlnet_cfg(net), MX_SLOT_OUT, s, st);
}

static int conditioning_shapes(const mx_unet_config *cfg, mx_net_io *io, int64_t ss[4], int64_t es[3], mx_status *st) {
    ss[0] = ss[2] = ss[3] = -1, ss[1] = cfg->in_channels;
    if (io->shape(io, CN_SAMPLE, 4, ss, st)) return -1;
    es[0] = ss[0], es[1] = -1, es[2] = cfg->cross_attention_dim;
    return io->shape(io, CN_HIDDEN, 3, es, st);
}

int mx_controlnet_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    int64_t ss[4], es[3];
    if (conditioning_shapes(mx_controlnet_cfg(net), io, ss, es, st)) return -1;
    return mx_controlnet_arena_bytes(net, (int)ss[0], (int)ss[2], (int)ss[3], (int)es[1], bytes, st);
}

int mx_controlnet_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    const mx_controlnet *m = net;
    const mx_unet_config *cfg = mx_controlnet_cfg(m);
    int n = mx_unet_num_residuals(cfg), f = 1 << (cfg->n_cond_emb - 1), C, h, w;
    int64_t ss[4], es[3], one[1] = {1};
    if (conditioning_shapes(cfg, io, ss, es, st)) return -1;
    mx_controlnet_input in = {.sample = mx_net_io_input(io, CN_SAMPLE, 4, ss, st), .scale = 1.0f};
    if (!in.sample) return -1;
    if (!(in.encoder_hidden_states = mx_net_io_input(io, CN_HIDDEN, 3, es, st))) return -1;
    in.B = (int)ss[0], in.H = (int)ss[2], in.W = (int)ss[3], in.T = (int)es[1];
    if (!(in.timesteps = mx_net_io_timesteps(io, CN_TIMESTEP, in.B, st))) return -1;
    int64_t cs[4] = {in.B, cfg->conditioning_channels, ss[2] * f, ss[3] * f};
    if (!(in.cond = mx_net_io_input(io, CN_COND, 4, cs, st))) return -1;
    if (mx_net_io_has(io, CN_SCALE)) {
        const float *scale = io->host(io, CN_SCALE, 1, one, st);
        if (!scale) return -1;
        in.scale = scale[0];
    }
    if (check_cond_sizes(cfg, &in, st)) return -1;
    float *down[MX_UNET_MAX_RES + 1];
    for (int i = 0; i <= n; i++) {
        mx_unet_residual_shape(cfg, i, in.H, in.W, &C, &h, &w);
        int64_t rs[4] = {in.B, C, h, w};
        if (!(down[i] = io->output(io, CN_RES + i, 4, rs, st))) return -1;
    }
    return mx_controlnet_forward(c, m, &in, down, down[n], 0, a, st);
}
