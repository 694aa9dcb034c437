/* AutoencoderKL (diffusers v0.35.2 autoencoder_kl.py, vae.py: Encoder / Decoder with
 * DownEncoderBlock2D, UpDecoderBlock2D and UNetMidBlock2D). Norm eps is 1e-6 throughout. */
#include "vae.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ae_pass.h"
#include "blocks.h"
#include "precision.h"

#define VAE_EPS 1e-6f
#define VAE_MAX_LAYERS 16

typedef struct vae_level {
    mx_resnet res[VAE_MAX_LAYERS + 1];
    mx_down down;
    mx_up up;
    int nres, has_resample, cout;
} vae_level;

/* UNetMidBlock2D without time embedding: resnet, [attention,] resnet. */
typedef struct vae_mid {
    mx_resnet res0, res1;
    mx_vae_attn attn;
    int has_attn;
} vae_mid;

typedef struct vae_half {
    mx_conv conv_in, conv_out;
    vae_level levels[MX_NET_MAX_LEVELS];
    vae_mid mid;
    mx_gn norm_out;
} vae_half;

struct mx_vae {
    mx_vae_config cfg;
    vae_half enc, dec;
    mx_conv quant_conv, post_quant_conv;
    int fp32; /* runs in fp32 throughout under a bf16 context (mx_prec_net_fp32, read at load) */
};

const mx_vae_config *mx_vae_cfg(const mx_vae *v) { return &v->cfg; }
int mx_vae_factor(const mx_vae *v) { return 1 << (v->cfg.nlevels - 1); }

static int mid_load(vae_mid *m, mx_binder *b, const char *part, const mx_vae_config *c, mx_status *st) {
    int ch = c->block_out_channels[c->nlevels - 1];
    char path[128];
    snprintf(path, sizeof path, "%s.mid_block.resnets.0", part);
    if (mx_resnet_load(&m->res0, b, path, ch, ch, 0, c->norm_num_groups, VAE_EPS, 1.0f, st)) return -1;
    m->has_attn = c->mid_attention;
    snprintf(path, sizeof path, "%s.mid_block.attentions.0", part);
    if (m->has_attn && mx_vae_attn_load(&m->attn, b, path, ch, c->norm_num_groups, VAE_EPS, st)) return -1;
    snprintf(path, sizeof path, "%s.mid_block.resnets.1", part);
    return mx_resnet_load(&m->res1, b, path, ch, ch, 0, c->norm_num_groups, VAE_EPS, 1.0f, st);
}

static int encoder_load(vae_half *e, mx_binder *b, const mx_vae_config *c, mx_status *st) {
    const int *ch = c->block_out_channels;
    int n = c->nlevels, cin = ch[0];
    char path[128];
    if (mx_conv_load(&e->conv_in, b, "encoder.conv_in", c->in_channels, ch[0], 3, 1, 1, 1, st)) return -1;
    for (int i = 0; i < n; i++) {
        vae_level *lv = &e->levels[i];
        lv->nres = c->layers_per_block;
        lv->cout = ch[i];
        lv->has_resample = i < n - 1;
        for (int j = 0; j < lv->nres; j++) {
            snprintf(path, sizeof path, "encoder.down_blocks.%d.resnets.%d", i, j);
            if (mx_resnet_load(&lv->res[j], b, path, j ? ch[i] : cin, ch[i], 0, c->norm_num_groups, VAE_EPS, 1.0f, st))
                return -1;
        }
        snprintf(path, sizeof path, "encoder.down_blocks.%d.downsamplers.0", i);
        if (lv->has_resample && mx_down_load(&lv->down, b, path, ch[i], 0, st)) return -1;
        cin = ch[i];
    }
    if (mid_load(&e->mid, b, "encoder", c, st)) return -1;
    if (mx_gn_load(&e->norm_out, b, "encoder.conv_norm_out", ch[n - 1], c->norm_num_groups, VAE_EPS, st)) return -1;
    return mx_conv_load(&e->conv_out, b, "encoder.conv_out", ch[n - 1], 2 * c->latent_channels, 3, 1, 1, 1, st);
}

