/* diffusers config.json -> mx_unet_config / mx_vae_config, with every size checked. */
#include "netcfg.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../runtime/json.h"
#include "../../weights/networks.h"

#define MAX_CHANNELS 16384
#define MAX_LAYERS 16
#define MAX_HEADS 1024

typedef struct cfg_reader {
    const mx_json *root;
    const char *what;
    mx_status *st;
} cfg_reader;

static int is_null(const mx_json *j) { return !j || mx_json_kind(j) == MX_JSON_NULL; }

static int int_value(const cfg_reader *r, const char *key, const mx_json *j, int lo, int hi, int *out) {
    double v = mx_json_num(j);
    if (mx_json_kind(j) != MX_JSON_NUM || v != floor(v) || v < lo || v > hi)
        return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" must be an integer in [%d, %d]", r->what, key, lo, hi);
    *out = (int)v;
    return 0;
}

/* Integer member; absent or null gives dflt. */
static int get_int(const cfg_reader *r, const char *key, int dflt, int lo, int hi, int *out) {
    const mx_json *j = mx_json_get(r->root, key);
    if (is_null(j)) {
        *out = dflt;
        return 0;
    }
    return int_value(r, key, j, lo, hi, out);
}

static int get_float(const cfg_reader *r, const char *key, double dflt, double lo, double hi, float *out) {
    const mx_json *j = mx_json_get(r->root, key);
    double v = is_null(j) ? dflt : mx_json_num(j);
    if ((!is_null(j) && mx_json_kind(j) != MX_JSON_NUM) || !(v >= lo && v <= hi))
        return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" must be a number in [%g, %g]", r->what, key, lo, hi);
    *out = (float)v;
    return 0;
}

static int get_bool(const cfg_reader *r, const char *key, int dflt, int *out) {
    const mx_json *j = mx_json_get(r->root, key);
    if (is_null(j)) {
        *out = dflt;
        return 0;
    }
    if (mx_json_kind(j) != MX_JSON_BOOL) return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" must be true or false", r->what, key);
    *out = mx_json_bool(j);
    return 0;
}

/* Integer array of 1..cap entries, each in [lo, hi]; returns the count in *n. */
static int get_int_array(const cfg_reader *r, const char *key, int cap, int lo, int hi, int *vals, int *n) {
    const mx_json *j = mx_json_get(r->root, key);
    if (mx_json_kind(j) != MX_JSON_ARR || mx_json_len(j) < 1 || mx_json_len(j) > (size_t)cap)
        return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" must be an array of 1 to %d integers", r->what, key, cap);
    *n = (int)mx_json_len(j);
    for (int i = 0; i < *n; i++)
        if (int_value(r, key, mx_json_at(j, (size_t)i), lo, hi, &vals[i])) return -1;
    return 0;
}

/* An int or a per-level list (diffusers accepts both for several keys). */
static int get_per_level(const cfg_reader *r, const char *key, int dflt, int nlevels, int lo, int hi, int *vals) {
    const mx_json *j = mx_json_get(r->root, key);
    if (mx_json_kind(j) == MX_JSON_ARR) {
        int n;
        if (get_int_array(r, key, MX_NET_MAX_LEVELS, lo, hi, vals, &n)) return -1;
        if (n != nlevels)
            return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" has %d entries, block_out_channels has %d", r->what, key, n,
                           nlevels);
        return 0;
    }
    int v;
    if (get_int(r, key, dflt, lo, hi, &v)) return -1;
    for (int i = 0; i < nlevels; i++) vals[i] = v;
    return 0;
}

/* Rejects a config feature matex does not implement: the key must be absent or null. */
static int require_null(const cfg_reader *r, const char *key) {
    if (!is_null(mx_json_get(r->root, key)))
        return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" is not supported (must be null)", r->what, key);
    return 0;
}

