/* AutoencoderTiny (see taesd.h). The layer indices of diffusers' nn.Sequential name the
 * parameters, so the loaders count them exactly as EncoderTiny / DecoderTiny build the list. */
#include "taesd.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "ae_pass.h"
#include "blocks.h"
#include "precision.h"

#define TAESD_MAX_BLOCKS 16

/* AutoencoderTinyBlock with in == out channels (the skip is the identity). */
typedef struct tiny_block {
    mx_conv c0, c2, c4;
} tiny_block;

/* Encoder level: its conv (stride 1 with bias on level 0, else stride 2 without), then blocks.
 * Decoder level: blocks, then (but the last level) upsample + conv without bias. */
typedef struct tiny_level {
    tiny_block blocks[TAESD_MAX_BLOCKS];
    int nblocks, has_conv;
    mx_conv conv;
} tiny_level;

struct mx_taesd {
    mx_taesd_config cfg;
    tiny_level enc[MX_NET_MAX_LEVELS], dec[MX_NET_MAX_LEVELS];
    mx_conv enc_out, dec_in, dec_out;
    int fp32; /* runs in fp32 throughout under a bf16 context (mx_prec_net_fp32, read at load) */
};

const mx_taesd_config *mx_taesd_cfg(const mx_taesd *t) { return &t->cfg; }
int mx_taesd_factor(const mx_taesd *t) { return 1 << (t->cfg.nlevels - 1); }

static int block_load(tiny_block *k, mx_binder *b, const char *half, int idx, int ch, mx_status *st) {
    char path[96];
    mx_conv *convs[3] = {&k->c0, &k->c2, &k->c4};
    for (int i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s.layers.%d.conv.%d", half, idx, 2 * i);
        if (mx_conv_load(convs[i], b, path, ch, ch, 3, 1, 1, 1, st)) return -1;
    }
    return 0;
}

static int layer_conv_load(mx_conv *p, mx_binder *b, const char *half, int idx, int cin, int cout, int stride,
                           int bias, mx_status *st) {
    char path[96];
    snprintf(path, sizeof path, "%s.layers.%d", half, idx);
    return mx_conv_load(p, b, path, cin, cout, 3, stride, 1, bias, st);
}

static int encoder_load(mx_taesd *t, mx_binder *b, mx_status *st) {
    const mx_taesd_config *c = &t->cfg;
    int idx = 0, ch = c->channels;
    for (int i = 0; i < c->nlevels; i++) {
        tiny_level *lv = &t->enc[i];
        lv->has_conv = 1;
        lv->nblocks = c->enc_blocks[i];
        if (layer_conv_load(&lv->conv, b, "encoder", idx++, i ? ch : c->in_channels, ch, i ? 2 : 1, i == 0, st))
            return -1;
        for (int j = 0; j < lv->nblocks; j++)
            if (block_load(&lv->blocks[j], b, "encoder", idx++, ch, st)) return -1;
    }
    return layer_conv_load(&t->enc_out, b, "encoder", idx, ch, c->latent_channels, 1, 1, st);
}

static int decoder_load(mx_taesd *t, mx_binder *b, mx_status *st) {
    const mx_taesd_config *c = &t->cfg;
    int ch = c->channels, idx = 2; /* layers.1 is the ReLU after the first conv */
    if (layer_conv_load(&t->dec_in, b, "decoder", 0, c->latent_channels, ch, 1, 1, st)) return -1;
    for (int i = 0; i < c->nlevels; i++) {
        tiny_level *lv = &t->dec[i];
        lv->nblocks = c->dec_blocks[i];
        lv->has_conv = i < c->nlevels - 1;
        for (int j = 0; j < lv->nblocks; j++)
            if (block_load(&lv->blocks[j], b, "decoder", idx++, ch, st)) return -1;
        if (!lv->has_conv) continue;
        idx++; /* the upsample */
        if (layer_conv_load(&lv->conv, b, "decoder", idx++, ch, ch, 1, 0, st)) return -1;
    }
    return layer_conv_load(&t->dec_out, b, "decoder", idx, ch, c->out_channels, 1, 1, st);
}