static int decoder_load(vae_half *d, mx_binder *b, const mx_vae_config *c, mx_status *st) {
    const int *ch = c->block_out_channels;
    int n = c->nlevels, prev = ch[n - 1];
    char path[128];
    if (mx_conv_load(&d->conv_in, b, "decoder.conv_in", c->latent_channels, ch[n - 1], 3, 1, 1, 1, st)) return -1;
    if (mid_load(&d->mid, b, "decoder", c, st)) return -1;
    for (int i = 0; i < n; i++) {
        vae_level *lv = &d->levels[i];
        int out = ch[n - 1 - i];
        lv->nres = c->layers_per_block + 1;
        lv->cout = out;
        lv->has_resample = i < n - 1;
        for (int j = 0; j < lv->nres; j++) {
            snprintf(path, sizeof path, "decoder.up_blocks.%d.resnets.%d", i, j);
            if (mx_resnet_load(&lv->res[j], b, path, j ? out : prev, out, 0, c->norm_num_groups, VAE_EPS, 1.0f, st))
                return -1;
            if (mx_prec_vae_up_block_bf16(i, n)) lv->res[j].conv1.prec = lv->res[j].conv2.prec = MX_CONV_PREC_GIVEN;
        }
        snprintf(path, sizeof path, "decoder.up_blocks.%d.upsamplers.0", i);
        if (lv->has_resample && mx_up_load(&lv->up, b, path, out, st)) return -1;
        if (lv->has_resample && mx_prec_vae_up_block_bf16(i, n)) lv->up.conv.prec = MX_CONV_PREC_GIVEN;
        prev = out;
    }
    if (mx_gn_load(&d->norm_out, b, "decoder.conv_norm_out", ch[0], c->norm_num_groups, VAE_EPS, st)) return -1;
    return mx_conv_load(&d->conv_out, b, "decoder.conv_out", ch[0], c->out_channels, 3, 1, 1, 1, st);
}

int mx_vae_load(mx_vae **out, const mx_vae_config *cfg, mx_binder *b, mx_status *st) {
    *out = NULL;
    if (cfg->layers_per_block > VAE_MAX_LAYERS)
        return mx_fail(st, MX_EINPUT, "VAE layers_per_block %d exceeds %d", cfg->layers_per_block, VAE_MAX_LAYERS);
    mx_vae *v = calloc(1, sizeof *v);
    if (!v) return mx_fail(st, MX_ENOMEM, "out of memory loading the VAE");
    v->cfg = *cfg;
    v->fp32 = mx_prec_net_fp32(MX_NET_VAE);
    int lc = cfg->latent_channels;
    int rc = encoder_load(&v->enc, b, cfg, st);
    if (!rc) rc = decoder_load(&v->dec, b, cfg, st);
    if (!rc && cfg->use_quant_conv) rc = mx_conv_load(&v->quant_conv, b, "quant_conv", 2 * lc, 2 * lc, 1, 1, 0, 1, st);
    if (!rc && cfg->use_post_quant_conv)
        rc = mx_conv_load(&v->post_quant_conv, b, "post_quant_conv", lc, lc, 1, 1, 0, 1, st);
    if (rc) {
        mx_fail_prefix(st, "loading the VAE");
        free(v);
        return -1;
    }
    *out = v;
    return 0;
}

void mx_vae_free(mx_vae *v) { free(v); }

static size_t max_channels(const mx_vae_config *c) {
    int m = c->in_channels > c->out_channels ? c->in_channels : c->out_channels;
    if (2 * c->latent_channels > m) m = 2 * c->latent_channels;
    for (int i = 0; i < c->nlevels; i++)
        if (c->block_out_channels[i] > m) m = c->block_out_channels[i];
    return (size_t)m;
}

/* Largest hidden state of the encoder (image H×W) or decoder (latent H×W), in floats: the
 * ping-pong buffer size. */