static int require_str(const cfg_reader *r, const char *key, const char *allowed) {
    const mx_json *j = mx_json_get(r->root, key);
    if (is_null(j)) return 0;
    const char *s = mx_json_str(j);
    if (!s || strcmp(s, allowed))
        return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" must be \"%s\"", r->what, key, allowed);
    return 0;
}

static int require_false(const cfg_reader *r, const char *key) {
    int v;
    if (get_bool(r, key, 0, &v)) return -1;
    if (v) return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" = true is not supported", r->what, key);
    return 0;
}

/* Block type list: each entry must be one of two names; flags[i] = 1 for `name1`. */
static int get_block_types(const cfg_reader *r, const char *key, int nlevels, const char *name0, const char *name1,
                           int *flags) {
    const mx_json *j = mx_json_get(r->root, key);
    if (mx_json_kind(j) != MX_JSON_ARR || mx_json_len(j) != (size_t)nlevels)
        return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" must list %d block types (one per block_out_channels entry)",
                       r->what, key, nlevels);
    for (int i = 0; i < nlevels; i++) {
        const char *s = mx_json_str(mx_json_at(j, (size_t)i));
        if (s && !strcmp(s, name0))
            flags[i] = 0;
        else if (s && name1 && !strcmp(s, name1))
            flags[i] = 1;
        else
            return mx_fail(r->st, MX_EINPUT, "%s: \"%s\"[%d] = \"%s\" is not supported (expected %s%s%s)", r->what,
                           key, i, s ? s : "?", name0, name1 ? " or " : "", name1 ? name1 : "");
    }
    return 0;
}

static int check_groups(const cfg_reader *r, const int *ch, int n, int groups) {
    for (int i = 0; i < n; i++)
        if (ch[i] % groups)
            return mx_fail(r->st, MX_EINPUT, "%s: block_out_channels[%d] = %d is not divisible by norm_num_groups %d",
                           r->what, i, ch[i], groups);
    return 0;
}

static int reject_unet_extras(const cfg_reader *r) {
    static const char *const null_keys[] = {"class_embed_type",   "addition_embed_type", "encoder_hid_dim_type",
                                            "time_cond_proj_dim", "timestep_post_act",   "time_embedding_act_fn",
                                            "num_class_embeds",   "cross_attention_norm"};
    for (size_t i = 0; i < sizeof null_keys / sizeof *null_keys; i++)
        if (require_null(r, null_keys[i])) return -1;
    if (require_str(r, "act_fn", "silu") || require_str(r, "resnet_time_scale_shift", "default") ||
        require_str(r, "time_embedding_type", "positional") || require_str(r, "attention_type", "default"))
        return -1;
    if (require_false(r, "only_cross_attention") || require_false(r, "dual_cross_attention") ||
        require_false(r, "center_input_sample") || require_false(r, "global_pool_conditions") ||
        require_false(r, "class_embeddings_concat") || require_false(r, "resnet_skip_time_act"))
        return -1;
    float s;
    if (get_float(r, "resnet_out_scale_factor", 1.0, 0, 1e6, &s)) return -1;
    if (s != 1.0f) return mx_fail(r->st, MX_EINPUT, "%s: \"resnet_out_scale_factor\" must be 1", r->what);
    return 0;
}

static int parse_heads(const cfg_reader *r, mx_unet_config *c) {
    /* diffusers: num_attention_heads = num_attention_heads or attention_head_dim (legacy
     * naming: in SD1.x configs attention_head_dim is the number of heads). */
    const char *key = is_null(mx_json_get(r->root, "num_attention_heads")) ? "attention_head_dim" : "num_attention_heads";
    if (get_per_level(r, key, 8, c->nlevels, 1, MAX_HEADS, c->heads)) return -1;
    for (int i = 0; i < c->nlevels; i++)
        if (c->block_out_channels[i] % c->heads[i])
            return mx_fail(r->st, MX_EINPUT, "%s: block_out_channels[%d] = %d is not divisible by %d heads (%s)",
                           r->what, i, c->block_out_channels[i], c->heads[i], key);
    return 0;
}

