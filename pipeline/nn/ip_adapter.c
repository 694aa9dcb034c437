/* The IP-Adapter (ip_adapter.h): diffusers v0.35.2 embeddings.py ImageProjection,
 * MultiIPAdapterImageProjection, and the to_k_ip / to_v_ip of attention_processor.py
 * IPAdapterAttnProcessor2_0 (run by the UNet's cross-attentions, blocks.c). */
#include "ip_adapter.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"

#define MAX_DIM (1 << 16)

static int config_int(const mx_json *j, const char *key, int *out, const char *what, mx_status *st) {
    const mx_json *v = mx_json_get(j, key);
    double d = v && mx_json_kind(v) == MX_JSON_NUM ? mx_json_num(v) : 0.0;
    if (!(d >= 1.0 && d <= MAX_DIM) || d != (int)d)
        return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be an integer in 1..%d", what, key, MAX_DIM);
    *out = (int)d;
    return 0;
}

static int parse_config(mx_ip_adapter *ad, const char *text, size_t len, const char *what, mx_status *st) {
    mx_json *j = mx_json_parse(text, len, what, st);
    if (!j) return -1;
    const mx_json *hs = mx_json_get(j, "hidden_sizes");
    int rc = config_int(j, "image_embed_dim", &ad->embed_dim, what, st) ||
                     config_int(j, "num_tokens", &ad->num_tokens, what, st) ||
                     config_int(j, "cross_attention_dim", &ad->cross_dim, what, st)
                 ? -1
                 : 0;
    if (!rc && (mx_json_kind(hs) != MX_JSON_ARR || mx_json_len(hs) < 1 || mx_json_len(hs) > MX_IP_MAX_LAYERS))
        rc = mx_fail(st, MX_EINPUT, "%s: \"hidden_sizes\" must be an array of 1..%d layer widths", what,
                     MX_IP_MAX_LAYERS);
    for (size_t i = 0; !rc && i < mx_json_len(hs); i++) {
        double d = mx_json_kind(mx_json_at(hs, i)) == MX_JSON_NUM ? mx_json_num(mx_json_at(hs, i)) : 0.0;
        if (!(d >= 1.0 && d <= MAX_DIM) || d != (int)d)
            rc = mx_fail(st, MX_EINPUT, "%s: hidden_sizes[%zu] is not a layer width", what, i);
        else ad->hidden[i] = (int)d;
    }
    if (!rc) ad->n_layers = (int)mx_json_len(hs);
    if (!rc && (double)ad->num_tokens * ad->cross_dim > MAX_DIM * 16.0)
        rc = mx_fail(st, MX_EINPUT, "%s: %d tokens of %d are too many", what, ad->num_tokens, ad->cross_dim);
    mx_json_free(j);
    return rc;
}

static int bind_layers(mx_ip_adapter *ad, mx_binder *b, mx_status *st) {
    if (mx_lin_load(&ad->proj, b, "image_proj.proj", ad->embed_dim, ad->num_tokens * ad->cross_dim, 1, st) ||
        mx_ln_load(&ad->norm, b, "image_proj.norm", ad->cross_dim, 1e-5f, st))
        return -1;
    for (int j = 0; j < ad->n_layers; j++) {
        char path[32];
        snprintf(path, sizeof path, "%d.to_k_ip", 2 * j + 1);
        if (mx_lin_load(&ad->k[j], b, path, ad->cross_dim, ad->hidden[j], 0, st)) return -1;
        snprintf(path, sizeof path, "%d.to_v_ip", 2 * j + 1);
        if (mx_lin_load(&ad->v[j], b, path, ad->cross_dim, ad->hidden[j], 0, st)) return -1;
    }
    return 0;
}

int mx_ip_adapter_load(mx_ip_adapter **out, const char *text, size_t len, const char *what, mx_binder *b,
                       mx_status *st) {
    mx_ip_adapter *ad = calloc(1, sizeof *ad);
    *out = NULL;
    if (!ad) return mx_fail(st, MX_ENOMEM, "out of memory loading the IP-Adapter");
    if (parse_config(ad, text, len, what, st) || bind_layers(ad, b, st)) {
        free(ad);
        return mx_fail_prefix(st, "loading the IP-Adapter");
    }
    *out = ad;
    return 0;
}

void mx_ip_adapter_free(mx_ip_adapter *ad) { free(ad); }

/* ImageProjection on n embeddings: proj, then LayerNorm over each token. */
static int tokens_run(mx_run *r, const mx_ip_adapter *ad, const float *embeds, int n, float *tokens) {
    float *t = mx_run_alloc(r, (size_t)n * ad->num_tokens * ad->cross_dim);
    if (!t) return -1;
    mx_lin_run(r, &ad->proj, t, embeds, n);
    mx_ln_run(r, &ad->norm, tokens, t, n * ad->num_tokens);
    return 0;
}

