/* Helpers for the network parity tests (test_nn_unet/controlnet/vae/clip/pipeline): golden
 * folder paths, config text, fp32 copies of golden tensors, a ready ops context on the device
 * named by MX_TEST_DEVICE (cpu, cpu-strict, cuda; default cpu) and the host <-> device copies
 * at the edges of a network call. Header-only (static). */
#ifndef MX_NN_GOLDEN_H
#define MX_NN_GOLDEN_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/ops.h"
#include "../pipeline/nn/controlnet.h"
#include "../pipeline/nn/registry.h"
#include "../pipeline/nn/unet.h"
#include "../pipeline/nn/vae.h"
#include "../runtime/fileio.h"
#include "../weights/safetensors.h"
#include "util_test.h"
#ifdef MX_WITH_CUDA
#include "../ops/cuda/cuda_backend.h"
#endif

/* Path of golden/NET/FILE in the test data (util_test.h); -1 when absent. */
static inline int golden_path(char *buf, size_t cap, const char *net, const char *file) {
    char rel[512];
    snprintf(rel, sizeof rel, "golden/%s/%s", net, file);
    return mx_test_path(buf, cap, rel);
}

/* 1 when golden/NET/FILE is there; otherwise reports the case skipped (util_test.h), returns 0. */
static inline int golden_have(const char *net, const char *file) {
    char path[1024];
    return mx_test_need(path, sizeof path, "golden/%s/%s", net, file);
}

/* Whole file as a NUL-terminated string (caller frees), or NULL. */
static inline char *golden_text(const char *net, const char *file, size_t *len) {
    char path[1024];
    golden_path(path, sizeof path, net, file);
    return mx_read_file(path, (size_t)1 << 30, len, NULL);
}