static int parse_controlnet_part(const cfg_reader *r, mx_unet_config *c) {
    if (get_int(r, "conditioning_channels", 3, 1, 64, &c->conditioning_channels)) return -1;
    int def[4] = {16, 32, 96, 256};
    if (is_null(mx_json_get(r->root, "conditioning_embedding_out_channels"))) {
        c->n_cond_emb = 4;
        memcpy(c->cond_emb_channels, def, sizeof def);
    } else if (get_int_array(r, "conditioning_embedding_out_channels", MX_NET_MAX_COND_CH, 1, MAX_CHANNELS,
                             c->cond_emb_channels, &c->n_cond_emb)) {
        return -1;
    }
    const char *order = mx_json_get_str(r->root, "controlnet_conditioning_channel_order", "rgb");
    if (strcmp(order, "rgb") && strcmp(order, "bgr"))
        return mx_fail(r->st, MX_EINPUT, "%s: \"controlnet_conditioning_channel_order\" must be rgb or bgr", r->what);
    c->cond_bgr = !strcmp(order, "bgr");
    return 0;
}

static int parse_unet(const cfg_reader *r, mx_unet_config *c) {
    memset(c, 0, sizeof *c);
    char cls[64];
    snprintf(cls, sizeof cls, "%s", mx_json_get_str(r->root, "_class_name", ""));
    if (!strcmp(cls, "ControlNetModel"))
        c->is_controlnet = 1;
    else if (strcmp(cls, "UNet2DConditionModel"))
        return mx_fail(r->st, MX_EINPUT, "%s: \"_class_name\" is \"%s\", expected UNet2DConditionModel or ControlNetModel",
                       r->what, cls);
    if (reject_unet_extras(r)) return -1;
    if (get_int_array(r, "block_out_channels", MX_NET_MAX_LEVELS, 1, MAX_CHANNELS, c->block_out_channels, &c->nlevels))
        return -1;
    if (get_int(r, "in_channels", 4, 1, 64, &c->in_channels) || get_int(r, "out_channels", 4, 1, 64, &c->out_channels) ||
        get_int(r, "layers_per_block", 2, 1, MAX_LAYERS, &c->layers_per_block) ||
        get_int(r, "norm_num_groups", 32, 1, MAX_CHANNELS, &c->norm_num_groups) ||
        get_float(r, "norm_eps", 1e-5, 1e-12, 1.0, &c->norm_eps) ||
        get_int(r, "cross_attention_dim", 768, 1, MAX_CHANNELS, &c->cross_attention_dim) ||
        get_bool(r, "use_linear_projection", 0, &c->use_linear_projection) ||
        get_bool(r, "flip_sin_to_cos", 1, &c->flip_sin_to_cos) || get_float(r, "freq_shift", 0, -1e6, 1e6, &c->freq_shift) ||
        get_int(r, "conv_in_kernel", 3, 1, 7, &c->conv_in_kernel) ||
        get_int(r, "conv_out_kernel", 3, 1, 7, &c->conv_out_kernel) ||
        get_int(r, "downsample_padding", 1, 0, 1, &c->downsample_padding) ||
        get_float(r, "mid_block_scale_factor", 1.0, 1e-6, 1e6, &c->mid_block_scale_factor) ||
        get_int(r, "time_embedding_dim", c->block_out_channels[0] * 4, 1, 4 * MAX_CHANNELS, &c->time_embed_dim))
        return -1;
    if (c->conv_in_kernel % 2 == 0 || c->conv_out_kernel % 2 == 0)
        return mx_fail(r->st, MX_EINPUT, "%s: conv_in_kernel / conv_out_kernel must be odd", r->what);
    if (c->nlevels * (c->layers_per_block + 1) + 1 > 64)
        return mx_fail(r->st, MX_EINPUT, "%s: too many blocks (levels × (layers_per_block + 1) > 63)", r->what);
    if (check_groups(r, c->block_out_channels, c->nlevels, c->norm_num_groups) ||
        get_per_level(r, "transformer_layers_per_block", 1, c->nlevels, 1, MAX_LAYERS, c->transformer_layers) ||
        parse_heads(r, c))
        return -1;
    if (get_block_types(r, "down_block_types", c->nlevels, "DownBlock2D", "CrossAttnDownBlock2D", c->down_cross)) return -1;
    if (!c->is_controlnet &&
        get_block_types(r, "up_block_types", c->nlevels, "UpBlock2D", "CrossAttnUpBlock2D", c->up_cross))
        return -1;
    const mx_json *mid = mx_json_get(r->root, "mid_block_type");
    if (mid && (!mx_json_str(mid) || strcmp(mx_json_str(mid), "UNetMidBlock2DCrossAttn")))
        return mx_fail(r->st, MX_EINPUT, "%s: \"mid_block_type\" must be \"UNetMidBlock2DCrossAttn\"", r->what);
    return c->is_controlnet ? parse_controlnet_part(r, c) : 0;
}

