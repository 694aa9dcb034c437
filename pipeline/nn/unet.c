/* UNet2DConditionModel (diffusers v0.35.2 unet_2d_condition.py, unet_2d_blocks.py). */
#include "unet.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "unet_encoder.h"

/* One up level: layers_per_block + 1 resnets over [h | skip] (+ transformers for
 * CrossAttnUpBlock2D), then an Upsample2D unless it is the last level. */
typedef struct up_level {
    mx_resnet res[MX_ENC_MAX_LAYERS + 1];
    mx_transformer attn[MX_ENC_MAX_LAYERS + 1];
    mx_up up;
    int nres, cross, has_up, cout;
    int cin[MX_ENC_MAX_LAYERS + 1]; /* channels of h before the concat */
    int cskip[MX_ENC_MAX_LAYERS + 1];
} up_level;

struct mx_unet {
    mx_unet_encoder enc;
    up_level *up; /* cfg.nlevels */
    mx_gn norm_out;
    mx_conv conv_out;
    int n_cross; /* cross-attention layers (one per transformer block) */
};

/* The transformers in the order of diffusers' unet.attn_processors: the down blocks, the up
 * blocks, then the mid block (UNet2DConditionModel registers mid_block after up_blocks). Each of
 * their blocks is one cross-attention layer, the IP-Adapter's numbering (ip_adapter.h). */
static int cross_attention_transformers(const mx_unet *u, mx_transformer **list) {
    const mx_unet_config *c = &u->enc.cfg;
    int n = 0;
    for (int i = 0; i < c->nlevels; i++)
        for (int j = 0; u->enc.levels[i].cross && j < c->layers_per_block; j++) list[n++] = &u->enc.levels[i].attn[j];
    for (int i = 0; i < c->nlevels; i++)
        for (int j = 0; u->up[i].cross && j < u->up[i].nres; j++) list[n++] = &u->up[i].attn[j];
    list[n++] = (mx_transformer *)&u->enc.mid.attn;
    return n;
}

static void number_cross_attentions(mx_unet *u) {
    mx_transformer *list[2 * MX_NET_MAX_LEVELS * (MX_ENC_MAX_LAYERS + 1) + 1];
    int n = cross_attention_transformers(u, list);
    u->n_cross = 0;
    for (int t = 0; t < n; t++)
        for (int b = 0; b < list[t]->nblocks; b++) list[t]->blocks[b].ip_layer = u->n_cross++;
}

int mx_unet_check_ip(const mx_unet *u, const mx_ip_adapter *ad, mx_status *st) {
    mx_transformer *list[2 * MX_NET_MAX_LEVELS * (MX_ENC_MAX_LAYERS + 1) + 1];
    int n = cross_attention_transformers(u, list);
    if (ad->n_layers != u->n_cross)
        return mx_fail(st, MX_EINPUT, "the IP-Adapter has %d cross-attention layers, the UNet %d", ad->n_layers,
                       u->n_cross);
    if (ad->cross_dim != u->enc.cfg.cross_attention_dim)
        return mx_fail(st, MX_EINPUT, "the IP-Adapter's tokens are %d wide, the UNet's cross_attention_dim is %d",
                       ad->cross_dim, u->enc.cfg.cross_attention_dim);
    for (int t = 0; t < n; t++)
        for (int b = 0; b < list[t]->nblocks; b++) {
            const mx_tblock *tb = &list[t]->blocks[b];
            if (ad->hidden[tb->ip_layer] != tb->dim)
                return mx_fail(st, MX_EINPUT, "IP-Adapter layer %d (%d.to_k_ip) is %d wide, the UNet's is %d",
                               tb->ip_layer, 2 * tb->ip_layer + 1, ad->hidden[tb->ip_layer], tb->dim);
        }
    return 0;
}

const mx_unet_config *mx_unet_cfg(const mx_unet *u) { return &u->enc.cfg; }