int mx_taesd_load(mx_taesd **out, const mx_taesd_config *cfg, mx_binder *b, mx_status *st) {
    *out = NULL;
    if (cfg->nlevels < 2 || cfg->nlevels > MX_NET_MAX_LEVELS)
        return mx_fail(st, MX_EINPUT, "TAESD: %d levels (2..%d supported)", cfg->nlevels, MX_NET_MAX_LEVELS);
    for (int i = 0; i < cfg->nlevels; i++)
        if (cfg->enc_blocks[i] < 0 || cfg->enc_blocks[i] > TAESD_MAX_BLOCKS || cfg->dec_blocks[i] < 0 ||
            cfg->dec_blocks[i] > TAESD_MAX_BLOCKS)
            return mx_fail(st, MX_EINPUT, "TAESD: level %d has more than %d blocks", i, TAESD_MAX_BLOCKS);
    mx_taesd *t = calloc(1, sizeof *t);
    if (!t) return mx_fail(st, MX_ENOMEM, "out of memory loading TAESD");
    t->cfg = *cfg;
    t->fp32 = mx_prec_net_fp32(MX_NET_TAESD);
    if (encoder_load(t, b, st) || decoder_load(t, b, st)) {
        mx_fail_prefix(st, "loading TAESD");
        free(t);
        return -1;
    }
    *out = t;
    return 0;
}

void mx_taesd_free(mx_taesd *t) { free(t); }

/* ---- forward ---- */

static void run_relu(mx_run *r, float *x, size_t n) { mx_clamp(r->c, x, x, 0.0f, INFINITY, n); }

/* y = block(x); y must not alias x. One temporary from the arena. */
static int block_run(mx_run *r, const tiny_block *k, float *y, const float *x, int B, int H, int W) {
    size_t n = (size_t)B * k->c0.cout * H * W, mark = mx_arena_mark(r->a);
    float *t = mx_run_alloc(r, n);
    if (!t) return -1;
    mx_conv_run(r, &k->c0, t, x, B, H, W);
    run_relu(r, t, n);
    mx_conv_run(r, &k->c2, y, t, B, H, W);
    run_relu(r, y, n);
    mx_conv_run(r, &k->c4, t, y, B, H, W);
    mx_add(r->c, y, t, x, n);
    run_relu(r, y, n);
    mx_arena_reset(r->a, mark);
    return 0;
}

static float *other(float *p[2], const float *cur) { return cur == p[0] ? p[1] : p[0]; }

/* Runs a level's blocks ping-ponging between p[0] and p[1]; returns the buffer holding the result. */
static float *blocks_run(mx_run *r, const tiny_level *lv, float *p[2], float *h, int B, int H, int W) {
    for (int j = 0; j < lv->nblocks; j++) {
        if (block_run(r, &lv->blocks[j], other(p, h), h, B, H, W)) return NULL;
        h = other(p, h);
    }
    return h;
}

static int encode_run(mx_run *r, const void *net, const float *image, int B, int H, int W, float *latents) {
    const mx_taesd *t = net;
    const mx_taesd_config *c = &t->cfg;
    size_t n = (size_t)B * (c->channels > c->in_channels ? c->channels : c->in_channels) * H * W;
    float *p[2] = {mx_run_alloc(r, n), mx_run_alloc(r, n)};
    if (!p[0] || !p[1]) return -1;
    float *h = p[0];
    /* [-1, 1] -> [0, 1]: (x + 1) / 2, which 0.5 x + 0.5 equals bit for bit */
    mx_affine(r->c, p[1], image, 0.5f, 0.5f, (size_t)B * c->in_channels * H * W);
    for (int i = 0; i < c->nlevels; i++) {
        const tiny_level *lv = &t->enc[i];
        mx_conv_run(r, &lv->conv, h, other(p, h), B, H, W);
        H = mx_conv_out_size(&lv->conv, H);
        W = mx_conv_out_size(&lv->conv, W);
        if (!(h = blocks_run(r, lv, p, h, B, H, W))) return -1;
        if (i < c->nlevels - 1) h = other(p, h); /* the next level's conv reads the other buffer */
    }
    mx_conv_run(r, &t->enc_out, latents, h, B, H, W);
    return 0;
}