static size_t encoder_max(const mx_vae_config *c, int B, int H, int W) {
    size_t m = (size_t)2 * c->latent_channels, area = (size_t)H * W, prev = (size_t)c->block_out_channels[0];
    for (int i = 0; i < c->nlevels; i++, area /= 4) {
        size_t ch = (size_t)c->block_out_channels[i];
        if ((ch > prev ? ch : prev) * area > m) m = (ch > prev ? ch : prev) * area;
        prev = ch;
    }
    return (size_t)B * m;
}

static size_t decoder_max(const mx_vae_config *c, int B, int H, int W) {
    int n = c->nlevels;
    size_t area = (size_t)H * W, prev = (size_t)c->block_out_channels[n - 1], m = prev * area;
    for (int i = 0; i < n; i++) {
        size_t ch = (size_t)c->block_out_channels[n - 1 - i];
        if ((ch > prev ? ch : prev) * area > m) m = (ch > prev ? ch : prev) * area;
        if (i < n - 1) area *= 4;
        if (ch * area > m) m = ch * area;
        prev = ch;
    }
    return (size_t)B * m;
}

/* x -> mid block -> y, through one temporary (all at the smallest resolution). */
static int mid_run(mx_run *r, const vae_mid *m, float *y, const float *x, int B, int C, int h, int w) {
    size_t mark = mx_arena_mark(r->a);
    float *t = mx_run_alloc(r, (size_t)B * C * h * w);
    if (!t || mx_resnet_run(r, &m->res0, y, x, B, h, w, NULL)) return -1;
    if (m->has_attn) {
        if (mx_vae_attn_run(r, &m->attn, t, y, B, h, w)) return -1;
    } else {
        mx_copy(r->c, t, y, (size_t)B * C * h * w);
    }
    if (mx_resnet_run(r, &m->res1, y, t, B, h, w, NULL)) return -1;
    mx_arena_reset(r->a, mark);
    return 0;
}

static float *other(float *p[2], const float *cur) { return cur == p[0] ? p[1] : p[0]; }

static int encode_run(mx_run *r, const mx_vae *v, const float *image, int B, int H, int W, float *mean,
                      float *logvar) {
    const mx_vae_config *c = &v->cfg;
    const vae_half *e = &v->enc;
    size_t n = encoder_max(c, B, H, W);
    float *p[2] = {mx_run_alloc(r, n), mx_run_alloc(r, n)};
    if (!p[0] || !p[1]) return -1;
    float *h = p[0];
    mx_conv_run(r, &e->conv_in, h, image, B, H, W);
    for (int i = 0; i < c->nlevels; i++) {
        const vae_level *lv = &e->levels[i];
        for (int j = 0; j < lv->nres; j++) {
            if (mx_resnet_run_spending_x(r, &lv->res[j], other(p, h), h, B, H, W, NULL)) return -1;
            h = other(p, h);
        }
        if (lv->has_resample) {
            if (mx_down_run(r, &lv->down, other(p, h), h, B, H, W)) return -1;
            h = other(p, h);
            H /= 2;
            W /= 2;
        }
    }
    int C = c->block_out_channels[c->nlevels - 1], lc = c->latent_channels;
    if (mid_run(r, &e->mid, other(p, h), h, B, C, H, W)) return -1;
    h = other(p, h);
    mx_gn_run(r, &e->norm_out, other(p, h), h, B, H * W, 1);
    h = other(p, h);
    mx_conv_run(r, &e->conv_out, other(p, h), h, B, H, W);
    h = other(p, h);
    if (c->use_quant_conv) {
        mx_conv_run(r, &v->quant_conv, other(p, h), h, B, H, W);
        h = other(p, h);
    }
    /* moments = [mean | logvar] per item; logvar clamped to [-30, 20] as in DiagonalGaussianDistribution */
    size_t hw = (size_t)H * W, half = (size_t)lc * hw;
    for (int bi = 0; bi < B; bi++) {
        const float *mo = h + (size_t)bi * 2 * half;
        mx_copy(r->c, mean + (size_t)bi * half, mo, half);
        if (logvar) mx_clamp(r->c, logvar + (size_t)bi * half, mo + half, -30.0f, 20.0f, half);
    }
    return 0;
}