static int up_level_load(up_level *lv, mx_binder *b, const mx_unet_config *c, int i, mx_status *st) {
    int n = c->nlevels, L = c->layers_per_block;
    int out = c->block_out_channels[n - 1 - i];
    int prev = c->block_out_channels[n - 1 - (i > 0 ? i - 1 : 0)];
    int in = c->block_out_channels[n - 1 - (i + 1 < n ? i + 1 : n - 1)];
    int heads = c->heads[n - 1 - i], layers = c->transformer_layers[n - 1 - i];
    char path[128];
    lv->cross = c->up_cross[i];
    lv->cout = out;
    lv->has_up = i < n - 1;
    lv->nres = L + 1;
    for (int j = 0; j <= L; j++) {
        lv->cin[j] = j == 0 ? prev : out;
        lv->cskip[j] = j == L ? in : out;
        snprintf(path, sizeof path, "up_blocks.%d.resnets.%d", i, j);
        if (mx_resnet_load(&lv->res[j], b, path, lv->cin[j] + lv->cskip[j], out, c->time_embed_dim,
                           c->norm_num_groups, c->norm_eps, 1.0f, st))
            return -1;
        snprintf(path, sizeof path, "up_blocks.%d.attentions.%d", i, j);
        if (lv->cross && mx_transformer_load(&lv->attn[j], b, path, out, heads, layers, c->cross_attention_dim,
                                             c->norm_num_groups, c->use_linear_projection, st))
            return -1;
    }
    snprintf(path, sizeof path, "up_blocks.%d.upsamplers.0", i);
    return lv->has_up ? mx_up_load(&lv->up, b, path, out, st) : 0;
}

int mx_unet_load(mx_unet **out, const mx_unet_config *cfg, mx_binder *b, mx_status *st) {
    *out = NULL;
    if (cfg->is_controlnet) return mx_fail(st, MX_EINPUT, "mx_unet_load: the config is a ControlNetModel config");
    mx_unet *u = calloc(1, sizeof *u);
    if (!u) return mx_fail(st, MX_ENOMEM, "out of memory loading the UNet");
    const mx_unet_config *c = cfg;
    int rc = mx_unet_encoder_load(&u->enc, cfg, b, st);
    if (!rc) {
        u->up = calloc((size_t)c->nlevels, sizeof *u->up);
        if (!u->up) rc = mx_fail(st, MX_ENOMEM, "out of memory loading the UNet");
    }
    for (int i = 0; !rc && i < c->nlevels; i++) rc = up_level_load(&u->up[i], b, c, i, st);
    if (!rc) rc = mx_gn_load(&u->norm_out, b, "conv_norm_out", c->block_out_channels[0], c->norm_num_groups, c->norm_eps, st);
    if (!rc)
        rc = mx_conv_load(&u->conv_out, b, "conv_out", c->block_out_channels[0], c->out_channels, c->conv_out_kernel, 1,
                          (c->conv_out_kernel - 1) / 2, 1, st);
    if (rc) {
        mx_fail_prefix(st, "loading the UNet");
        mx_unet_free(u);
        return -1;
    }
    number_cross_attentions(u);
    *out = u;
    return 0;
}

void mx_unet_free(mx_unet *u) {
    if (!u) return;
    if (u->up)
        for (int i = 0; i < u->enc.cfg.nlevels; i++)
            for (int j = 0; j <= MX_ENC_MAX_LAYERS; j++) mx_transformer_free(&u->up[i].attn[j]);
    free(u->up);
    mx_unet_encoder_free(&u->enc);
    free(u);
}

/* Largest hidden state of the up path (floats): the ping-pong buffer size. */
static size_t up_path_max(const mx_unet_config *c, int B, int H, int W) {
    size_t m = 0;
    int f = 1 << (c->nlevels - 1), h = H / f, w = W / f;
    for (int i = 0; i < c->nlevels; i++) {
        size_t n = (size_t)B * c->block_out_channels[c->nlevels - 1 - i] * h * w;
        if (i < c->nlevels - 1) {
            n *= 4;
            h *= 2;
            w *= 2;
        }
        if (n > m) m = n;
    }
    return m;
}

/* Up level i: each resnet on concat(h, skip) (skips popped from the end), optional
 * transformer, then the upsampler. h moves between the ping-pong buffers p[0], p[1]. */
