/* The published IP-Adapter file (ip_adapter_file.h). */
#include "ip_adapter_file.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../runtime/buf.h"
#include "../runtime/json.h"
#include "networks.h"

#define MAX_LAYERS 64 /* MX_IP_MAX_LAYERS of pipeline/nn/ip_adapter.h (SD1.5 has 16) */
#define LAYER_PREFIX "ip_adapter."

typedef struct adapter_parts {
    const mx_st_tensor *proj_w, *proj_b, *norm_w, *norm_b;
    const mx_st_tensor *k[MAX_LAYERS], *v[MAX_LAYERS];
    int n_layers;
} adapter_parts;

/* "ip_adapter.K.to_k_ip.weight" -> layer (K-1)/2 into p; 1 when it was such a name. */
static int layer_tensor(adapter_parts *p, const mx_st_tensor *t) {
    const char *s = t->name + strlen(LAYER_PREFIX);
    char *end;
    if (strncmp(t->name, LAYER_PREFIX, strlen(LAYER_PREFIX)) || *s < '0' || *s > '9') return 0;
    long k = strtol(s, &end, 10);
    int is_k = !strcmp(end, ".to_k_ip.weight"), is_v = !strcmp(end, ".to_v_ip.weight");
    if (!(is_k || is_v) || k < 1 || k % 2 == 0 || k > 2 * MAX_LAYERS - 1) return 0;
    int j = (int)(k - 1) / 2;
    if (is_k) p->k[j] = t;
    else p->v[j] = t;
    if (j + 1 > p->n_layers) p->n_layers = j + 1;
    return 1;
}

static int classify(const mx_safetensors *f, adapter_parts *p, mx_status *st) {
    memset(p, 0, sizeof *p);
    for (size_t i = 0; i < f->count; i++) {
        const mx_st_tensor *t = &f->tensors[i];
        const mx_st_tensor **slot = !strcmp(t->name, "image_proj.proj.weight")   ? &p->proj_w
                                    : !strcmp(t->name, "image_proj.proj.bias")   ? &p->proj_b
                                    : !strcmp(t->name, "image_proj.norm.weight") ? &p->norm_w
                                    : !strcmp(t->name, "image_proj.norm.bias")   ? &p->norm_b
                                                                                 : NULL;
        if (slot) *slot = t;
        else if (!layer_tensor(p, t))
            return mx_fail(st, MX_EINPUT,
                           "%s: tensor '%s' is not part of the SD1.5 IP-Adapter (image_proj.proj/norm.*, "
                           "ip_adapter.{1,3,5,...}.to_k_ip/to_v_ip.weight; Plus and FaceID adapters are not supported)",
                           f->path, t->name);
    }
    if (!p->proj_w || !p->proj_b || !p->norm_w || !p->norm_b)
        return mx_fail(st, MX_EINPUT, "%s: not an IP-Adapter: image_proj.proj.* or image_proj.norm.* missing", f->path);
    if (p->n_layers == 0) return mx_fail(st, MX_EINPUT, "%s: no ip_adapter.N.to_k_ip/to_v_ip layers", f->path);
    for (int j = 0; j < p->n_layers; j++)
        if (!p->k[j] || !p->v[j])
            return mx_fail(st, MX_EINPUT, "%s: ip_adapter.%d.%s.weight missing (layers are numbered 1, 3, 5, ... up to %d)",
                           f->path, 2 * j + 1, p->k[j] ? "to_v_ip" : "to_k_ip", 2 * p->n_layers - 1);
    return 0;
}

static int is_float(const mx_st_tensor *t) {
    return t->dtype == MX_ST_F32 || t->dtype == MX_ST_F16 || t->dtype == MX_ST_BF16 || t->dtype == MX_ST_F64;
}

