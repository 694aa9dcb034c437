/* Single-file SD1.x checkpoints (single_file.h): which container, which networks, which
 * architecture, and each network's tensors under diffusers names. */
#include "single_file.h"

#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../runtime/buf.h"
#include "ldm_names.h"
#include "networks.h"
#include "torchzip.h"

#define NAME_MAX_LEN 1024

typedef struct {
    const char *prefix;
    mx_ldm_net net;
    const char *kind;
} part;

static const part parts[] = {
    {"model.diffusion_model.", MX_LDM_UNET, MX_NET_UNET},
    {"control_model.", MX_LDM_CONTROLNET, MX_NET_CONTROLNET},
    {"first_stage_model.", MX_LDM_VAE, MX_NET_VAE},
    {"cond_stage_model.transformer.", MX_LDM_CLIP, MX_NET_TEXT_ENCODER},
};

static int starts(const char *s, const char *pre) { return !strncmp(s, pre, strlen(pre)); }

int mx_sf_is_file(const char *path) {
    struct stat sb;
    return stat(path, &sb) == 0 && S_ISREG(sb.st_mode);
}

/* A tensor of the file by printf-formatted name, or NULL. */
static const mx_st_tensor *find(const mx_single_file *sf, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static const mx_st_tensor *find(const mx_single_file *sf, const char *fmt, ...) {
    char name[NAME_MAX_LEN];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(name, sizeof name, fmt, ap);
    va_end(ap);
    return n < (int)sizeof name ? mx_st_find(&sf->src, name) : NULL;
}

/* Dimension d of a tensor, -1 when the tensor is absent or has fewer dimensions. */
static int64_t dim(const mx_st_tensor *t, int d) { return t && d < t->ndim ? t->shape[d] : -1; }

/* Largest index N in names PREFIX+"pattern-head"+N+"." ("input_blocks.", ...), -1 if none. */
static int max_index(const mx_single_file *sf, const char *prefix, const char *head) {
    int best = -1;
    size_t pl = strlen(prefix), hl = strlen(head);
    for (size_t i = 0; i < sf->src.count; i++) {
        const char *s = sf->src.tensors[i].name;
        if (strncmp(s, prefix, pl) || strncmp(s + pl, head, hl)) continue;
        char *end;
        long v = strtol(s + pl + hl, &end, 10);
        if (end != s + pl + hl && *end == '.' && v >= 0 && v < 100000 && v > best) best = (int)v;
    }
    return best;
}

static void note_skipped(mx_single_file *sf, const char *name) {
    sf->skipped++;
    if (!sf->skipped_example[0]) snprintf(sf->skipped_example, sizeof sf->skipped_example, "%s", name);
}

/* ---- architecture ---- */

static int unet_layout(mx_single_file *sf, const char *pre, mx_ldm_net net, mx_ldm_layout *l, mx_status *st) {
    int max_in = max_index(sf, pre, "input_blocks.");
    int first_op = -1;
    for (int i = 1; i <= max_in && first_op < 0; i++)
        if (find(sf, "%sinput_blocks.%d.0.op.weight", pre, i)) first_op = i;
    if (max_in < 1) return mx_fail(st, MX_EINPUT, "%s: %sinput_blocks.* missing: not an SD1.x UNet", sf->src.path, pre);
    l->layers_per_block = first_op > 1 ? first_op - 1 : max_in;
    l->levels = (max_in - 1) / (l->layers_per_block + 1) + 1;
    if (l->levels > 8) return mx_fail(st, MX_EINPUT, "%s: %d UNet levels: not an SD1.x UNet", sf->src.path, l->levels);
    int per = l->layers_per_block + 1;
    l->up_attention = 0;
    for (int b = 0; b < l->levels; b++)
        if (find(sf, "%soutput_blocks.%d.1.proj_in.weight", pre, b * per)) l->up_attention |= 1u << b;
    l->hint_convs = net == MX_LDM_CONTROLNET ? max_index(sf, pre, "input_hint_block.") / 2 + 1 : 0;
    return 0;
}

/* SD1.x only: 4 input channels, convolutional proj_in, cross-attention from a 768-wide CLIP
 * (other widths are the test models'; 1024 is SD2.x's OpenCLIP). */
static int check_unet_arch(mx_single_file *sf, const char *pre, const char *kind, mx_status *st) {
    const mx_st_tensor *conv_in = find(sf, "%sinput_blocks.0.0.weight", pre);
    const mx_st_tensor *k = NULL, *proj = NULL;
    for (size_t i = 0; i < sf->src.count && (!k || !proj); i++) {
        const char *s = sf->src.tensors[i].name;
        if (!starts(s, pre)) continue;
        size_t n = strlen(s);
        if (!k && n > 17 && !strcmp(s + n - 17, "attn2.to_k.weight")) k = &sf->src.tensors[i];
        if (!proj && n > 14 && !strcmp(s + n - 14, "proj_in.weight")) proj = &sf->src.tensors[i];
    }
    const char *path = sf->src.path;
    if (dim(conv_in, 1) == 9)
        return mx_fail(st, MX_EINPUT, "%s: a 9-channel inpainting UNet (SD1.x inpainting); matex supports the "
                       "4-channel SD1.x UNet (inpainting goes through the ControlNet inpaint model)", path);
    if (dim(k, 1) == 1024 || (proj && proj->ndim == 2))
        return mx_fail(st, MX_EINPUT, "%s: a Stable Diffusion 2.x %s (1024-wide cross-attention or linear proj_in); "
                       "matex supports SD1.x", path, kind);
    if (dim(conv_in, 1) != 4 || conv_in->ndim != 4 || !k)
        return mx_fail(st, MX_EINPUT, "%s: %s with %lld input channels%s: not an SD1.x %s", path, kind,
                       (long long)dim(conv_in, 1), k ? "" : " and no cross-attention", kind);
    return 0;
}

/* ---- configs made from the shapes ---- */

static void put_int_list(mx_buf *b, const char *key, const int64_t *v, int n) {
    mx_buf_printf(b, ", \"%s\": [", key);
    for (int i = 0; i < n; i++) mx_buf_printf(b, "%s%lld", i ? ", " : "", (long long)v[i]);
    mx_buf_put(b, "]", 1);
}

static void put_block_types(mx_buf *b, const char *key, unsigned attn, int n, const char *plain, const char *cross) {
    mx_buf_printf(b, ", \"%s\": [", key);
    for (int i = 0; i < n; i++) mx_buf_printf(b, "%s\"%s\"", i ? ", " : "", (attn >> i) & 1 ? cross : plain);
    mx_buf_put(b, "]", 1);
}

static int unet_config(mx_single_file *sf, const char *pre, mx_ldm_net net, const mx_ldm_layout *l, mx_buf *b,
                       mx_status *st) {
    int per = l->layers_per_block + 1;
    int64_t ch[8];
    unsigned down_attn = 0;
    for (int i = 0; i < l->levels; i++) {
        ch[i] = dim(find(sf, "%sinput_blocks.%d.0.out_layers.3.weight", pre, 1 + i * per), 0);
        if (ch[i] <= 0) return mx_fail(st, MX_EINPUT, "%s: %sinput_blocks.%d.0 is not a resnet", sf->src.path, pre, 1 + i * per);
        if (find(sf, "%sinput_blocks.%d.1.proj_in.weight", pre, 1 + i * per)) down_attn |= 1u << i;
    }
    int64_t ctx = -1;
    for (size_t i = 0; i < sf->src.count && ctx < 0; i++) {
        const char *s = sf->src.tensors[i].name;
        size_t n = strlen(s);
        if (starts(s, pre) && n > 17 && !strcmp(s + n - 17, "attn2.to_k.weight")) ctx = dim(&sf->src.tensors[i], 1);
    }
    if (net == MX_LDM_UNET) sf->sd15_sizes = ch[0] == 320 && ctx == 768;
    mx_buf_printf(b, "{\"_class_name\": \"%s\", \"matex_source\": \"single file\"",
                  net == MX_LDM_UNET ? "UNet2DConditionModel" : "ControlNetModel");
    put_int_list(b, "block_out_channels", ch, l->levels);
    mx_buf_printf(b, ", \"layers_per_block\": %d, \"cross_attention_dim\": %lld, \"attention_head_dim\": 8, "
                     "\"in_channels\": 4, \"norm_num_groups\": 32, \"use_linear_projection\": false",
                  l->layers_per_block, (long long)ctx);
    put_block_types(b, "down_block_types", down_attn, l->levels, "DownBlock2D", "CrossAttnDownBlock2D");
    if (net == MX_LDM_UNET) {
        mx_buf_printf(b, ", \"out_channels\": %lld, \"sample_size\": 64", (long long)dim(find(sf, "%sout.2.weight", pre), 0));
        put_block_types(b, "up_block_types", l->up_attention, l->levels, "UpBlock2D", "CrossAttnUpBlock2D");
    } else {
        int64_t cond[8];
        int n = 0;
        for (int i = 0; i < l->hint_convs - 1 && n < 8; i++)
            if (i == 0 || (i >= 2 && i % 2 == 0)) cond[n++] = dim(find(sf, "%sinput_hint_block.%d.weight", pre, 2 * i), 0);
        put_int_list(b, "conditioning_embedding_out_channels", cond, n);
        mx_buf_printf(b, ", \"conditioning_channels\": %lld",
                      (long long)dim(find(sf, "%sinput_hint_block.0.weight", pre), 1));
    }
    mx_buf_put(b, "}", 1);
    return 0;
}

static int vae_config(mx_single_file *sf, const char *pre, const mx_ldm_layout *l, mx_buf *b, mx_status *st) {
    int64_t ch[8];
    for (int i = 0; i < l->levels; i++)
        if ((ch[i] = dim(find(sf, "%sencoder.down.%d.block.0.conv2.weight", pre, i), 0)) <= 0)
            return mx_fail(st, MX_EINPUT, "%s: %sencoder.down.%d.block.0 missing: not an SD1.x VAE", sf->src.path, pre, i);
    mx_buf_printf(b, "{\"_class_name\": \"AutoencoderKL\", \"matex_source\": \"single file\"");
    put_int_list(b, "block_out_channels", ch, l->levels);
    mx_buf_printf(b, ", \"layers_per_block\": %d, \"in_channels\": %lld, \"out_channels\": %lld, \"latent_channels\": %lld, "
                     "\"norm_num_groups\": 32, \"scaling_factor\": 0.18215",
                  l->layers_per_block, (long long)dim(find(sf, "%sencoder.conv_in.weight", pre), 1),
                  (long long)dim(find(sf, "%sdecoder.conv_out.weight", pre), 0),
                  (long long)dim(find(sf, "%spost_quant_conv.weight", pre), 0));
    put_block_types(b, "down_block_types", 0, l->levels, "DownEncoderBlock2D", "");
    put_block_types(b, "up_block_types", 0, l->levels, "UpDecoderBlock2D", "");
    mx_buf_put(b, "}", 1);
    return 0;
}

static int clip_config(mx_single_file *sf, const char *pre, mx_buf *b, mx_status *st) {
    const char *tm = find(sf, "%stext_model.embeddings.token_embedding.weight", pre) ? "text_model." : "";
    const mx_st_tensor *tok = find(sf, "%s%sembeddings.token_embedding.weight", pre, tm);
    const mx_st_tensor *pos = find(sf, "%s%sembeddings.position_embedding.weight", pre, tm);
    const mx_st_tensor *fc1 = find(sf, "%s%sencoder.layers.0.mlp.fc1.weight", pre, tm);
    char head[128];
    snprintf(head, sizeof head, "%sencoder.layers.", tm);
    int layers = max_index(sf, pre, head) + 1;
    int64_t hidden = dim(tok, 1);
    if (!tok || !pos || !fc1 || layers < 1 || hidden < 1)
        return mx_fail(st, MX_EINPUT, "%s: %s* is not a CLIP text encoder of SD1.x (width %lld)", sf->src.path, pre,
                       (long long)hidden);
    mx_buf_printf(b, "{\"architectures\": [\"CLIPTextModel\"], \"model_type\": \"clip_text_model\", "
                     "\"matex_source\": \"single file\", \"hidden_act\": \"quick_gelu\", \"hidden_size\": %lld, "
                     "\"intermediate_size\": %lld, \"num_hidden_layers\": %d, \"num_attention_heads\": %lld, "
                     "\"max_position_embeddings\": %lld, \"vocab_size\": %lld, \"layer_norm_eps\": 1e-05, "
                     "\"bos_token_id\": 0, \"eos_token_id\": 2, \"pad_token_id\": 1}",
                  (long long)hidden, (long long)dim(fc1, 0), layers, (long long)(hidden % 64 ? 1 : hidden / 64), (long long)dim(pos, 0),
                  (long long)dim(tok, 0));
    return 0;
}

/* ---- one network ---- */

/* The EMA copy of UNet tensor NAME: model_ema. + "diffusion_model.NAME" without its dots. */
static const mx_st_tensor *ema_of(const mx_single_file *sf, const char *ldm_name) {
    char key[NAME_MAX_LEN] = "model_ema.";
    size_t n = strlen(key);
    for (const char *s = "diffusion_model."; *s && n + 1 < sizeof key; s++)
        if (*s != '.') key[n++] = *s;
    for (const char *s = ldm_name; *s && n + 1 < sizeof key; s++)
        if (*s != '.') key[n++] = *s;
    key[n] = 0;
    return mx_st_find(&sf->src, key);
}

static int skipped_in_part(mx_ldm_net net, const char *name) {
    return net == MX_LDM_CLIP && strstr(name, "position_ids") != NULL;
}

/* The tensors of a VAE file of its own: the autoencoder's, not its training loss (loss.*). */
static int in_bare_vae(const char *name) {
    return starts(name, "encoder.") || starts(name, "decoder.") || starts(name, "quant_conv.") ||
           starts(name, "post_quant_conv.");
}

static int add_net_tensor(mx_single_file *sf, mx_sf_net *out, const part *p, const char *pre, const mx_ldm_layout *l,
                          const mx_st_tensor *t, int flags, mx_status *st) {
    char dname[NAME_MAX_LEN];
    const char *ldm = t->name + strlen(pre);
    if (mx_ldm_to_diffusers(p->net, l, ldm, dname, sizeof dname))
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s' is not part of an SD1.x %s", sf->src.path, t->name, p->kind);
    mx_st_tensor *o = &out->tensors[out->count];
    *o = *t;
    if (p->net == MX_LDM_UNET && (flags & MX_SF_EMA)) {
        const mx_st_tensor *e = ema_of(sf, ldm);
        if (!e || e->dtype != t->dtype || e->nbytes != t->nbytes)
            return mx_fail(st, MX_EINPUT, "%s: --ema: no EMA copy of '%s' of the same type and size", sf->src.path, t->name);
        o->data = e->data;
    }
    if (p->net == MX_LDM_VAE && mx_ldm_vae_attn_linear(dname) && t->ndim == 4 && t->shape[2] == 1 && t->shape[3] == 1)
        o->ndim = 2; /* LDM's 1x1 convolution is diffusers' linear layer: same bytes */
    if (!(o->name = strdup(dname))) return mx_fail(st, MX_ENOMEM, "%s: out of memory", sf->src.path);
    out->count++;
    return 0;
}

static int add_part(mx_single_file *sf, const part *p, const char *pre, int flags, mx_status *st) {
    mx_ldm_layout l = {0};
    if (p->net == MX_LDM_UNET || p->net == MX_LDM_CONTROLNET) {
        if (check_unet_arch(sf, pre, p->kind, st) || unet_layout(sf, pre, p->net, &l, st)) return -1;
    } else if (p->net == MX_LDM_VAE) {
        l.levels = max_index(sf, pre, "encoder.down.") + 1;
        char head[64];
        snprintf(head, sizeof head, "encoder.down.0.block.");
        l.layers_per_block = max_index(sf, pre, head) + 1;
        if (l.levels < 1 || l.levels > 8 || l.layers_per_block < 1)
            return mx_fail(st, MX_EINPUT, "%s: %sencoder.down.* missing: not an SD1.x VAE", sf->src.path, pre);
    }
    mx_sf_net *n = &sf->nets[sf->n_nets];
    n->kind = p->kind;
    if (!(n->tensors = calloc(sf->src.count, sizeof *n->tensors)))
        return mx_fail(st, MX_ENOMEM, "%s: out of memory", sf->src.path);
    sf->n_nets++;
    size_t pl = strlen(pre);
    for (size_t i = 0; i < sf->src.count; i++) {
        const mx_st_tensor *t = &sf->src.tensors[i];
        if (strncmp(t->name, pre, pl)) continue;
        if (!pl && p->net == MX_LDM_VAE && !in_bare_vae(t->name)) continue;
        if (skipped_in_part(p->net, t->name)) {
            note_skipped(sf, t->name);
            continue;
        }
        if (add_net_tensor(sf, n, p, pre, &l, t, flags, st)) return -1;
    }
    mx_buf b = {0};
    int rc = p->net == MX_LDM_VAE    ? vae_config(sf, pre, &l, &b, st)
             : p->net == MX_LDM_CLIP ? clip_config(sf, pre, &b, st)
                                     : unet_config(sf, pre, p->net, &l, &b, st);
    if (!rc && b.oom) rc = mx_fail(st, MX_ENOMEM, "%s: out of memory", sf->src.path);
    if (rc) {
        mx_buf_free(&b);
        return -1;
    }
    n->config = b.p;
    return 0;
}

/* ---- the schedule ---- */

/* SD1.5's alphas_cumprod: betas linear in sqrt from 0.00085 to 0.012 over 1000 steps. */
static int check_schedule(mx_single_file *sf, mx_status *st) {
    const mx_st_tensor *t = mx_st_find(&sf->src, "alphas_cumprod");
    if (!t) return 0;
    if (t->ndim != 1 || t->shape[0] != 1000)
        return mx_fail(st, MX_EINPUT, "%s: alphas_cumprod has not 1000 steps: not SD1.5's schedule", sf->src.path);
    float *a = mx_st_to_f32(&sf->src, t, st);
    if (!a) return -1;
    double prod = 1, lo = sqrt(0.00085), hi = sqrt(0.012);
    int rc = 0;
    for (int i = 0; i < 1000 && !rc; i++) {
        double s = lo + (hi - lo) * i / 999.0;
        prod *= 1 - s * s;
        double tol = (t->dtype == MX_ST_F32 || t->dtype == MX_ST_F64 ? 1e-5 : 4e-3) * prod + 1e-7;
        if (fabs(a[i] - prod) > tol)
            rc = mx_fail(st, MX_EINPUT,
                         "%s: alphas_cumprod[%d] = %.6g, SD1.5's scaled-linear schedule has %.6g: another noise "
                         "schedule (matex supports SD1.5's)",
                         sf->src.path, i, (double)a[i], prod);
    }
    free(a);
    sf->schedule_checked = !rc;
    return rc;
}

/* ---- the whole file ---- */

static int refuse_other_models(const mx_single_file *sf, mx_status *st) {
    for (size_t i = 0; i < sf->src.count; i++) {
        const char *s = sf->src.tensors[i].name;
        if (starts(s, "conditioner."))
            return mx_fail(st, MX_EINPUT, "%s: an SDXL checkpoint (conditioner.*); matex supports SD1.x", sf->src.path);
        if (starts(s, "cond_stage_model.model."))
            return mx_fail(st, MX_EINPUT, "%s: a Stable Diffusion 2.x checkpoint (OpenCLIP text encoder); matex "
                           "supports SD1.x", sf->src.path);
    }
    return 0;
}

static int has_prefix(const mx_single_file *sf, const char *pre) {
    for (size_t i = 0; i < sf->src.count; i++)
        if (starts(sf->src.tensors[i].name, pre)) return 1;
    return 0;
}

int mx_sf_open_tensors(mx_safetensors *src, const char *path, const char **container, size_t *skipped,
                       mx_status *st) {
    FILE *f = fopen(path, "rb");
    unsigned char head[8] = {0};
    size_t n = f ? fread(head, 1, sizeof head, f) : 0;
    if (f) fclose(f);
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open", path);
    if (mx_torchzip_is_zip(head, n)) {
        *container = "PyTorch zip";
        return mx_torchzip_open(src, path, skipped, st);
    }
    if (n >= 2 && head[0] == 0x80 && head[1] <= 5)
        return mx_fail(st, MX_EINPUT, "%s: a PyTorch checkpoint in the legacy format (before PyTorch 1.6), which "
                       "matex does not read; use its .safetensors copy", path);
    *container = "safetensors";
    return mx_st_open(src, path, st);
}

/* A VAE file in diffusers names: renamed to the LDM layout in place (attention projections back
 * to 1x1 convolutions), so that one path reads both. */
static int rename_diffusers_vae(mx_single_file *sf, mx_status *st) {
    mx_ldm_layout l = {.levels = max_index(sf, "", "encoder.down_blocks.") + 1};
    for (size_t i = 0; i < sf->src.count; i++) {
        mx_st_tensor *t = &sf->src.tensors[i];
        char ldm[NAME_MAX_LEN];
        if (!in_bare_vae(t->name)) continue;
        if (mx_diffusers_to_ldm(MX_LDM_VAE, &l, t->name, ldm, sizeof ldm))
            return mx_fail(st, MX_EINPUT, "%s: tensor '%s' is not part of an SD1.x VAE", sf->src.path, t->name);
        if (mx_ldm_vae_attn_linear(t->name) && t->ndim == 2) {
            t->ndim = 4;
            t->shape[2] = t->shape[3] = 1;
        }
        char *name = strdup(ldm);
        if (!name) return mx_fail(st, MX_ENOMEM, "%s: out of memory", sf->src.path);
        free(t->name);
        t->name = name;
    }
    mx_st_sort(&sf->src);
    return 0;
}

static int convert_parts(mx_single_file *sf, int flags, mx_status *st) {
    int any_prefixed = 0;
    for (size_t i = 0; i < sizeof parts / sizeof parts[0]; i++) {
        if (!has_prefix(sf, parts[i].prefix)) continue;
        any_prefixed = 1;
        if ((flags & MX_SF_CONTROLNET_ONLY) && parts[i].net != MX_LDM_CONTROLNET) continue;
        if ((flags & MX_SF_VAE_ONLY) && parts[i].net != MX_LDM_VAE) continue;
        if (add_part(sf, &parts[i], parts[i].prefix, flags, st)) return -1;
    }
    if (!any_prefixed && mx_st_find(&sf->src, "input_hint_block.0.weight")) /* a bare ControlNet */
        return add_part(sf, &parts[1], "", flags, st);
    if (!any_prefixed && (flags & MX_SF_VAE_ONLY) && mx_st_find(&sf->src, "encoder.down_blocks.0.resnets.0.conv1.weight") &&
        rename_diffusers_vae(sf, st))
        return -1;
    if (!any_prefixed && (flags & MX_SF_VAE_ONLY) && mx_st_find(&sf->src, "encoder.conv_in.weight")) /* a bare VAE */
        return add_part(sf, &parts[2], "", flags, st);
    return 0;
}

static void count_skipped(mx_single_file *sf) {
    for (size_t i = 0; i < sf->src.count; i++) {
        const char *s = sf->src.tensors[i].name;
        int used = 0;
        for (size_t k = 0; k < sf->n_nets && !used; k++)
            for (size_t j = 0; j < sf->nets[k].count && !used; j++) used = sf->nets[k].tensors[j].data == sf->src.tensors[i].data;
        if (starts(s, "model_ema.") && strcmp(s, "model_ema.decay") && strcmp(s, "model_ema.num_updates")) sf->has_ema = 1;
        if (!used && !skipped_in_part(MX_LDM_CLIP, s)) note_skipped(sf, s);
    }
}

int mx_sf_open(mx_single_file *sf, const char *path, int flags, mx_status *st) {
    memset(sf, 0, sizeof *sf);
    int rc = mx_sf_open_tensors(&sf->src, path, &sf->container, &sf->skipped, st);
    if (!rc) rc = refuse_other_models(sf, st);
    if (!rc) rc = check_schedule(sf, st);
    if (!rc) rc = convert_parts(sf, flags, st);
    if (!rc && sf->n_nets == 0)
        rc = mx_fail(st, MX_EINPUT, "%s: no %s found (keys %s)", path,
                     flags & MX_SF_CONTROLNET_ONLY ? "ControlNet" : flags & MX_SF_VAE_ONLY ? "VAE" : "SD1.x networks",
                     flags & MX_SF_CONTROLNET_ONLY ? "control_model.* or input_hint_block.*"
                     : flags & MX_SF_VAE_ONLY     ? "first_stage_model.*, encoder.*/decoder.* or encoder.down_blocks.*"
                                                   : "model.diffusion_model.*, first_stage_model.*, cond_stage_model.transformer.*");
    if (!rc) {
        count_skipped(sf);
        sf->used_ema = (flags & MX_SF_EMA) && has_prefix(sf, "model.diffusion_model.");
    }
    if (rc) mx_sf_close(sf);
    return rc;
}

void mx_sf_close(mx_single_file *sf) {
    for (size_t k = 0; k < sf->n_nets; k++) {
        for (size_t i = 0; i < sf->nets[k].count; i++) free(sf->nets[k].tensors[i].name);
        free(sf->nets[k].tensors);
        free(sf->nets[k].config);
    }
    mx_st_close(&sf->aux);
    mx_st_close(&sf->src);
    memset(sf, 0, sizeof *sf);
}

static const char *dtype_name(mx_st_dtype d) {
    static const char *const names[] = {"f32", "f16", "bf16", "i64", "i32", "f64"};
    return (unsigned)d < 6 ? names[d] : "?";
}

void mx_sf_print_info(const mx_single_file *sf, FILE *out) {
    fprintf(out, "file:         %s\ncontainer:    %s\narchitecture: Stable Diffusion 1.x%s\n", sf->src.path,
            sf->container, sf->sd15_sizes ? " (SD1.5 sizes)" : " layout");
    fprintf(out, "tensors:      %zu\n", sf->src.count);
    for (size_t k = 0; k < sf->n_nets; k++) {
        const mx_sf_net *n = &sf->nets[k];
        size_t counts[6] = {0};
        for (size_t i = 0; i < n->count; i++) counts[n->tensors[i].dtype < 6 ? n->tensors[i].dtype : 0]++;
        fprintf(out, "network:      %-13s %zu tensors (", n->kind, n->count);
        for (int d = 0, first = 1; d < 6; d++)
            if (counts[d]) fprintf(out, "%s%zu %s", first ? "" : ", ", counts[d], dtype_name((mx_st_dtype)d)), first = 0;
        fprintf(out, ")\n  config:     %s\n", n->config);
    }
    fprintf(out, "EMA copy:     %s\n", sf->has_ema ? (sf->used_ema ? "yes (used)" : "yes (not used; --ema takes it)") : "no");
    fprintf(out, "schedule:     %s\n", sf->schedule_checked ? "alphas_cumprod matches SD1.5's" : "no alphas_cumprod in the file");
    fprintf(out, "skipped:      %zu%s%s%s\n", sf->skipped, sf->skipped ? " (e.g. " : "", sf->skipped_example,
            sf->skipped ? ")" : "");
}
