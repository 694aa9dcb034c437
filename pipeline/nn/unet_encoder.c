/* The UNet / ControlNet encoder half and its sizes (unet_2d_condition.py, controlnet.py). */
#include "unet_encoder.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "unet.h"

int mx_unet_num_residuals(const mx_unet_config *cfg) {
    return 1 + cfg->nlevels * cfg->layers_per_block + (cfg->nlevels - 1);
}

void mx_unet_residual_shape(const mx_unet_config *cfg, int i, int H, int W, int *C, int *h, int *w) {
    int k = 0; /* residual 0: conv_in output */
    *C = cfg->block_out_channels[0];
    *h = H;
    *w = W;
    for (int lv = 0; lv < cfg->nlevels && k < i; lv++) {
        for (int j = 0; j < cfg->layers_per_block && k < i; j++, k++) *C = cfg->block_out_channels[lv];
        if (lv < cfg->nlevels - 1 && k < i) {
            *h /= 2;
            *w /= 2;
            k++;
        }
    }
    if (i >= mx_unet_num_residuals(cfg)) *C = cfg->block_out_channels[cfg->nlevels - 1]; /* mid */
}


static int down_level_load(mx_down_level *lv, mx_binder *b, const mx_unet_config *c, int i, int cin, mx_status *st) {
    char path[128];
    lv->cross = c->down_cross[i];
    lv->cout = c->block_out_channels[i];
    lv->has_down = i < c->nlevels - 1;
    for (int j = 0; j < c->layers_per_block; j++) {
        snprintf(path, sizeof path, "down_blocks.%d.resnets.%d", i, j);
        if (mx_resnet_load(&lv->res[j], b, path, j == 0 ? cin : lv->cout, lv->cout, c->time_embed_dim,
                           c->norm_num_groups, c->norm_eps, 1.0f, st))
            return -1;
        snprintf(path, sizeof path, "down_blocks.%d.attentions.%d", i, j);
        if (lv->cross && mx_transformer_load(&lv->attn[j], b, path, lv->cout, c->heads[i], c->transformer_layers[i],
                                             c->cross_attention_dim, c->norm_num_groups, c->use_linear_projection, st))
            return -1;
    }
    snprintf(path, sizeof path, "down_blocks.%d.downsamplers.0", i);
    return lv->has_down ? mx_down_load(&lv->down, b, path, lv->cout, c->downsample_padding, st) : 0;
}

static int mid_load(mx_mid_block *m, mx_binder *b, const mx_unet_config *c, mx_status *st) {
    int n = c->nlevels - 1, ch = c->block_out_channels[n];
    if (mx_resnet_load(&m->res0, b, "mid_block.resnets.0", ch, ch, c->time_embed_dim, c->norm_num_groups, c->norm_eps,
                       c->mid_block_scale_factor, st))
        return -1;
    if (mx_transformer_load(&m->attn, b, "mid_block.attentions.0", ch, c->heads[n], c->transformer_layers[n],
                            c->cross_attention_dim, c->norm_num_groups, c->use_linear_projection, st))
        return -1;
    return mx_resnet_load(&m->res1, b, "mid_block.resnets.1", ch, ch, c->time_embed_dim, c->norm_num_groups,
                          c->norm_eps, c->mid_block_scale_factor, st);
}

int mx_unet_encoder_load(mx_unet_encoder *e, const mx_unet_config *cfg, mx_binder *b, mx_status *st) {
    memset(e, 0, sizeof *e);
    e->cfg = *cfg;
    const mx_unet_config *c = &e->cfg;
    if (c->layers_per_block > MX_ENC_MAX_LAYERS)
        return mx_fail(st, MX_EINPUT, "layers_per_block %d exceeds %d", c->layers_per_block, MX_ENC_MAX_LAYERS);
    if (mx_time_embed_load(&e->time, b, c->block_out_channels[0], c->time_embed_dim, c->flip_sin_to_cos,
                           c->freq_shift, st))
        return -1;
    if (mx_conv_load(&e->conv_in, b, "conv_in", c->in_channels, c->block_out_channels[0], c->conv_in_kernel, 1,
                     (c->conv_in_kernel - 1) / 2, 1, st))
        return -1;
    e->levels = calloc((size_t)c->nlevels, sizeof *e->levels);
    if (!e->levels) return mx_fail(st, MX_ENOMEM, "out of memory loading the UNet encoder");
    int cin = c->block_out_channels[0];
    for (int i = 0; i < c->nlevels; i++) {
        if (down_level_load(&e->levels[i], b, c, i, cin, st)) return -1;
        cin = c->block_out_channels[i];
    }
    return mid_load(&e->mid, b, c, st);
}