static int check_shape(const char *path, const mx_st_tensor *t, int ndim, int64_t d0, int64_t d1, mx_status *st) {
    if (is_float(t) && t->ndim == ndim && t->shape[0] == d0 && (ndim == 1 || t->shape[1] == d1)) return 0;
    if (ndim == 1) return mx_fail(st, MX_EINPUT, "%s: tensor '%s' must be floats of shape [%lld]", path, t->name, (long long)d0);
    return mx_fail(st, MX_EINPUT, "%s: tensor '%s' must be floats of shape [%lld, %lld]", path, t->name, (long long)d0,
                   (long long)d1);
}

/* The sizes from the shapes, every shape checked against them; the config into n->config. */
static int adapter_config(const char *path, const adapter_parts *p, mx_sf_net *n, mx_status *st) {
    int64_t C = p->norm_w->ndim == 1 ? p->norm_w->shape[0] : 0, NC = p->proj_w->shape[0];
    int64_t E = p->proj_w->ndim == 2 ? p->proj_w->shape[1] : 0;
    if (C < 1 || C > 65536 || NC % C || NC / C < 1 || NC / C > 4096 || E < 1 || E > 65536)
        return mx_fail(st, MX_EINPUT, "%s: image_proj shapes do not make tokens (proj.weight [N*C, E], norm.weight [C])",
                       path);
    if (check_shape(path, p->norm_w, 1, C, 0, st) || check_shape(path, p->norm_b, 1, C, 0, st) ||
        check_shape(path, p->proj_w, 2, NC, E, st) || check_shape(path, p->proj_b, 1, NC, 0, st))
        return -1;
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"_class_name\": \"IPAdapter\", \"image_embed_dim\": %lld, \"num_tokens\": %lld, "
                      "\"cross_attention_dim\": %lld, \"hidden_sizes\": [",
                  (long long)E, (long long)(NC / C), (long long)C);
    for (int j = 0; j < p->n_layers; j++) {
        int64_t H = p->k[j]->ndim == 2 ? p->k[j]->shape[0] : 0;
        if (H < 1 || H > 65536 || check_shape(path, p->k[j], 2, H, C, st) || check_shape(path, p->v[j], 2, H, C, st)) {
            mx_buf_free(&b);
            return H < 1 || H > 65536 ? mx_fail(st, MX_EINPUT, "%s: tensor '%s' is not [width, %lld]", path,
                                                p->k[j]->name, (long long)C)
                                      : -1;
        }
        mx_buf_printf(&b, "%s%lld", j ? ", " : "", (long long)H);
    }
    mx_buf_put(&b, "]}", 2);
    if (b.oom) {
        mx_buf_free(&b);
        return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    }
    n->config = b.p;
    return 0;
}

/* The network's tensors: image_proj.* as they are, ip_adapter.K.* as K.* (the weight file's
 * prefix "ip_adapter." gives back the published name). */
static int adapter_tensors(const mx_safetensors *f, mx_sf_net *n, mx_status *st) {
    if (!(n->tensors = calloc(f->count + 1, sizeof *n->tensors))) return mx_fail(st, MX_ENOMEM, "%s: out of memory", f->path);
    for (size_t i = 0; i < f->count; i++) {
        mx_st_tensor *o = &n->tensors[n->count];
        *o = f->tensors[i];
        const char *name = strncmp(o->name, LAYER_PREFIX, strlen(LAYER_PREFIX)) ? o->name : o->name + strlen(LAYER_PREFIX);
        if (!(o->name = strdup(name))) return mx_fail(st, MX_ENOMEM, "%s: out of memory", f->path);
        n->count++;
    }
    return 0;
}

void mx_ip_adapter_published_name(const char *name, char *buf, size_t cap) {
    snprintf(buf, cap, "%s%s", *name >= '0' && *name <= '9' ? LAYER_PREFIX : "", name);
}

int mx_ip_adapter_file_open(mx_single_file *sf, const char *path, mx_status *st) {
    memset(sf, 0, sizeof *sf);
    adapter_parts p;
    mx_sf_net *n = &sf->nets[0];
    n->kind = MX_NET_IP_ADAPTER;
    int rc = mx_sf_open_tensors(&sf->src, path, &sf->container, &sf->skipped, st);
    if (!rc) sf->n_nets = 1;
    if (!rc) rc = classify(&sf->src, &p, st);
    if (!rc) rc = adapter_config(path, &p, n, st);
    if (!rc) rc = adapter_tensors(&sf->src, n, st);
    if (rc) mx_sf_close(sf);
    return rc;
}