static inline int golden_open(mx_safetensors *f, const char *net, const char *file) {
    char path[1024];
    mx_status st;
    golden_path(path, sizeof path, net, file);
    if (mx_st_open(f, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    return 0;
}

/* A golden network's weights bound for context c: the file, its host binder and the device binder
 * over it that the network is loaded through, so the weights are device copies on a device
 * context (CUDA, and cpu-strict, which refuses host weights) as models.c binds them. */
typedef struct golden_weights {
    mx_safetensors wf; /* unused (map NULL) by the rule binder */
    mx_binder host, dev;
} golden_weights;

/* net/file of the goldens. */
static inline int golden_weights_open(golden_weights *g, const mx_ctx *c, const char *net, const char *file,
                                      mx_status *st) {
    memset(g, 0, sizeof *g);
    if (golden_open(&g->wf, net, file)) return mx_fail(st, MX_EINPUT, "%s/%s: cannot open", net, file);
    return mx_binder_st(&g->host, &g->wf, "", st) || mx_binder_device(&g->dev, &g->host, c, st) ? -1 : 0;
}

/* Random weights by the golden-v1 rule (mx_binder_rule). */
static inline int golden_weights_rule(golden_weights *g, const mx_ctx *c, uint64_t seed, mx_dtype dtype, mx_status *st) {
    memset(g, 0, sizeof *g);
    return mx_binder_rule(&g->host, seed, dtype, st) || mx_binder_device(&g->dev, &g->host, c, st) ? -1 : 0;
}

static inline void golden_weights_close(golden_weights *g) {
    mx_binder_free(&g->dev);
    mx_binder_free(&g->host);
    if (g->wf.map) mx_st_close(&g->wf);
    memset(g, 0, sizeof *g);
}

/* A golden network loaded as the product loads one: its config.json through the network registry
 * (registry.h: the config class picks the entry), its weights NET/FILE through the device binder. */
typedef struct golden_net {
    golden_weights g;
    const mx_net_def *def;
    void *net; /* the entry's network (mx_unet *, mx_vae *, ...) */
} golden_net;

static inline void golden_net_free(golden_net *k) {
    if (k->def && k->net) k->def->free(k->net);
    golden_weights_close(&k->g);
    memset(k, 0, sizeof *k);
}

/* Loads NET with FILE's weights; fails unless its config is of registry kind `kind` ("unet"). */
static inline int golden_net_load(golden_net *k, const mx_ctx *c, const char *net, const char *file,
                                  const char *kind) {
    mx_status st = {0};
    size_t len;
    memset(k, 0, sizeof *k);
    char *cfg = golden_text(net, "config.json", &len);
    if (!cfg) return fprintf(stderr, "%s: no config.json\n", net), -1;
    int rc = golden_weights_open(&k->g, c, net, file, &st) ||
             mx_net_load_config(&k->def, &k->net, cfg, len, net, &k->g.dev, &st);
    free(cfg);
    if (!rc && strcmp(k->def->kind, kind))
        rc = mx_fail(&st, MX_EINPUT, "%s: a %s, expected a %s", net, k->def->kind, kind);
    if (rc) {
        fprintf(stderr, "%s: %s\n", net, st.msg);
        golden_net_free(k);
        return -1;
    }
    return 0;
}

/* fp32 copy of a tensor (malloc'ed), with its element count; NULL when absent. */
static inline float *golden_f32(const mx_safetensors *f, const char *name, size_t *n) {
    mx_status st;
    const mx_st_tensor *t = mx_st_find(f, name);
    if (!t) {
        fprintf(stderr, "%s: missing %s\n", f->path, name);
        return NULL;
    }
    float *x = mx_st_to_f32(f, t, &st);
    if (!x) fprintf(stderr, "%s\n", st.msg);
    if (n) *n = (size_t)mx_shape_numel(t->ndim, t->shape);
    return x;
}

/* The device of the network tests: MX_TEST_DEVICE, default cpu. */
static inline mx_backend_kind golden_device(void) {
    mx_backend_kind kind = MX_BACKEND_CPU;
    mx_status st;
    const char *name = getenv("MX_TEST_DEVICE");
    if (name && *name && mx_backend_parse(name, &kind, &st)) {
        fprintf(stderr, "MX_TEST_DEVICE: %s\n", st.msg);
        exit(2);
    }
    return kind;
}

/* An ops context computing in precision p (the parity tests default to fp32). */
static inline int golden_ctx_precision(mx_ctx *c, mx_precision p) {
    mx_status st;
    int threads = getenv("MX_TEST_THREADS") ? atoi(getenv("MX_TEST_THREADS")) : 0;
    if (mx_ctx_create_on(c, golden_device(), threads, mx_cpu_isa_for(p), (size_t)64 << 20, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    printf("device %s\n", mx_backend_name(c->be->kind));
    return 0;
}

static inline int golden_ctx(mx_ctx *c) { return golden_ctx_precision(c, MX_PREC_FP32); }

/* A bf16 context when this CPU has bf16 arithmetic (0); else prints that the bf16 parity was
 * not tested and returns 1 (-1 on error). */
static inline int golden_bf16_ctx(mx_ctx *c, const char *test) {
    if (mx_isa_precision(mx_cpu_isa_for(MX_PREC_BF16)) != MX_PREC_BF16) {
        printf("%s: bf16 arithmetic NOT TESTED (no AVX512_BF16 or FEAT_BF16 on this CPU, or lowered by MATEX_ISA)\n", test);
        return 1;
    }
    return golden_ctx_precision(c, MX_PREC_BF16);
}

/* Relative L2 bounds against the fp32 goldens. fp32 arithmetic: 1e-4 (tests/data/golden/README.md).
 * bf16 arithmetic: the README's half-precision bound 1e-2, for every network and output. bf16
 * rounds both operands of every product to 8 significant bits (about 1.6e-3 of error per layer)
 * and the layers add up; the precision policy (pipeline/nn/precision.h: most of the VAE and the
 * layers fed by unnormalised activations in fp32) keeps the sum within it. Measured with the policy:
 * UNet tiny 6.5e-3, mini 6.4e-3, SD1.5 5.7e-3; ControlNet deepest residual mini 8.9e-3, SD1.5
 * 6.7e-3; CLIP tiny 4.8e-3, SD1.5 6.7e-3; VAE decode tiny 7.8e-3, mini 8.2e-3, SD1.5 7.5e-3
 * (encode ~2e-5: fp32). */
#define GOLDEN_BF16 1e-2

/* The bound of fp16/bf16 arithmetic on a GPU (README: <= 1e-2 against the fp32 outputs). */
#define GOLDEN_HALF 1e-2

/* 1 when the network runs on c since golden_half_reset computed a product in half precision: on
 * CUDA, fp16/bf16 weights run on tensor cores (the CPU widens them and computes in fp32). */
static inline int golden_ran_half(const mx_ctx *c) {
#ifdef MX_WITH_CUDA
    if (c->be && c->be->kind == MX_BACKEND_CUDA) return mx_cuda_half_products(c->be, 0) > 0;
#endif
    (void)c;
    return 0;
}

static inline void golden_half_reset(const mx_ctx *c) {
#ifdef MX_WITH_CUDA
    if (c->be && c->be->kind == MX_BACKEND_CUDA) mx_cuda_half_products(c->be, 1);
#endif
    (void)c;
}

/* The bound for the arithmetic c used: bf16_bound for the CPU's bf16 levels, GOLDEN_HALF where the
 * GPU computed in half precision, fp32_bound (1e-4 for the goldens) otherwise: fp32 weights on the
 * GPU keep the fp32 bound. */
static inline double golden_bound_for(const mx_ctx *c, double bf16_bound, double fp32_bound) {
    if (mx_isa_precision(c->k->isa) == MX_PREC_BF16) return bf16_bound;
    return golden_ran_half(c) && fp32_bound < GOLDEN_HALF ? GOLDEN_HALF : fp32_bound;
}

static inline double golden_bound(const mx_ctx *c, double bf16_bound) { return golden_bound_for(c, bf16_bound, 1e-4); }

/* "net" or "net [bf16]": the label of a parity line. */
static inline void golden_label(char *buf, size_t cap, const mx_ctx *c, const char *net) {
    snprintf(buf, cap, "%s%s", net, mx_isa_precision(c->k->isa) == MX_PREC_BF16 ? " [bf16]" : "");
}

/* Backend copy of n host floats (NULL stays NULL); exits on failure. */
static inline float *golden_dev(const mx_ctx *c, const float *host, size_t n) {
    mx_status st;
    if (!host) return NULL;
    float *d = mx_dev_from_host(c, host, n, &st);
    if (!d) {
        fprintf(stderr, "%s\n", st.msg);
        exit(1);
    }
    return d;
}

/* Backend memory for n floats; exits on failure. */
static inline float *golden_dev_alloc(const mx_ctx *c, size_t n) {
    mx_status st;
    float *d = mx_dev_alloc(c, n, &st);
    if (!d) {
        fprintf(stderr, "%s\n", st.msg);
        exit(1);
    }
    return d;
}

/* host[0..n) = dev[0..n), then frees dev; returns 0 or -1 (message printed). */
static inline int golden_fetch(const mx_ctx *c, float *host, float *dev, size_t n) {
    mx_status st;
    int rc = mx_download(c, host, dev, n, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    mx_dev_free(c, dev);
    return rc;
}

/* An arena on the context's backend of exactly `bytes`; exits on failure. */
static inline void golden_arena(const mx_ctx *c, mx_arena *a, size_t bytes) {
    mx_status st;
    if (mx_arena_create_on(a, c->be, bytes, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        exit(1);
    }
}

/* Runs one call on the context's device in an arena of exactly the measured size: the host
 * inputs (image tokens too) are copied to the device, the output back; with a step cache (or NULL). */
static inline int golden_run_unet_cached(const mx_ctx *c, const mx_unet *u, const mx_unet_input *in,
                                         mx_step_cache *cache, float *out) {
    mx_status st;
    size_t bytes;
    mx_arena a;
    if (mx_unet_call_arena_bytes(u, in, &bytes, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    golden_arena(c, &a, bytes);
    const mx_unet_config *cfg = mx_unet_cfg(u);
    int n = mx_unet_num_residuals(cfg), C, h, w;
    mx_unet_input d = *in;
    float *res[MX_UNET_MAX_RES + 1] = {0};
    d.sample = golden_dev(c, in->sample, (size_t)in->B * cfg->in_channels * in->H * in->W);
    d.timesteps = golden_dev(c, in->timesteps, (size_t)in->B);
    d.encoder_hidden_states = golden_dev(c, in->encoder_hidden_states, (size_t)in->B * in->T * cfg->cross_attention_dim);
    d.ip_tokens = golden_dev(c, in->ip_tokens, (size_t)in->B * in->ip_n * cfg->cross_attention_dim);
    for (int i = 0; i <= n && in->down_residuals; i++) {
        mx_unet_residual_shape(cfg, i, in->H, in->W, &C, &h, &w);
        res[i] = golden_dev(c, i < n ? in->down_residuals[i] : in->mid_residual, (size_t)in->B * C * h * w);
    }
    d.down_residuals = in->down_residuals ? (const float *const *)res : NULL;
    d.mid_residual = in->down_residuals ? res[n] : NULL;
    size_t no = (size_t)in->B * cfg->out_channels * in->H * in->W;
    float *dout = golden_dev_alloc(c, no);
    golden_half_reset(c);
    int rc = mx_unet_forward_cached(c, u, &d, cache, dout, &a, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    if (golden_fetch(c, out, dout, no)) rc = -1;
    mx_dev_free(c, (void *)d.sample);
    mx_dev_free(c, (void *)d.timesteps);
    mx_dev_free(c, (void *)d.encoder_hidden_states);
    mx_dev_free(c, (void *)d.ip_tokens);
    for (int i = 0; i <= n; i++) mx_dev_free(c, res[i]);
    mx_arena_destroy(&a);
    return rc;
}

static inline int golden_run_unet(const mx_ctx *c, const mx_unet *u, const mx_unet_input *in, float *out) {
    return golden_run_unet_cached(c, u, in, NULL, out);
}

/* The same for a ControlNet: down[0..n) and mid are host buffers (read too when accumulating). */
static inline int golden_run_controlnet_cached(const mx_ctx *c, const mx_controlnet *m, const mx_controlnet_input *in,
                                               mx_step_cache *cache, float **down, float *mid, int accumulate) {
    mx_status st;
    size_t bytes;
    mx_arena a;
    if (mx_controlnet_arena_bytes(m, in->B, in->H, in->W, in->T, &bytes, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    golden_arena(c, &a, bytes);
    const mx_unet_config *cfg = mx_controlnet_cfg(m);
    int n = mx_unet_num_residuals(cfg), C, h, w, f = 1 << (cfg->n_cond_emb - 1);
    mx_controlnet_input d = *in;
    float *res[MX_UNET_MAX_RES + 1];
    size_t cnt[MX_UNET_MAX_RES + 1];
    d.sample = golden_dev(c, in->sample, (size_t)in->B * cfg->in_channels * in->H * in->W);
    d.timesteps = golden_dev(c, in->timesteps, (size_t)in->B);
    d.encoder_hidden_states = golden_dev(c, in->encoder_hidden_states, (size_t)in->B * in->T * cfg->cross_attention_dim);
    d.cond = golden_dev(c, in->cond, (size_t)in->B * cfg->conditioning_channels * in->H * f * in->W * f);
    for (int i = 0; i <= n; i++) {
        mx_unet_residual_shape(cfg, i, in->H, in->W, &C, &h, &w);
        cnt[i] = (size_t)in->B * C * h * w;
        res[i] = golden_dev(c, i < n ? down[i] : mid, cnt[i]);
    }
    golden_half_reset(c);
    int rc = mx_controlnet_forward_cached(c, m, &d, cache, res, res[n], accumulate, &a, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    for (int i = 0; i <= n; i++)
        if (golden_fetch(c, i < n ? down[i] : mid, res[i], cnt[i])) rc = -1;
    mx_dev_free(c, (void *)d.sample);
    mx_dev_free(c, (void *)d.timesteps);
    mx_dev_free(c, (void *)d.encoder_hidden_states);
    mx_dev_free(c, (void *)d.cond);
    mx_arena_destroy(&a);
    return rc;
}

static inline int golden_run_controlnet(const mx_ctx *c, const mx_controlnet *m, const mx_controlnet_input *in,
                                        float **down, float *mid, int accumulate) {
    return golden_run_controlnet_cached(c, m, in, NULL, down, mid, accumulate);
}

/* Encode / decode on the context's device: host in, host out. */
static inline int golden_vae_encode(const mx_ctx *c, const mx_vae *v, const float *img, int B, int H, int W, float *mean, float *logvar) {
    mx_status st;
    size_t bytes, f = (size_t)mx_vae_factor(v);
    mx_arena a;
    if (mx_vae_encode_arena_bytes(v, B, H, W, &bytes, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    golden_arena(c, &a, bytes);
    const mx_vae_config *cfg = mx_vae_cfg(v);
    size_t nl = (size_t)B * cfg->latent_channels * (H / f) * (W / f);
    float *dimg = golden_dev(c, img, (size_t)B * cfg->in_channels * H * W), *dmean = golden_dev_alloc(c, nl);
    float *dlogvar = logvar ? golden_dev_alloc(c, nl) : NULL;
    golden_half_reset(c);
    int rc = mx_vae_encode(c, v, dimg, B, H, W, dmean, dlogvar, &a, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    if (golden_fetch(c, mean, dmean, nl) || (logvar && golden_fetch(c, logvar, dlogvar, nl))) rc = -1;
    mx_dev_free(c, dimg);
    mx_arena_destroy(&a);
    return rc;
}

static inline int golden_vae_decode(const mx_ctx *c, const mx_vae *v, const float *lat, int B, int h, int w, float *img) {
    mx_status st;
    size_t bytes, f = (size_t)mx_vae_factor(v);
    mx_arena a;
    if (mx_vae_decode_arena_bytes(v, B, h, w, &bytes, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    golden_arena(c, &a, bytes);
    const mx_vae_config *cfg = mx_vae_cfg(v);
    size_t ni = (size_t)B * cfg->out_channels * (h * f) * (w * f);
    float *dlat = golden_dev(c, lat, (size_t)B * cfg->latent_channels * h * w), *dimg = golden_dev_alloc(c, ni);
    golden_half_reset(c);
    int rc = mx_vae_decode(c, v, dlat, B, h, w, dimg, &a, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    if (golden_fetch(c, img, dimg, ni)) rc = -1;
    mx_dev_free(c, dlat);
    mx_arena_destroy(&a);
    return rc;
}

#endif
