/* CLIP vision tower with projection, one function per stage, following transformers 4.39
 * modeling_clip.py (CLIPVisionEmbeddings, CLIPVisionTransformer, CLIPVisionModelWithProjection)
 * with eager attention. */
#include "clip_vision.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"

/* transformers' CLIPVisionConfig defaults (ViT-B/32). */
static void config_defaults(mx_clip_vision_config *cfg) {
    *cfg = (mx_clip_vision_config){.hidden_size = 768,
                                   .intermediate_size = 3072,
                                   .num_attention_heads = 12,
                                   .num_hidden_layers = 12,
                                   .num_channels = 3,
                                   .image_size = 224,
                                   .patch_size = 32,
                                   .projection_dim = 512,
                                   .layer_norm_eps = 1e-5f,
                                   .hidden_act = MX_TF_ACT_QUICK_GELU};
}

static int parse_members(mx_clip_vision_config *cfg, const mx_json *v, const char *what, mx_status *st) {
    if (mx_tf_json_int(v, "hidden_size", 1, 1 << 16, &cfg->hidden_size, what, st) ||
        mx_tf_json_int(v, "intermediate_size", 1, 1 << 18, &cfg->intermediate_size, what, st) ||
        mx_tf_json_int(v, "num_attention_heads", 1, 1024, &cfg->num_attention_heads, what, st) ||
        mx_tf_json_int(v, "num_hidden_layers", 1, 256, &cfg->num_hidden_layers, what, st) ||
        mx_tf_json_int(v, "num_channels", 1, 64, &cfg->num_channels, what, st) ||
        mx_tf_json_int(v, "image_size", 1, 4096, &cfg->image_size, what, st) ||
        mx_tf_json_int(v, "patch_size", 1, 4096, &cfg->patch_size, what, st) ||
        mx_tf_json_int(v, "projection_dim", 1, 1 << 16, &cfg->projection_dim, what, st) ||
        mx_tf_act_parse(mx_json_get_str(v, "hidden_act", "quick_gelu"), &cfg->hidden_act, what, st))
        return -1;
    cfg->layer_norm_eps = (float)mx_json_get_num(v, "layer_norm_eps", cfg->layer_norm_eps);
    if (cfg->hidden_size % cfg->num_attention_heads)
        return mx_fail(st, MX_EINPUT, "%s: hidden_size %d is not divisible by num_attention_heads %d", what,
                       cfg->hidden_size, cfg->num_attention_heads);
    if (cfg->image_size % cfg->patch_size)
        return mx_fail(st, MX_EINPUT, "%s: image_size %d is not a multiple of patch_size %d", what, cfg->image_size,
                       cfg->patch_size);
    if (mx_clip_vision_tokens(cfg) > 1 << 16)
        return mx_fail(st, MX_EINPUT, "%s: %d patches per image is too many", what, mx_clip_vision_tokens(cfg) - 1);
    if (!(cfg->layer_norm_eps > 0)) return mx_fail(st, MX_EINPUT, "%s: layer_norm_eps must be positive", what);
    return 0;
}

int mx_clip_vision_config_parse(mx_clip_vision_config *cfg, const char *json_text, size_t len, const char *what,
                                mx_status *st) {
    mx_json *root = mx_json_parse(json_text, len, what, st);
    if (!root) return -1;
    config_defaults(cfg);
    const mx_json *vision = mx_json_get(root, "vision_config"); /* a whole CLIPModel's config */
    const mx_json *v = mx_json_kind(vision) == MX_JSON_OBJ ? vision : root;
    int rc = mx_json_kind(root) != MX_JSON_OBJ ? mx_fail(st, MX_EINPUT, "%s: config is not a JSON object", what)
                                               : parse_members(cfg, v, what, st);
    /* CLIPModel keeps projection_dim at its top level */
    if (rc == 0 && v == vision) rc = mx_tf_json_int(root, "projection_dim", 1, 1 << 16, &cfg->projection_dim, what, st);
    mx_json_free(root);
    return rc;
}

int mx_clip_vision_tokens(const mx_clip_vision_config *cfg) {
    int g = cfg->image_size / cfg->patch_size;
    return 1 + g * g;
}

/* ---- parameters ---- */

static int bind_layer(mx_binder *b, const mx_tf_shape *s, int i, mx_tf_layer *l, mx_status *st) {
    char path[64];
    snprintf(path, sizeof path, "vision_model.encoder.layers.%d", i);
    return mx_tf_layer_bind(b, path, s, l, st);
}