static int up_level_run(mx_run *r, const up_level *lv, float **h, float *p[2], float *const *res, int *k, int B,
                        int *H, int *W, const float *temb, const float *context, int T, const mx_ip_guide *ip) {
    for (int j = 0; j < lv->nres; j++) {
        size_t mark = mx_arena_mark(r->a), hw = (size_t)*H * *W;
        float *cat = mx_run_alloc(r, (size_t)B * (lv->cin[j] + lv->cskip[j]) * hw);
        if (!cat) return -1;
        const float *skip = res[--*k];
        mx_concat_channels(r->c, cat, *h, lv->cin[j], skip, lv->cskip[j], B, (int)hw);
        float *dst = *h == p[0] ? p[1] : p[0];
        if (mx_resnet_run_spending_x(r, &lv->res[j], dst, cat, B, *H, *W, temb)) return -1;
        mx_arena_reset(r->a, mark);
        *h = dst;
        if (lv->cross) {
            dst = *h == p[0] ? p[1] : p[0];
            if (mx_transformer_run(r, &lv->attn[j], dst, *h, B, *H, *W, context, T, ip)) return -1;
            *h = dst;
        }
    }
    if (lv->has_up) {
        float *dst = *h == p[0] ? p[1] : p[0];
        mx_up_run(r, &lv->up, dst, *h, B, *H, *W);
        *h = dst;
        *H *= 2;
        *W *= 2;
    }
    return 0;
}

static void add_residuals(mx_run *r, const mx_unet_config *c, const mx_unet_input *in, float *const *res, float *mid) {
    int n = mx_unet_num_residuals(c), C, h, w;
    for (int i = 0; i <= n; i++) {
        const float *add = i < n ? (in->down_residuals ? in->down_residuals[i] : NULL) : in->mid_residual;
        if (!add) continue;
        mx_unet_residual_shape(c, i, in->H, in->W, &C, &h, &w);
        mx_add(r->c, i < n ? res[i] : mid, i < n ? res[i] : mid, add, (size_t)in->B * C * h * w);
    }
}

/* The call's image guidance, or NULL when it has none (no adapter, no tokens or scale 0). */
static const mx_ip_guide *ip_guide(const mx_unet_input *in, mx_ip_guide *g) {
    if (!in->ip || in->ip_n <= 0 || in->ip_scale == 0.0f) return NULL;
    *g = (mx_ip_guide){.k = in->ip->k, .v = in->ip->v, .tokens = in->ip_tokens, .n = in->ip_n, .scale = in->ip_scale};
    return g;
}

static int unet_run(mx_run *r, const mx_unet *u, const mx_unet_input *in, float *out) {
    const mx_unet_config *c = &u->enc.cfg;
    int B = in->B, n = mx_unet_num_residuals(c), C, h, w;
    mx_ip_guide guide;
    const mx_ip_guide *ip = ip_guide(in, &guide);
    float *res[MX_UNET_MAX_RES];
    float *temb = mx_run_alloc(r, (size_t)B * c->time_embed_dim);
    if (!temb || mx_time_embed_run(r, &u->enc.time, temb, in->timesteps, B)) return -1;
    for (int i = 0; i <= n; i++) {
        mx_unet_residual_shape(c, i, in->H, in->W, &C, &h, &w);
        if (!(res[i] = mx_run_alloc(r, (size_t)B * C * h * w))) return -1;
    }
    float *mid = res[n];
    if (mx_unet_encoder_run(r, &u->enc, in->sample, NULL, B, in->H, in->W, temb, in->encoder_hidden_states, in->T, ip, res,
                            mid))
        return -1;
    add_residuals(r, c, in, res, mid);
    size_t pmax = up_path_max(c, B, in->H, in->W);
    float *p[2] = {mx_run_alloc(r, pmax), mx_run_alloc(r, pmax)};
    if (!p[0] || !p[1]) return -1;
    float *hcur = mid;
    int k = n, H = h, W = w;
    for (int i = 0; i < c->nlevels; i++)
        if (up_level_run(r, &u->up[i], &hcur, p, res, &k, B, &H, &W, temb, in->encoder_hidden_states, in->T, ip))
            return -1;
    float *t = hcur == p[0] ? p[1] : p[0];
    mx_gn_run(r, &u->norm_out, t, hcur, B, H * W, 1);
    mx_conv_run(r, &u->conv_out, out, t, B, H, W);
    return 0;
}