static int decode_run(mx_run *r, const void *net, const float *latents, int B, int H, int W, float *image) {
    const mx_vae *v = net;
    const mx_vae_config *c = &v->cfg;
    const vae_half *d = &v->dec;
    size_t n = decoder_max(c, B, H, W);
    float *p[2] = {mx_run_alloc(r, n), mx_run_alloc(r, n)};
    if (!p[0] || !p[1]) return -1;
    const float *z = latents;
    if (c->use_post_quant_conv) {
        mx_conv_run(r, &v->post_quant_conv, p[1], latents, B, H, W);
        z = p[1];
    }
    float *h = p[0];
    mx_conv_run(r, &d->conv_in, h, z, B, H, W);
    if (mid_run(r, &d->mid, other(p, h), h, B, c->block_out_channels[c->nlevels - 1], H, W)) return -1;
    h = other(p, h);
    for (int i = 0; i < c->nlevels; i++) {
        const vae_level *lv = &d->levels[i];
        for (int j = 0; j < lv->nres; j++) {
            if (mx_resnet_run_spending_x(r, &lv->res[j], other(p, h), h, B, H, W, NULL)) return -1;
            h = other(p, h);
        }
        if (lv->has_resample) {
            mx_up_run(r, &lv->up, other(p, h), h, B, H, W);
            h = other(p, h);
            H *= 2;
            W *= 2;
        }
    }
    mx_gn_run(r, &d->norm_out, other(p, h), h, B, H * W, 1);
    h = other(p, h);
    mx_conv_run(r, &d->conv_out, image, h, B, H, W);
    return 0;
}

static int check_sizes(const mx_vae *v, int B, int H, int W, int f, mx_status *st) {
    if (B < 1 || H < 1 || W < 1 || H % f || W % f)
        return mx_fail(st, MX_EINPUT, "VAE: bad sizes: batch %d, %d×%d (must be positive multiples of %d)", B, H, W, f);
    if ((double)B * max_channels(&v->cfg) * H * W > 2147483647.0)
        return mx_fail(st, MX_EINPUT, "VAE: sizes too large: batch %d, %d×%d", B, H, W);
    return 0;
}

int mx_vae_encode(const mx_ctx *c, const mx_vae *v, const float *image, int B, int H, int W, float *mean,
                  float *logvar, mx_arena *a, mx_status *st) {
    if (check_sizes(v, B, H, W, mx_vae_factor(v), st)) return -1;
    mx_run r;
    mx_run_init_prec(&r, v->fp32, c, a, st);
    size_t mark = mx_arena_mark(a);
    int rc = encode_run(&r, v, image, B, H, W, mean, logvar);
    mx_arena_reset(a, mark);
    return rc ? mx_fail_prefix(st, "VAE encode") : 0;
}

int mx_vae_decode(const mx_ctx *c, const mx_vae *v, const float *latents, int B, int h, int w, float *image,
                  mx_arena *a, mx_status *st) {
    int f = mx_vae_factor(v);
    if (check_sizes(v, B, h * f, w * f, f, st)) return -1;
    return mx_ae_run(c, v->fp32, decode_run, v, latents, B, h, w, image, a, st, "VAE decode");
}

int mx_vae_encode_arena_bytes(const mx_vae *v, int B, int H, int W, size_t *bytes, mx_status *st) {
    mx_arena a;
    mx_arena_measure(&a);
    if (mx_vae_encode(NULL, v, NULL, B, H, W, NULL, NULL, &a, st)) return -1;
    *bytes = a.peak + 4 * MX_ARENA_ALIGN;
    return 0;
}