int mx_clip_vision_load(mx_clip_vision **out, const mx_clip_vision_config *cfg, mx_binder *b, mx_status *st) {
    mx_clip_vision *m = calloc(1, sizeof *m);
    *out = m;
    if (!m) return mx_fail(st, MX_ENOMEM, "clip vision: out of memory");
    m->cfg = *cfg;
    m->shape = (mx_tf_shape){.hidden = cfg->hidden_size,
                             .intermediate = cfg->intermediate_size,
                             .heads = cfg->num_attention_heads,
                             .eps = cfg->layer_norm_eps,
                             .act = cfg->hidden_act,
                             .causal = 0};
    int64_t C = cfg->hidden_size, P = cfg->patch_size;
    m->layers = calloc((size_t)cfg->num_hidden_layers, sizeof *m->layers);
    if (!m->layers) return mx_fail(st, MX_ENOMEM, "clip vision: out of memory");
    if (mx_bind(b, &m->class_embedding, st, "vision_model.embeddings.class_embedding", 1, C) ||
        mx_bind(b, &m->patch_w, st, "vision_model.embeddings.patch_embedding.weight", 4, C,
                (int64_t)cfg->num_channels, P, P) ||
        mx_bind(b, &m->position_embedding, st, "vision_model.embeddings.position_embedding.weight", 2,
                (int64_t)mx_clip_vision_tokens(cfg), C) ||
        mx_tf_norm_bind(b, "vision_model.pre_layrnorm", C, &m->pre_ln_w, &m->pre_ln_b, st))
        goto fail;
    for (int i = 0; i < cfg->num_hidden_layers; i++)
        if (bind_layer(b, &m->shape, i, &m->layers[i], st)) goto fail;
    if (mx_tf_norm_bind(b, "vision_model.post_layernorm", C, &m->post_ln_w, &m->post_ln_b, st) ||
        mx_bind(b, &m->projection, st, "visual_projection.weight", 2, (int64_t)cfg->projection_dim, C))
        goto fail;
    return 0;
fail:
    mx_clip_vision_free(m);
    *out = NULL;
    return mx_fail_prefix(st, "loading the CLIP vision tower: ");
}

void mx_clip_vision_free(mx_clip_vision *m) {
    if (!m) return;
    free(m->layers);
    free(m);
}

/* ---- forward ---- */

/* x [B, T, C] = [class_embedding; patch_embedding(pixels)] + position_embedding, added in the
 * reference's order: the class row is class + pos[0] (embed_tokens with id 0 of the one-row class
 * table), the patch rows pos[t] (id -1: no token row) plus the patch's embedding. */
static int embed(const mx_clip_vision *m, const mx_ctx *c, mx_arena *a, const float *pixels, int B, float *x,
                 mx_status *st) {
    const mx_clip_vision_config *cfg = &m->cfg;
    int C = cfg->hidden_size, T = mx_clip_vision_tokens(cfg), G = cfg->image_size / cfg->patch_size, GG = G * G;
    size_t per_image = (size_t)GG * (size_t)C;
    int32_t *ids = malloc((size_t)B * (size_t)T * sizeof *ids);
    float *patches = mx_act_alloc(a, (size_t)B * per_image, st), *rows = mx_act_alloc(a, (size_t)B * per_image, st);
    if (!ids || !patches || !rows) {
        free(ids);
        return ids ? -1 : mx_fail(st, MX_ENOMEM, "clip vision: out of memory");
    }
    for (int i = 0; i < B * T; i++) ids[i] = i % T == 0 ? 0 : -1;
    mx_embed_tokens(c, x, ids, B, T, C, m->class_embedding, m->position_embedding);
    free(ids);
    mx_conv2d(c, patches, pixels, B, cfg->num_channels, cfg->image_size, cfg->image_size, m->patch_w, mx_w_none(), C,
              cfg->patch_size, cfg->patch_size, cfg->patch_size, 0);
    mx_transpose_chw_hwc(c, rows, patches, B, C, GG);
    for (int b = 0; b < B; b++) {
        float *dst = x + ((size_t)b * T + 1) * C;
        mx_add(c, dst, dst, rows + (size_t)b * per_image, per_image);
    }
    return 0;
}

int mx_clip_vision_forward(const mx_clip_vision *m, const mx_ctx *c, mx_arena *arena, const float *pixels, int B,
                           float *image_embeds, float *last_hidden, float *penultimate, mx_status *st) {
    const mx_clip_vision_config *cfg = &m->cfg;
    if (B < 1 || B > 1 << 16) return mx_fail(st, MX_EUSAGE, "clip vision: a batch of %d images", B);
    int C = cfg->hidden_size, T = mx_clip_vision_tokens(cfg), L = cfg->num_hidden_layers, M = B * T;
    size_t MC = (size_t)M * (size_t)C, mark = mx_arena_mark(arena);
    mx_tf_buffers bf;
    c = mx_run_ctx(c, arena);
    float *x = mx_act_alloc(arena, MC, st), *pooled = mx_act_alloc(arena, (size_t)B * C, st);
    if (!x || !pooled || mx_tf_buffers_alloc(arena, (size_t)M, &m->shape, &bf, st) || embed(m, c, arena, pixels, B, x, st))
        return mx_fail_prefix(st, "clip vision forward: ");
    mx_layer_norm(c, x, x, M, C, m->pre_ln_w, m->pre_ln_b, cfg->layer_norm_eps);
    /* hidden_states[-2]: the input of the last layer (the pre-LN output when there is one layer) */
    for (int i = 0; i < L; i++) {
        if (i == L - 1 && penultimate) mx_copy(c, penultimate, x, MC);
        mx_tf_layer_forward(c, &m->shape, &m->layers[i], x, B, T, &bf);
    }
    if (last_hidden) mx_copy(c, last_hidden, x, MC);
    for (int b = 0; b < B; b++) /* the class token of each image */
        mx_layer_norm(c, pooled + (size_t)b * C, x + (size_t)b * T * C, 1, C, m->post_ln_w, m->post_ln_b,
                      cfg->layer_norm_eps);
    if (image_embeds) mx_linear(c, image_embeds, pooled, m->projection, mx_w_none(), B, cfg->projection_dim, C);
    mx_arena_reset(arena, mark);
    return 0;
}