int mx_unet_forward_cached(const mx_ctx *c, const mx_unet *u, const mx_unet_input *in, mx_step_cache *cache,
                           float *out, mx_arena *a, mx_status *st) {
    mx_ip_guide guide;
    if (mx_unet_check_sizes(&u->enc.cfg, in->B, in->H, in->W, in->T, st)) return -1;
    if (ip_guide(in, &guide) && mx_unet_check_ip(u, in->ip, st)) return -1;
    if (ip_guide(in, &guide) && in->ip_n > MX_IP_MAX_TOKENS)
        return mx_fail(st, MX_EINPUT, "%d image tokens (at most %d)", in->ip_n, MX_IP_MAX_TOKENS);
    mx_run r;
    mx_run_init(&r, c, a, st);
    r.cache = cache;
    r.shared = in->halves_equal && in->B == 2;
    mx_step_cache_begin(cache);
    size_t mark = mx_arena_mark(a);
    int rc = unet_run(&r, u, in, out);
    mx_arena_reset(a, mark);
    mx_step_cache_end(cache, rc == 0 && !a->measuring);
    return rc ? mx_fail_prefix(st, "UNet forward") : 0;
}

int mx_unet_forward(const mx_ctx *c, const mx_unet *u, const mx_unet_input *in, float *out, mx_arena *a,
                    mx_status *st) {
    return mx_unet_forward_cached(c, u, in, NULL, out, a, st);
}

int mx_unet_call_arena_bytes(const mx_unet *u, const mx_unet_input *in, size_t *bytes, mx_status *st) {
    mx_arena a;
    mx_arena_measure(&a);
    mx_unet_input dry = {.B = in->B, .H = in->H, .W = in->W, .T = in->T, .ip = in->ip, .ip_n = in->ip_n,
                         .ip_scale = in->ip_scale};
    if (mx_unet_forward(NULL, u, &dry, NULL, &a, st)) return -1;
    *bytes = a.peak + 4 * MX_ARENA_ALIGN;
    return 0;
}

int mx_unet_arena_bytes(const mx_unet *u, int B, int H, int W, int T, size_t *bytes, mx_status *st) {
    mx_unet_input in = {.B = B, .H = H, .W = W, .T = T};
    return mx_unet_call_arena_bytes(u, &in, bytes, st);
}

/* A dry run with a sizing cache (the image guidance's K/V are not cached: its sizes do not matter). */
int mx_unet_cache_floats(const mx_unet *u, int B, int H, int W, int T, size_t *floats, mx_status *st) {
    mx_arena a;
    mx_step_cache sizing = {0};
    mx_arena_measure(&a);
    mx_unet_input in = {.B = B, .H = H, .W = W, .T = T};
    if (mx_unet_forward_cached(NULL, u, &in, &sizing, NULL, &a, st)) return -1;
    *floats = sizing.cursor;
    return 0;
}

double mx_unet_flops(const mx_unet *u, int B, int H, int W, int T, int how) {
    mx_arena a;
    mx_status st;
    mx_step_cache replay = {.recorded = 1};
    mx_arena_measure(&a);
    mx_unet_input in = {.B = B, .H = H, .W = W, .T = T};
    mx_run r;
    mx_run_init(&r, NULL, &a, &st);
    r.cache = how & MX_FLOPS_REPLAYED ? &replay : NULL;
    r.shared = (how & MX_FLOPS_HALVES_EQUAL) && B == 2;
    if (mx_unet_check_sizes(&u->enc.cfg, B, H, W, T, &st) || unet_run(&r, u, &in, NULL)) return 0.0;
    return r.flops;
}

/* ---- the registry's entry points (registry.h) ---- */