static int decode_run(mx_run *r, const void *net, const float *latents, int B, int H, int W, float *image) {
    const mx_taesd *t = net;
    const mx_taesd_config *c = &t->cfg;
    int f = mx_taesd_factor(t);
    size_t n = (size_t)B * (c->channels > c->latent_channels ? c->channels : c->latent_channels) * H * W * f * f;
    size_t nl = (size_t)B * c->latent_channels * H * W;
    float *p[2] = {mx_run_alloc(r, n), mx_run_alloc(r, n)};
    if (!p[0] || !p[1]) return -1;
    float *h = p[0];
    /* "clamp": 3 tanh(x / 3) */
    mx_affine(r->c, p[1], latents, 1.0f / 3.0f, 0.0f, nl);
    mx_tanh(r->c, p[1], nl);
    mx_scale(r->c, p[1], p[1], 3.0f, nl);
    mx_conv_run(r, &t->dec_in, h, p[1], B, H, W);
    run_relu(r, h, (size_t)B * c->channels * H * W);
    for (int i = 0; i < c->nlevels; i++) {
        const tiny_level *lv = &t->dec[i];
        if (!(h = blocks_run(r, lv, p, h, B, H, W))) return -1;
        if (!lv->has_conv) break;
        float *u = other(p, h);
        mx_conv_up2x_run(r, &lv->conv, u, h, B, H, W); /* nn.Upsample, then the 3×3 conv */
        h = u;
        H *= 2;
        W *= 2;
    }
    mx_conv_run(r, &t->dec_out, image, h, B, H, W);
    /* [0, 1] -> [-1, 1]: x * 2 - 1 */
    mx_affine(r->c, image, image, 2.0f, -1.0f, (size_t)B * c->out_channels * H * W);
    return 0;
}

static int check_sizes(const mx_taesd *t, int B, int H, int W, mx_status *st) {
    int f = mx_taesd_factor(t);
    const mx_taesd_config *c = &t->cfg;
    if (B < 1 || H < 1 || W < 1 || H % f || W % f)
        return mx_fail(st, MX_EINPUT, "TAESD: bad sizes: batch %d, %d×%d (must be positive multiples of %d)", B, H, W,
                       f);
    int m = c->channels > c->in_channels ? c->channels : c->in_channels;
    if (c->out_channels > m) m = c->out_channels;
    if ((double)B * m * H * W > 2147483647.0) return mx_fail(st, MX_EINPUT, "TAESD: sizes too large: batch %d, %d×%d", B, H, W);
    return 0;
}

int mx_taesd_encode(const mx_ctx *c, const mx_taesd *t, const float *image, int B, int H, int W, float *latents,
                    mx_arena *a, mx_status *st) {
    if (check_sizes(t, B, H, W, st)) return -1;
    return mx_ae_run(c, t->fp32, encode_run, t, image, B, H, W, latents, a, st, "TAESD encode");
}

int mx_taesd_decode(const mx_ctx *c, const mx_taesd *t, const float *latents, int B, int h, int w, float *image,
                    mx_arena *a, mx_status *st) {
    int f = mx_taesd_factor(t);
    if (check_sizes(t, B, h * f, w * f, st)) return -1;
    return mx_ae_run(c, t->fp32, decode_run, t, latents, B, h, w, image, a, st, "TAESD decode");
}

int mx_taesd_encode_arena_bytes(const mx_taesd *t, int B, int H, int W, size_t *bytes, mx_status *st) {
    return check_sizes(t, B, H, W, st) ? -1 : mx_ae_dry_run(encode_run, t, B, H, W, bytes, NULL, st);
}

int mx_taesd_decode_arena_bytes(const mx_taesd *t, int B, int h, int w, size_t *bytes, mx_status *st) {
    int f = mx_taesd_factor(t);
    return check_sizes(t, B, h * f, w * f, st) ? -1 : mx_ae_dry_run(decode_run, t, B, h, w, bytes, NULL, st);
}

static int decode_dev(const mx_ctx *c, const void *net, const float *latents, int n, int h, int w, float *image,
                      mx_arena *a, mx_status *st) {
    return mx_taesd_decode(c, net, latents, n, h, w, image, a, st);
}

static int encode_dev(const mx_ctx *c, const void *net, const float *image, int n, int H, int W, float *latents,
                      mx_arena *a, mx_status *st) {
    return mx_taesd_encode(c, net, image, n, H, W, latents, a, st);
}

static mx_ae_coder coder(const mx_taesd *t, int encode) {
    const mx_taesd_config *cfg = &t->cfg;
    mx_ae_coder k = {encode ? encode_dev : decode_dev, t, cfg->latent_channels, encode ? cfg->in_channels : cfg->out_channels,
                     mx_taesd_factor(t), cfg->scaling_factor, 0};
    return k;
}