int mx_clip_vision_arena_bytes(const mx_clip_vision *m, int B, size_t *bytes, mx_status *st) {
    mx_arena dry;
    mx_arena_measure(&dry);
    if (mx_clip_vision_forward(m, NULL, &dry, mx_act_placeholder(), B, mx_act_placeholder(), NULL, NULL, st)) return -1;
    *bytes = dry.peak + 4 * MX_ARENA_ALIGN;
    return 0;
}

int mx_clip_vision_embed_images(const mx_ctx *c, const mx_clip_vision *m, const float *pixels, int B,
                                float *image_embeds, mx_status *st) {
    const mx_clip_vision_config *cfg = &m->cfg;
    size_t npix = (size_t)B * cfg->num_channels * cfg->image_size * cfg->image_size;
    size_t nout = (size_t)B * cfg->projection_dim, bytes;
    mx_arena arena;
    if (mx_clip_vision_arena_bytes(m, B, &bytes, st)) return -1;
    float *dpix = mx_dev_from_host(c, pixels, npix, st), *dout = dpix ? mx_dev_alloc(c, nout, st) : NULL;
    int rc = -1;
    if (dout && mx_arena_create_on(&arena, c->be, bytes, st) == 0) {
        rc = mx_clip_vision_forward(m, c, &arena, dpix, B, dout, NULL, NULL, st) ||
                     mx_download(c, image_embeds, dout, nout, st)
                 ? -1
                 : 0;
        mx_arena_destroy(&arena);
    }
    mx_dev_free(c, dout);
    mx_dev_free(c, dpix);
    return rc;
}

/* ---- the registry's entry points (registry.h) ---- */

int mx_clip_vision_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                               mx_status *st) {
    mx_clip_vision_config cfg;
    return mx_clip_vision_config_parse(&cfg, text, len, what, st) ? -1
                                                                   : mx_clip_vision_load((mx_clip_vision **)net, &cfg, b, st);
}

/* run-net clip-vision: pixel_values [B,3,S,S] -> image_embeds, last_hidden_state, penultimate_hidden_state. */
enum { CV_PIXELS, CV_EMBEDS, CV_LAST, CV_PENULT, CV_N };
const mx_net_slot mx_clip_vision_slots[] = {
    [CV_PIXELS] = {"pixel_values", MX_SLOT_IN},
    [CV_EMBEDS] = {"image_embeds", MX_SLOT_OUT},
    [CV_LAST] = {"last_hidden_state", MX_SLOT_OUT},
    [CV_PENULT] = {"penultimate_hidden_state", MX_SLOT_OUT},
    [CV_N] = {NULL, 0},
};

static void pixel_shape(const mx_clip_vision *m, int64_t ps[4]) {
    ps[0] = -1, ps[1] = m->cfg.num_channels, ps[2] = ps[3] = m->cfg.image_size;
}

int mx_clip_vision_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    int64_t ps[4];
    pixel_shape(net, ps);
    return io->shape(io, CV_PIXELS, 4, ps, st) ? -1 : mx_clip_vision_arena_bytes(net, (int)ps[0], bytes, st);
}

int mx_clip_vision_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    const mx_clip_vision *m = net;
    const mx_clip_vision_config *cfg = &m->cfg;
    int64_t ps[4];
    pixel_shape(m, ps);
    const float *pixels = mx_net_io_input(io, CV_PIXELS, 4, ps, st);
    if (!pixels) return -1;
    int B = (int)ps[0], T = mx_clip_vision_tokens(cfg);
    int64_t es[2] = {B, cfg->projection_dim}, hs[3] = {B, T, cfg->hidden_size};
    float *embeds, *last, *penult;
    if (!(embeds = io->output(io, CV_EMBEDS, 2, es, st)) || !(last = io->output(io, CV_LAST, 3, hs, st)) ||
        !(penult = io->output(io, CV_PENULT, 3, hs, st)))
        return -1;
    return mx_clip_vision_forward(m, c, a, pixels, B, embeds, last, penult, st);
}