int mx_unet_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st) {
    mx_unet_config cfg;
    if (mx_unet_config_parse(&cfg, text, len, what, st)) return -1;
    if (cfg.is_controlnet) return mx_fail(st, MX_EINPUT, "%s: a ControlNetModel config, not a UNet2DConditionModel", what);
    return mx_unet_load((mx_unet **)net, &cfg, b, st);
}

int mx_unet_residual_slots(const mx_unet_config *cfg, int flags, mx_net_slots *s, mx_status *st) {
    int n = mx_unet_num_residuals(cfg);
    for (int i = 0; i < n; i++) {
        char name[48];
        snprintf(name, sizeof name, "down_block_res_sample.%d", i);
        if (mx_net_slots_add(s, name, flags, st)) return -1;
    }
    return mx_net_slots_add(s, "mid_block_res_sample", flags, st);
}

/* run-net unet's tensors: the slots below, then the residuals (UNET_RES + i, the mid block's
 * last). */
enum { UNET_SAMPLE, UNET_TIMESTEP, UNET_HIDDEN, UNET_EMBEDS, UNET_IP_SCALE, UNET_OUT, UNET_TOKENS, UNET_RES };
const mx_net_slot mx_unet_slots[] = {
    [UNET_SAMPLE] = {"sample", MX_SLOT_IN},
    [UNET_TIMESTEP] = {"timestep", MX_SLOT_IN},
    [UNET_HIDDEN] = {"encoder_hidden_states", MX_SLOT_IN},
    [UNET_EMBEDS] = {"image_embeds", MX_SLOT_IN | MX_SLOT_OPTIONAL},
    [UNET_IP_SCALE] = {"ip_adapter_scale", MX_SLOT_IN | MX_SLOT_OPTIONAL},
    [UNET_OUT] = {"out", MX_SLOT_OUT},
    [UNET_TOKENS] = {"image_tokens", MX_SLOT_OUT},
    [UNET_RES] = {NULL, 0},
};

int mx_unet_more_slots(const void *net, mx_net_slots *s, mx_status *st) {
    return mx_unet_residual_slots(mx_unet_cfg(net), MX_SLOT_IN | MX_SLOT_OPTIONAL, s, st);
}

/* run-net unet: the call's sizes from its inputs' shapes (sample [B,C,H,W],
 * encoder_hidden_states [B,T,D]) and, with image_embeds [B, n_images, E], the weight file's
 * IP-Adapter (*ad, else NULL) and its n_images. */
static int read_sizes(mx_net_io *io, const mx_unet *u, mx_unet_input *in, const mx_ip_adapter **ad, int *n_images,
                      mx_status *st) {
    const mx_unet_config *cfg = mx_unet_cfg(u);
    int64_t ss[4] = {-1, cfg->in_channels, -1, -1}, es[3] = {-1, -1, cfg->cross_attention_dim};
    if (io->shape(io, UNET_SAMPLE, 4, ss, st)) return -1;
    es[0] = ss[0];
    if (io->shape(io, UNET_HIDDEN, 3, es, st)) return -1;
    *in = (mx_unet_input){.B = (int)ss[0], .H = (int)ss[2], .W = (int)ss[3], .T = (int)es[1]};
    if (mx_unet_check_sizes(cfg, in->B, in->H, in->W, in->T, st)) return -1;
    *ad = NULL;
    *n_images = 0;
    if (!mx_net_io_has(io, UNET_EMBEDS))
        return mx_net_io_has(io, UNET_IP_SCALE)
                   ? mx_fail(st, MX_EINPUT, "%s: ip_adapter_scale without image_embeds", io->source)
                   : 0;
    if (!(*ad = io->network(io, MX_NET_IP_ADAPTER, st)) || mx_unet_check_ip(u, *ad, st)) return -1;
    int64_t is[3] = {in->B, -1, (*ad)->embed_dim};
    if (io->shape(io, UNET_EMBEDS, 3, is, st)) return -1;
    if (is[1] > MX_IP_MAX_TOKENS / (*ad)->num_tokens)
        return mx_fail(st, MX_EINPUT, "%s: image_embeds: %lld images of %d tokens (at most %d tokens)", io->source,
                       (long long)is[1], (*ad)->num_tokens, MX_IP_MAX_TOKENS);
    *n_images = (int)is[1];
    in->ip = *ad;
    in->ip_n = *n_images * (*ad)->num_tokens;
    in->ip_scale = 1.0f;
    return 0;
}