static int with_config(const char *text, size_t len, const char *what, mx_status *st, void *cfg,
                       int (*fn)(const cfg_reader *, void *)) {
    mx_json *root = mx_json_parse(text, len, what, st);
    if (!root) return -1;
    cfg_reader r = {root, what, st};
    int rc = mx_json_kind(root) == MX_JSON_OBJ ? fn(&r, cfg) : mx_fail(st, MX_EINPUT, "%s: not a JSON object", what);
    mx_json_free(root);
    return rc;
}

static int parse_unet_cb(const cfg_reader *r, void *cfg) { return parse_unet(r, cfg); }

int mx_unet_config_parse(mx_unet_config *cfg, const char *text, size_t len, const char *what, mx_status *st) {
    return with_config(text, len, what, st, cfg, parse_unet_cb);
}

static int parse_vae(const cfg_reader *r, void *out) {
    mx_vae_config *c = out;
    memset(c, 0, sizeof *c);
    if (strcmp(mx_json_get_str(r->root, "_class_name", "AutoencoderKL"), "AutoencoderKL"))
        return mx_fail(r->st, MX_EINPUT, "%s: \"_class_name\" must be AutoencoderKL", r->what);
    int dummy[MX_NET_MAX_LEVELS];
    if (get_int_array(r, "block_out_channels", MX_NET_MAX_LEVELS, 1, MAX_CHANNELS, c->block_out_channels, &c->nlevels) ||
        get_int(r, "in_channels", 3, 1, 64, &c->in_channels) || get_int(r, "out_channels", 3, 1, 64, &c->out_channels) ||
        get_int(r, "latent_channels", 4, 1, 64, &c->latent_channels) ||
        get_int(r, "layers_per_block", 1, 1, MAX_LAYERS, &c->layers_per_block) ||
        get_int(r, "norm_num_groups", 32, 1, MAX_CHANNELS, &c->norm_num_groups) ||
        get_bool(r, "mid_block_add_attention", 1, &c->mid_attention) ||
        get_bool(r, "use_quant_conv", 1, &c->use_quant_conv) ||
        get_bool(r, "use_post_quant_conv", 1, &c->use_post_quant_conv) ||
        get_float(r, "scaling_factor", 0.18215, -1e6, 1e6, &c->scaling_factor) || require_str(r, "act_fn", "silu") ||
        check_groups(r, c->block_out_channels, c->nlevels, c->norm_num_groups) ||
        get_block_types(r, "down_block_types", c->nlevels, "DownEncoderBlock2D", NULL, dummy) ||
        get_block_types(r, "up_block_types", c->nlevels, "UpDecoderBlock2D", NULL, dummy))
        return -1;
    return 0;
}

int mx_vae_config_parse(mx_vae_config *cfg, const char *text, size_t len, const char *what, mx_status *st) {
    return with_config(text, len, what, st, cfg, parse_vae);
}