/* ---- the check against a UNet config ---- */

/* transformer_layers_per_block of level i (an int for all levels, or a list). */
static int transformer_layers(const mx_json *u, int i) {
    const mx_json *t = mx_json_get(u, "transformer_layers_per_block");
    if (mx_json_kind(t) == MX_JSON_ARR) return (int)mx_json_num(mx_json_at(t, (size_t)i));
    return t ? (int)mx_json_num(t) : 1;
}

static int is_cross(const mx_json *types, int i) {
    const char *s = mx_json_str(mx_json_at(types, (size_t)i));
    return s && strstr(s, "CrossAttn") != NULL;
}

/* The UNet's cross-attention widths in the order of diffusers' attn_processors: the down blocks
 * (layers_per_block each), the up blocks (layers_per_block + 1 each, the channels reversed),
 * the mid block; each transformer layer is one. -1 when more than cap. */
static int unet_cross_widths(const mx_json *u, int *w, int cap) {
    const mx_json *ch = mx_json_get(u, "block_out_channels"), *down = mx_json_get(u, "down_block_types"),
                  *up = mx_json_get(u, "up_block_types");
    int L = (int)mx_json_get_num(u, "layers_per_block", 2), levels = (int)mx_json_len(ch), n = 0;
    for (int pass = 0; pass < 3; pass++)
        for (int i = 0; i < (pass == 2 ? 1 : levels); i++) {
            int level = pass == 0 ? i : levels - 1 - (pass == 2 ? 0 : i);
            int count = pass == 0 ? (is_cross(down, i) ? L : 0) : pass == 1 ? (is_cross(up, i) ? L + 1 : 0) : 1;
            int width = (int)mx_json_num(mx_json_at(ch, (size_t)level));
            for (int r = 0; r < count * transformer_layers(u, level); r++) {
                if (n == cap) return -1;
                w[n++] = width;
            }
        }
    return n;
}

int mx_ip_adapter_file_check_unet(const char *adapter_config, const char *unet_config, const char *path,
                                  mx_status *st) {
    mx_json *a = mx_json_parse(adapter_config, strlen(adapter_config), path, st);
    mx_json *u = a ? mx_json_parse(unet_config, strlen(unet_config), "unet config", st) : NULL;
    int widths[MAX_LAYERS], rc = a && u ? 0 : -1;
    int n = rc ? 0 : unet_cross_widths(u, widths, MAX_LAYERS);
    const mx_json *hs = a ? mx_json_get(a, "hidden_sizes") : NULL;
    int cross = u ? (int)mx_json_get_num(u, "cross_attention_dim", 0) : 0, tokens_dim = a ? (int)mx_json_get_num(a, "cross_attention_dim", 0) : 0;
    if (!rc && (n < 0 || (size_t)n != mx_json_len(hs)))
        rc = mx_fail(st, MX_EINPUT, "%s: %zu IP-Adapter layers, but the UNet has %d cross-attention layers", path,
                     mx_json_len(hs), n);
    if (!rc && tokens_dim != cross)
        rc = mx_fail(st, MX_EINPUT, "%s: image tokens of width %d, but the UNet's cross_attention_dim is %d", path,
                     tokens_dim, cross);
    for (int j = 0; !rc && j < n; j++)
        if ((int)mx_json_num(mx_json_at(hs, (size_t)j)) != widths[j])
            rc = mx_fail(st, MX_EINPUT, "%s: ip_adapter.%d is %d wide, the UNet's cross-attention layer %d is %d", path,
                         2 * j + 1, (int)mx_json_num(mx_json_at(hs, (size_t)j)), j, widths[j]);
    mx_json_free(u);
    mx_json_free(a);
    return rc;
}