int mx_unet_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    mx_unet_input in;
    const mx_ip_adapter *ad;
    int n_images;
    size_t ip_bytes = 0;
    if (read_sizes(io, net, &in, &ad, &n_images, st) || mx_unet_call_arena_bytes(net, &in, bytes, st) ||
        (ad && mx_ip_adapter_arena_bytes(ad, n_images * in.B, &ip_bytes, st)))
        return -1;
    if (ip_bytes > *bytes) *bytes = ip_bytes; /* the tokens are made before the UNet runs, on the same arena */
    return 0;
}

/* The optional image guidance's tensors: image_embeds through the IP-Adapter into the output
 * image_tokens [B, n_images, num_tokens, C], at ip_adapter_scale [1] (default 1). */
static int run_image_guidance(const mx_ctx *c, mx_net_io *io, const mx_ip_adapter *ad, int n_images, mx_unet_input *in,
                              mx_arena *a, mx_status *st) {
    int64_t es[3] = {in->B, n_images, ad->embed_dim}, ts[4] = {in->B, n_images, ad->num_tokens, ad->cross_dim};
    const float *embeds = mx_net_io_input(io, UNET_EMBEDS, 3, es, st);
    if (!embeds) return -1;
    if (mx_net_io_has(io, UNET_IP_SCALE)) {
        size_t n;
        const float *s = io->host_flat(io, UNET_IP_SCALE, &n, st);
        if (!s) return -1;
        if (n != 1) return mx_fail(st, MX_EINPUT, "%s: ip_adapter_scale has %zu values, expected 1", io->source, n);
        in->ip_scale = s[0];
    }
    float *tokens = io->output(io, UNET_TOKENS, 4, ts, st);
    in->ip_tokens = tokens;
    return tokens ? mx_ip_adapter_tokens(c, ad, embeds, n_images * in->B, tokens, a, st) : -1;
}

/* run-net unet: sample, timestep, encoder_hidden_states, optional residuals and image guidance -> out. */
int mx_unet_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    const mx_unet *u = net;
    const mx_unet_config *cfg = mx_unet_cfg(u);
    mx_unet_input in;
    const mx_ip_adapter *ad;
    int n_images;
    if (read_sizes(io, u, &in, &ad, &n_images, st)) return -1;
    int64_t ss[4] = {in.B, cfg->in_channels, in.H, in.W}, es[3] = {in.B, in.T, cfg->cross_attention_dim};
    if (!(in.sample = mx_net_io_input(io, UNET_SAMPLE, 4, ss, st)) ||
        !(in.encoder_hidden_states = mx_net_io_input(io, UNET_HIDDEN, 3, es, st)) ||
        !(in.timesteps = mx_net_io_timesteps(io, UNET_TIMESTEP, in.B, st)))
        return -1;
    int n = mx_unet_num_residuals(cfg), C, h, w;
    const float *res[MX_UNET_MAX_RES];
    int have = mx_net_io_has(io, UNET_RES);
    for (int i = 0; i <= n && (have || mx_net_io_has(io, UNET_RES + n)); i++) {
        mx_unet_residual_shape(cfg, i, in.H, in.W, &C, &h, &w);
        int64_t rs[4] = {in.B, C, h, w};
        const float *p = mx_net_io_input(io, UNET_RES + i, 4, rs, st);
        if (!p) return -1;
        if (i < n) res[i] = p;
        else in.mid_residual = p;
    }
    if (have) in.down_residuals = res;
    int64_t os[4] = {in.B, cfg->out_channels, in.H, in.W};
    float *out = io->output(io, UNET_OUT, 4, os, st);
    if (!out || (ad && run_image_guidance(c, io, ad, n_images, &in, a, st))) return -1;
    return mx_unet_forward(c, u, &in, out, a, st);
}