static int check_count(int n, mx_status *st) {
    if (n < 1 || n > MAX_DIM) return mx_fail(st, MX_EINPUT, "IP-Adapter: %d image embeddings (1..%d)", n, MAX_DIM);
    return 0;
}

int mx_ip_adapter_arena_bytes(const mx_ip_adapter *ad, int n, size_t *bytes, mx_status *st) {
    mx_arena a;
    mx_run r;
    if (check_count(n, st)) return -1;
    mx_arena_measure(&a);
    mx_run_init(&r, NULL, &a, st);
    if (tokens_run(&r, ad, NULL, n, NULL)) return -1;
    *bytes = a.peak + 4 * MX_ARENA_ALIGN;
    return 0;
}

int mx_ip_adapter_tokens(const mx_ctx *c, const mx_ip_adapter *ad, const float *embeds, int n, float *tokens,
                         mx_arena *a, mx_status *st) {
    mx_run r;
    if (check_count(n, st)) return -1;
    mx_run_init(&r, c, a, st);
    size_t mark = mx_arena_mark(a);
    int rc = tokens_run(&r, ad, embeds, n, tokens);
    mx_arena_reset(a, mark);
    return rc ? mx_fail_prefix(st, "IP-Adapter image projection") : 0;
}

/* tokens (host) of embeds (host), n of them, through device copies and an arena of their own. */
static int tokens_host(const mx_ctx *c, const mx_ip_adapter *ad, const float *embeds, int n, float *tokens,
                       mx_status *st) {
    size_t ne = (size_t)n * ad->embed_dim, nt = (size_t)n * ad->num_tokens * ad->cross_dim, bytes;
    mx_arena a = {0};
    float *de = mx_dev_alloc(c, ne, st), *dt = de ? mx_dev_alloc(c, nt, st) : NULL;
    int rc = -1;
    if (dt && !mx_upload(c, de, embeds, ne, st) && !mx_ip_adapter_arena_bytes(ad, n, &bytes, st) &&
        !mx_arena_create_on(&a, c->be, bytes, st) && !mx_ip_adapter_tokens(c, ad, de, n, dt, &a, st))
        rc = mx_download(c, tokens, dt, nt, st);
    mx_arena_destroy(&a);
    mx_dev_free(c, de);
    mx_dev_free(c, dt);
    return rc;
}

int mx_ip_adapter_guidance_tokens(const mx_ctx *c, const mx_ip_adapter *ad, const float *embeds, int n_images,
                                  float *cond, float *uncond, mx_status *st) {
    if (check_count(n_images, st) || tokens_host(c, ad, embeds, n_images, cond, st)) return -1;
    if (!uncond) return 0;
    float *zeros = calloc((size_t)n_images * ad->embed_dim, sizeof *zeros);
    if (!zeros) return mx_fail(st, MX_ENOMEM, "out of memory");
    int rc = tokens_host(c, ad, zeros, n_images, uncond, st);
    free(zeros);
    return rc;
}

int mx_ip_adapter_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                              mx_status *st) {
    return mx_ip_adapter_load((mx_ip_adapter **)net, text, len, what, b, st);
}

/* run-net ip-adapter: image_embeds [B, n_images, E] -> image_tokens [B, n_images, num_tokens, D]. */
enum { IP_EMBEDS, IP_TOKENS, IP_N };
const mx_net_slot mx_ip_adapter_slots[] = {
    [IP_EMBEDS] = {"image_embeds", MX_SLOT_IN},
    [IP_TOKENS] = {"image_tokens", MX_SLOT_OUT},
    [IP_N] = {NULL, 0},
};

static int embeds_shape(const mx_ip_adapter *ad, mx_net_io *io, int64_t es[3], mx_status *st) {
    es[0] = es[1] = -1, es[2] = ad->embed_dim;
    if (io->shape(io, IP_EMBEDS, 3, es, st)) return -1;
    return es[0] * es[1] > MAX_DIM ? mx_fail(st, MX_EINPUT, "%s: image_embeds: %lld embeddings (at most %d)", io->source,
                                             (long long)(es[0] * es[1]), MAX_DIM)
                                   : 0;
}

int mx_ip_adapter_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    int64_t es[3];
    return embeds_shape(net, io, es, st) ? -1 : mx_ip_adapter_arena_bytes(net, (int)(es[0] * es[1]), bytes, st);
}

int mx_ip_adapter_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    const mx_ip_adapter *ad = net;
    int64_t es[3];
    const float *embeds = embeds_shape(ad, io, es, st) ? NULL : mx_net_io_input(io, IP_EMBEDS, 3, es, st);
    int64_t ts[4] = {es[0], es[1], ad->num_tokens, ad->cross_dim};
    float *tokens = embeds ? io->output(io, IP_TOKENS, 4, ts, st) : NULL;
    return tokens ? mx_ip_adapter_tokens(c, ad, embeds, (int)(es[0] * es[1]), tokens, a, st) : -1;
}