void mx_unet_encoder_free(mx_unet_encoder *e) {
    if (e->levels) {
        for (int i = 0; i < e->cfg.nlevels; i++)
            for (int j = 0; j < MX_ENC_MAX_LAYERS; j++) mx_transformer_free(&e->levels[i].attn[j]);
        free(e->levels);
        e->levels = NULL;
    }
    mx_transformer_free(&e->mid.attn);
}

int mx_unet_check_sizes(const mx_unet_config *cfg, int B, int H, int W, int T, mx_status *st) {
    int f = 1 << (cfg->nlevels - 1), cmax = 0;
    for (int i = 0; i < cfg->nlevels; i++)
        if (cfg->block_out_channels[i] > cmax) cmax = cfg->block_out_channels[i];
    if (B < 1 || H < 1 || W < 1 || T < 1)
        return mx_fail(st, MX_EINPUT, "bad sizes: batch %d, latent %d×%d, %d context tokens", B, H, W, T);
    if (H % f || W % f)
        return mx_fail(st, MX_EINPUT, "latent size %d×%d is not a multiple of %d (2^(levels-1))", H, W, f);
    /* Largest activation: the GEGLU buffer, B·H·W·8·C floats; keep every index in int range. */
    if ((double)B * H * W * 8.0 * cmax > 2147483647.0 || (double)B * T * cfg->cross_attention_dim > 2147483647.0)
        return mx_fail(st, MX_EINPUT, "sizes too large: batch %d, latent %d×%d", B, H, W);
    return 0;
}

/* The end of a shared batch (blocks.h) before a transformer: the skips res[0..k] so far, and the
 * transformer's input x (xn floats per item) when it is not one of them, copied to item 1. */
static void unshare(mx_run *r, const mx_unet_config *c, float *const *res, int k, float *x, size_t xn, int H, int W) {
    if (!r->shared) return;
    for (int i = 0; i <= k; i++) {
        int C, h, w;
        mx_unet_residual_shape(c, i, H, W, &C, &h, &w);
        mx_run_copy_item(r, res[i], (size_t)C * h * w);
    }
    if (x) mx_run_copy_item(r, x, xn);
}

int mx_unet_encoder_run(mx_run *r, const mx_unet_encoder *e, const float *sample, const float *add, int B, int H,
                        int W, const float *temb_silu, const float *context, int T, const mx_ip_guide *ip,
                        float *const *res, float *mid) {
    const mx_unet_config *c = &e->cfg;
    int b = mx_run_batch(r, B); /* items computed: 1 while the batch is shared */
    mx_conv_run(r, &e->conv_in, res[0], sample, b, H, W);
    if (add) mx_add(r->c, res[0], res[0], add, (size_t)b * c->block_out_channels[0] * H * W);
    int k = 0, h = H, w = W;
    for (int i = 0; i < c->nlevels; i++) {
        const mx_down_level *lv = &e->levels[i];
        for (int j = 0; j < c->layers_per_block; j++) {
            float *dst = res[k + 1];
            if (mx_resnet_run(r, &lv->res[j], dst, res[k], mx_run_batch(r, B), h, w, temb_silu)) return -1;
            if (lv->cross) {
                unshare(r, c, res, k + 1, NULL, 0, H, W);
                size_t mark = mx_arena_mark(r->a);
                float *t = mx_run_alloc(r, (size_t)B * lv->cout * h * w);
                if (!t || mx_transformer_run(r, &lv->attn[j], t, dst, B, h, w, context, T, ip)) return -1;
                mx_copy(r->c, dst, t, (size_t)B * lv->cout * h * w);
                mx_arena_reset(r->a, mark);
            }
            k++;
        }
        if (lv->has_down) {
            if (mx_down_run(r, &lv->down, res[k + 1], res[k], mx_run_batch(r, B), h, w)) return -1;
            k++;
            h /= 2;
            w /= 2;
        }
    }
    /* mid block: resnet -> transformer -> resnet, ping-ponging through one temporary */
    size_t mark = mx_arena_mark(r->a);
    int ch = c->block_out_channels[c->nlevels - 1];
    float *t = mx_run_alloc(r, (size_t)B * ch * h * w);
    if (!t || mx_resnet_run(r, &e->mid.res0, mid, res[k], mx_run_batch(r, B), h, w, temb_silu)) return -1;
    unshare(r, c, res, k, mid, (size_t)ch * h * w, H, W);
    r->shared = 0;
    if (mx_transformer_run(r, &e->mid.attn, t, mid, B, h, w, context, T, ip) ||
        mx_resnet_run(r, &e->mid.res1, mid, t, B, h, w, temb_silu))
        return -1;
    mx_arena_reset(r->a, mark);
    return 0;
}