int mx_vae_decode_arena_bytes(const mx_vae *v, int B, int h, int w, size_t *bytes, mx_status *st) {
    int f = mx_vae_factor(v);
    return check_sizes(v, B, h * f, w * f, f, st) ? -1 : mx_ae_dry_run(decode_run, v, B, h, w, bytes, NULL, st);
}

double mx_vae_decode_flops(const mx_vae *v, int B, int h, int w) {
    mx_status st;
    double flops = 0.0;
    int f = mx_vae_factor(v);
    if (check_sizes(v, B, h * f, w * f, f, &st) || mx_ae_dry_run(decode_run, v, B, h, w, NULL, &flops, &st)) return 0.0;
    return flops;
}

/* ---- the registry's entry points (registry.h) ---- */

int mx_vae_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st) {
    mx_vae_config cfg;
    return mx_vae_config_parse(&cfg, text, len, what, st) ? -1 : mx_vae_load((mx_vae **)net, &cfg, b, st);
}

/* run-net vae-encode: image [B,3,H,W] in [-1,1] -> mean, logvar. */
enum { ENC_IMAGE, ENC_MEAN, ENC_LOGVAR, ENC_N };
const mx_net_slot mx_vae_encode_slots[] = {
    [ENC_IMAGE] = {"image", MX_SLOT_IN},
    [ENC_MEAN] = {"mean", MX_SLOT_OUT},
    [ENC_LOGVAR] = {"logvar", MX_SLOT_OUT},
    [ENC_N] = {NULL, 0},
};

int mx_vae_encode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    const mx_vae *v = net;
    int64_t is[4] = {-1, v->cfg.in_channels, -1, -1};
    return io->shape(io, ENC_IMAGE, 4, is, st) ? -1 : mx_vae_encode_arena_bytes(v, (int)is[0], (int)is[2], (int)is[3], bytes, st);
}

int mx_vae_encode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    const mx_vae *v = net;
    int f = mx_vae_factor(v), lc = v->cfg.latent_channels;
    int64_t is[4] = {-1, v->cfg.in_channels, -1, -1};
    const float *img = mx_net_io_input(io, ENC_IMAGE, 4, is, st);
    if (!img) return -1;
    int B = (int)is[0], H = (int)is[2], W = (int)is[3];
    int64_t os[4] = {B, lc, H / f, W / f};
    float *mean = io->output(io, ENC_MEAN, 4, os, st), *logvar = mean ? io->output(io, ENC_LOGVAR, 4, os, st) : NULL;
    return logvar ? mx_vae_encode(c, v, img, B, H, W, mean, logvar, a, st) : -1;
}

/* run-net vae-decode: latents [B,4,h,w] (unscaled) -> image. */
enum { DEC_LATENTS, DEC_IMAGE, DEC_N };
const mx_net_slot mx_vae_decode_slots[] = {
    [DEC_LATENTS] = {"latents", MX_SLOT_IN},
    [DEC_IMAGE] = {"image", MX_SLOT_OUT},
    [DEC_N] = {NULL, 0},
};

int mx_vae_decode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    const mx_vae *v = net;
    int64_t ls[4] = {-1, v->cfg.latent_channels, -1, -1};
    return io->shape(io, DEC_LATENTS, 4, ls, st) ? -1 : mx_vae_decode_arena_bytes(v, (int)ls[0], (int)ls[2], (int)ls[3], bytes, st);
}

int mx_vae_decode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    const mx_vae *v = net;
    int f = mx_vae_factor(v);
    int64_t ls[4] = {-1, v->cfg.latent_channels, -1, -1};
    const float *lat = mx_net_io_input(io, DEC_LATENTS, 4, ls, st);
    if (!lat) return -1;
    int B = (int)ls[0], h = (int)ls[2], w = (int)ls[3];
    int64_t os[4] = {B, v->cfg.out_channels, (int64_t)h * f, (int64_t)w * f};
    float *img = io->output(io, DEC_IMAGE, 4, os, st);
    return img ? mx_vae_decode(c, v, lat, B, h, w, img, a, st) : -1;
}