int mx_taesd_decode_image(const mx_ctx *c, const mx_taesd *t, const float *latents, int n, int h, int w,
                          float *image, mx_status *st) {
    mx_ae_coder d = coder(t, 0);
    if (mx_taesd_decode_arena_bytes(t, n, h, w, &d.arena_bytes, st)) return -1;
    return mx_ae_decode_host(c, &d, latents, n, h, w, image, st);
}

int mx_taesd_encode_image(const mx_ctx *c, const mx_taesd *t, const float *image, int n, int H, int W, float *latents,
                          mx_status *st) {
    mx_ae_coder e = coder(t, 1);
    if (mx_taesd_encode_arena_bytes(t, n, H, W, &e.arena_bytes, st)) return -1;
    return mx_ae_encode_host(c, &e, image, n, H, W, latents, st);
}

double mx_taesd_decode_flops(const mx_taesd *t, int B, int h, int w) {
    mx_status st;
    double flops = 0.0;
    int f = mx_taesd_factor(t);
    if (check_sizes(t, B, h * f, w * f, &st) || mx_ae_dry_run(decode_run, t, B, h, w, NULL, &flops, &st)) return 0.0;
    return flops;
}

/* ---- the registry's entry points (registry.h) ---- */

int mx_taesd_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st) {
    mx_taesd_config cfg;
    return mx_taesd_config_parse(&cfg, text, len, what, st) ? -1 : mx_taesd_load((mx_taesd **)net, &cfg, b, st);
}

/* image -> latents (encode) or latents -> image (decode): one input (slot TAESD_IN) and one
 * output (slot TAESD_OUT). */
enum { TAESD_IN, TAESD_OUT, TAESD_N };
const mx_net_slot mx_taesd_encode_slots[] = {
    [TAESD_IN] = {"image", MX_SLOT_IN},
    [TAESD_OUT] = {"latents", MX_SLOT_OUT},
    [TAESD_N] = {NULL, 0},
};
const mx_net_slot mx_taesd_decode_slots[] = {
    [TAESD_IN] = {"latents", MX_SLOT_IN},
    [TAESD_OUT] = {"image", MX_SLOT_OUT},
    [TAESD_N] = {NULL, 0},
};

/* The input's shape (-1 where any size goes). */
static void input_shape(const mx_taesd *t, int decode, int64_t is[4]) {
    is[0] = is[2] = is[3] = -1;
    is[1] = decode ? t->cfg.latent_channels : t->cfg.in_channels;
}

static int arena_io(const mx_taesd *t, int decode, mx_net_io *io, size_t *bytes, mx_status *st) {
    int64_t is[4];
    input_shape(t, decode, is);
    if (io->shape(io, TAESD_IN, 4, is, st)) return -1;
    int B = (int)is[0], H = (int)is[2], W = (int)is[3];
    return decode ? mx_taesd_decode_arena_bytes(t, B, H, W, bytes, st) : mx_taesd_encode_arena_bytes(t, B, H, W, bytes, st);
}

static int run_io(const mx_ctx *c, const mx_taesd *t, int decode, mx_net_io *io, mx_arena *a, mx_status *st) {
    int64_t is[4];
    input_shape(t, decode, is);
    const float *x = mx_net_io_input(io, TAESD_IN, 4, is, st);
    if (!x) return -1;
    int f = mx_taesd_factor(t), B = (int)is[0], H = (int)is[2], W = (int)is[3];
    int Ho = decode ? H * f : H / f, Wo = decode ? W * f : W / f;
    int64_t os[4] = {B, decode ? t->cfg.out_channels : t->cfg.latent_channels, Ho, Wo};
    float *y = io->output(io, TAESD_OUT, 4, os, st);
    if (!y) return -1;
    return decode ? mx_taesd_decode(c, t, x, B, H, W, y, a, st) : mx_taesd_encode(c, t, x, B, H, W, y, a, st);
}

int mx_taesd_encode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    return arena_io(net, 0, io, bytes, st);
}

int mx_taesd_encode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    return run_io(c, net, 0, io, a, st);
}

int mx_taesd_decode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    return arena_io(net, 1, io, bytes, st);
}

int mx_taesd_decode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    return run_io(c, net, 1, io, a, st);
}