/* Equal per-level arrays of the same length (the encoder's, decoder's and the shared one). */
static int taesd_channels(const cfg_reader *r, mx_taesd_config *c) {
    static const char *const keys[3] = {"block_out_channels", "encoder_block_out_channels", "decoder_block_out_channels"};
    for (int k = 0; k < 3; k++) {
        int ch[MX_NET_MAX_LEVELS], n;
        if (k > 0 && is_null(mx_json_get(r->root, keys[k]))) continue;
        if (get_int_array(r, keys[k], MX_NET_MAX_LEVELS, 1, MAX_CHANNELS, ch, &n)) return -1;
        if (k == 0) {
            c->nlevels = n;
            c->channels = ch[0];
        }
        for (int i = 0; i < n; i++)
            if (n != c->nlevels || ch[i] != c->channels)
                return mx_fail(r->st, MX_EINPUT, "%s: \"%s\": TAESD needs one channel count on every level", r->what,
                               keys[k]);
    }
    return 0;
}

static int taesd_blocks(const cfg_reader *r, const char *key, const mx_taesd_config *c, int *vals) {
    int n;
    if (get_int_array(r, key, MX_NET_MAX_LEVELS, 1, MAX_LAYERS, vals, &n)) return -1;
    if (n != c->nlevels)
        return mx_fail(r->st, MX_EINPUT, "%s: \"%s\" has %d entries, block_out_channels has %d", r->what, key, n,
                       c->nlevels);
    return 0;
}

static int parse_taesd(const cfg_reader *r, void *out) {
    mx_taesd_config *c = out;
    memset(c, 0, sizeof *c);
    if (strcmp(mx_json_get_str(r->root, "_class_name", "AutoencoderTiny"), "AutoencoderTiny"))
        return mx_fail(r->st, MX_EINPUT, "%s: \"_class_name\" must be AutoencoderTiny", r->what);
    float up = 2;
    if (taesd_channels(r, c) || taesd_blocks(r, "num_encoder_blocks", c, c->enc_blocks) ||
        taesd_blocks(r, "num_decoder_blocks", c, c->dec_blocks) ||
        get_int(r, "in_channels", 3, 1, 64, &c->in_channels) || get_int(r, "out_channels", 3, 1, 64, &c->out_channels) ||
        get_int(r, "latent_channels", 4, 1, 64, &c->latent_channels) ||
        get_float(r, "scaling_factor", 1.0, -1e6, 1e6, &c->scaling_factor) ||
        get_float(r, "upsampling_scaling_factor", 2.0, 2.0, 2.0, &up) || require_str(r, "act_fn", "relu") ||
        require_str(r, "upsample_fn", "nearest"))
        return -1;
    if (c->nlevels < 2) return mx_fail(r->st, MX_EINPUT, "%s: TAESD needs at least 2 levels", r->what);
    if (c->scaling_factor == 0.0f) return mx_fail(r->st, MX_EINPUT, "%s: \"scaling_factor\" must not be 0", r->what);
    return 0;
}

int mx_taesd_config_parse(mx_taesd_config *cfg, const char *text, size_t len, const char *what, mx_status *st) {
    return with_config(text, len, what, st, cfg, parse_taesd);
}

int mx_config_class_name(char *buf, size_t cap, const char *text, size_t len, const char *what, mx_status *st) {
    mx_json *root = mx_json_parse(text, len, what, st);
    if (!root) return -1;
    /* diffusers writes "_class_name"; transformers writes "architectures" and "model_type" */
    const char *cls = mx_json_get_str(root, "_class_name", NULL);
    const mx_json *arch = mx_json_get(root, "architectures");
    if (!cls && mx_json_len(arch) > 0) cls = mx_json_str(mx_json_at(arch, 0));
    const mx_net_kind *k = cls ? NULL : mx_net_kind_of_model_type(mx_json_get_str(root, "model_type", NULL));
    if (k) cls = k->class_name;
    snprintf(buf, cap, "%s", cls ? cls : "");
    mx_json_free(root);
    return 0;
}
