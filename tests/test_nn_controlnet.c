/* ControlNetModel against the golden vectors of controlnet_tiny and controlnet_mini (fp32 and
 * fp16 weights, conditioning scales 1.0 and 0.5), the accumulate mode, and the fp16 UNet fed
 * with residuals of the fp16 ControlNet (how outputs_fp16w of unet_* were made). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/controlnet.h"
#include "../pipeline/nn/unet.h"
#include "nn_golden.h"

typedef struct cn_case {
    golden_net n;
    mx_controlnet *m;
    mx_unet_config cfg;
} cn_case;

static int load_cn(cn_case *k, const mx_ctx *c, const char *net, const char *wfile) {
    memset(k, 0, sizeof *k);
    if (golden_net_load(&k->n, c, net, wfile, "controlnet")) return -1;
    k->m = k->n.net;
    k->cfg = *mx_controlnet_cfg(k->m);
    return 0;
}

static void free_cn(cn_case *k) { golden_net_free(&k->n); }

typedef struct cn_inputs {
    float *sample, *ehs, *ts, *cond;
    mx_controlnet_input in;
} cn_inputs;

static int read_inputs(cn_inputs *x, const char *net) {
    mx_safetensors f;
    memset(x, 0, sizeof *x);
    if (golden_open(&f, net, "inputs.safetensors")) return -1;
    x->sample = golden_f32(&f, "sample", NULL);
    x->ehs = golden_f32(&f, "encoder_hidden_states", NULL);
    x->ts = golden_f32(&f, "timestep", NULL);
    x->cond = golden_f32(&f, "controlnet_cond", NULL);
    const mx_st_tensor *s = mx_st_find(&f, "sample"), *e = mx_st_find(&f, "encoder_hidden_states");
    int ok = x->sample && x->ehs && x->ts && x->cond && s && e;
    if (ok) {
        mx_controlnet_input in = {x->sample, x->ts, x->ehs, x->cond, (int)s->shape[0], (int)s->shape[2],
                                  (int)s->shape[3], (int)e->shape[1], 1.0f, 0};
        x->in = in;
    }
    mx_st_close(&f);
    return ok ? 0 : -1;
}

static void free_inputs(cn_inputs *x) {
    free(x->sample);
    free(x->ehs);
    free(x->ts);
    free(x->cond);
}

/* Residual buffers for one call (n + 1: the last is the mid block's). */
static float **alloc_residuals(const mx_unet_config *cfg, int B, int H, int W) {
    int n = mx_unet_num_residuals(cfg), C, h, w;
    float **r = calloc((size_t)n + 1, sizeof *r);
    for (int i = 0; r && i <= n; i++) {
        mx_unet_residual_shape(cfg, i, H, W, &C, &h, &w);
        r[i] = calloc((size_t)B * C * h * w, sizeof(float));
    }
    return r;
}

static void free_residuals(float **r, const mx_unet_config *cfg) {
    for (int i = 0; r && i <= mx_unet_num_residuals(cfg); i++) free(r[i]);
    free(r);
}

static void check_golden(const mx_ctx *c, const char *net, const char *wfile, const char *outfile) {
    cn_case k;
    cn_inputs x;
    mx_safetensors out;
    CHECK(load_cn(&k, c, net, wfile) == 0);
    CHECK(read_inputs(&x, net) == 0);
    CHECK(golden_open(&out, net, outfile) == 0);
    if (!k.m || !x.sample) return;
    int n = mx_unet_num_residuals(&k.cfg);
    float **res = alloc_residuals(&k.cfg, x.in.B, x.in.H, x.in.W);
    const float scales[2] = {1.0f, 0.5f};
    for (int s = 0; s < 2; s++) {
        x.in.scale = scales[s];
        CHECK(golden_run_controlnet(c, k.m, &x.in, res, res[n], 0) == 0);
        for (int i = 0; i <= n; i++) {
            char name[96], label[192];
            if (i < n)
                snprintf(name, sizeof name, "scale%d.down_block_res_sample.%d", s, i);
            else
                snprintf(name, sizeof name, "scale%d.mid_block_res_sample", s);
            size_t nw;
            float *want = golden_f32(&out, name, &nw);
            CHECK(want != NULL);
            char tag[64];
            golden_label(tag, sizeof tag, c, net);
            snprintf(label, sizeof label, "%s %s %s", tag, outfile, name);
            if (want) mx_check_close(label, res[i], want, nw, golden_bound(c, GOLDEN_BF16));
            free(want);
        }
    }
    /* accumulate: adding the scale-0.5 residuals twice onto zero gives the scale-1 ones */
    float **acc = alloc_residuals(&k.cfg, x.in.B, x.in.H, x.in.W);
    CHECK(golden_run_controlnet(c, k.m, &x.in, acc, acc[n], 1) == 0);
    CHECK(golden_run_controlnet(c, k.m, &x.in, acc, acc[n], 1) == 0);
    x.in.scale = 1.0f;
    CHECK(golden_run_controlnet(c, k.m, &x.in, res, res[n], 0) == 0);
    int C, h, w;
    mx_unet_residual_shape(&k.cfg, n, x.in.H, x.in.W, &C, &h, &w);
    char label[128];
    snprintf(label, sizeof label, "%s accumulate 2 x 0.5 vs 1.0 (mid)", net);
    mx_check_close(label, acc[n], res[n], (size_t)x.in.B * C * h * w, 1e-6);
    free_residuals(acc, &k.cfg);
    free_residuals(res, &k.cfg);
    free_inputs(&x);
    mx_st_close(&out);
    free_cn(&k);
}

/* unet_*'s outputs_fp16w with residuals were made from the fp16 ControlNet: chain both. */
static void check_unet_fp16w_chain(const mx_ctx *c, const char *cn_net, const char *unet_net) {
    mx_status st;
    cn_case k;
    cn_inputs x;
    size_t len;
    CHECK(load_cn(&k, c, cn_net, "diffusion_pytorch_model.fp16.safetensors") == 0);
    CHECK(read_inputs(&x, cn_net) == 0);
    if (!k.m || !x.sample) return;
    char *cfgtext = golden_text(unet_net, "config.json", &len);
    mx_unet_config ucfg;
    mx_safetensors uout;
    golden_weights ug;
    mx_unet *u = NULL;
    CHECK(cfgtext && mx_unet_config_parse(&ucfg, cfgtext, len, unet_net, &st) == 0);
    free(cfgtext);
    CHECK(golden_open(&uout, unet_net, "outputs_fp16w.safetensors") == 0);
    CHECK(golden_weights_open(&ug, c, unet_net, "diffusion_pytorch_model.fp16.safetensors", &st) == 0 &&
          mx_unet_load(&u, &ucfg, &ug.dev, &st) == 0);
    if (!u) return;
    int n = mx_unet_num_residuals(&k.cfg);
    float **res = alloc_residuals(&k.cfg, x.in.B, x.in.H, x.in.W);
    float *got = calloc((size_t)x.in.B * ucfg.out_channels * x.in.H * x.in.W, sizeof *got);
    const float scales[2] = {1.0f, 0.5f};
    for (int s = 0; s < 2; s++) {
        x.in.scale = scales[s];
        CHECK(golden_run_controlnet(c, k.m, &x.in, res, res[n], 0) == 0);
        mx_unet_input ui = {.sample = x.sample, .timesteps = x.ts, .encoder_hidden_states = x.ehs, .B = x.in.B, .H = x.in.H,
                            .W = x.in.W, .T = x.in.T, .down_residuals = (const float *const *)res, .mid_residual = res[n]};
        size_t nw;
        CHECK(golden_run_unet(c, u, &ui, got) == 0);
        char name[64], label[160];
        snprintf(name, sizeof name, "out_controlnet_scale%d", s);
        float *want = golden_f32(&uout, name, &nw);
        CHECK(want != NULL);
        snprintf(label, sizeof label, "%s fp16w %s (fp16 ControlNet chain)", unet_net, name);
        if (want) mx_check_close(label, got, want, nw, golden_bound(c, GOLDEN_BF16));
        free(want);
    }
    free(got);
    free_residuals(res, &k.cfg);
    mx_unet_free(u);
    golden_weights_close(&ug);
    mx_st_close(&uout);
    free_inputs(&x);
    free_cn(&k);
}

/* All residuals of run i (res[i]) equal those of run j, byte for byte. */
static int same_residuals(float ***res, int i, int j, const cn_inputs *x, const mx_unet_config *cfg) {
    int n = mx_unet_num_residuals(cfg), C, h, w;
    for (int r = 0; r <= n; r++) {
        mx_unet_residual_shape(cfg, r, x->in.H, x->in.W, &C, &h, &w);
        if (memcmp(res[i][r], res[j][r], (size_t)x->in.B * C * h * w * sizeof(float))) return 0;
    }
    return 1;
}

/* The step cache (step_cache.h): cached forwards give the uncached residuals bit for bit; the
 * later ones replay the first one's hint embedding and cross-attention K/V (another control
 * image on the recorded cache gives the recorded image's residuals). */
static void check_step_cache(const mx_ctx *c) {
    cn_case k;
    cn_inputs x;
    mx_status st;
    CHECK(load_cn(&k, c, "controlnet_tiny", "diffusion_pytorch_model.safetensors") == 0);
    CHECK(read_inputs(&x, "controlnet_tiny") == 0);
    if (!k.m || !x.sample) return;
    int n = mx_unet_num_residuals(&k.cfg), f = 1 << (k.cfg.n_cond_emb - 1);
    size_t ns = (size_t)x.in.B * k.cfg.in_channels * x.in.H * x.in.W, floats = 0;
    size_t nc = (size_t)x.in.B * k.cfg.conditioning_channels * x.in.H * f * x.in.W * f;
    float *sample2 = malloc(ns * sizeof(float)), *cond2 = malloc(nc * sizeof(float));
    mx_fill_random(sample2, ns, 51, -1.5f, 1.5f);
    mx_fill_random(cond2, nc, 52, 0.0f, 1.0f);
    /* the golden call, another latent (step 2 of a view), then another control image */
    mx_controlnet_input in[3] = {x.in, x.in, x.in};
    in[1].sample = in[2].sample = sample2;
    in[2].cond = cond2;
    float **res[5];
    for (int i = 0; i < 5; i++) res[i] = alloc_residuals(&k.cfg, x.in.B, x.in.H, x.in.W);
    for (int i = 0; i < 3; i++) CHECK(golden_run_controlnet(c, k.m, &in[i], res[i], res[i][n], 0) == 0);
    CHECK(mx_controlnet_cache_floats(k.m, x.in.B, x.in.H, x.in.W, x.in.T, &floats, &st) == 0);
    CHECK(floats >= (size_t)x.in.B * k.cfg.block_out_channels[0] * x.in.H * x.in.W); /* the hint embedding */
    mx_step_cache cache = {.mem = golden_dev_alloc(c, floats), .cap = floats};
    CHECK(golden_run_controlnet_cached(c, k.m, &in[0], &cache, res[3], res[3][n], 0) == 0 && cache.recorded);
    CHECK(same_residuals(res, 3, 0, &x, &k.cfg));
    CHECK(golden_run_controlnet_cached(c, k.m, &in[1], &cache, res[3], res[3][n], 0) == 0);
    CHECK(same_residuals(res, 3, 1, &x, &k.cfg));
    CHECK(golden_run_controlnet_cached(c, k.m, &in[2], &cache, res[4], res[4][n], 0) == 0); /* replays */
    CHECK(same_residuals(res, 4, 1, &x, &k.cfg) && !same_residuals(res, 4, 2, &x, &k.cfg));
    /* a replayed step's FLOPs (bench_nets) leave out the cached work: the hint embedding's last conv at least */
    double full = mx_controlnet_flops(k.m, x.in.B, x.in.H, x.in.W, x.in.T, 0),
           replayed = mx_controlnet_flops(k.m, x.in.B, x.in.H, x.in.W, x.in.T, MX_FLOPS_REPLAYED),
           hint_out = 2.0 * x.in.B * x.in.H * x.in.W * k.cfg.block_out_channels[0] * 9 *
                      k.cfg.cond_emb_channels[k.cfg.n_cond_emb - 1];
    CHECK(replayed > 0 && full - replayed >= hint_out);
    printf("controlnet_tiny step cache: %zu floats, bit-identical, replayed; %.3g of %.3g FLOPs per replayed step\n",
           floats, replayed, full);
    mx_dev_free(c, cache.mem);
    for (int i = 0; i < 5; i++) free_residuals(res[i], &k.cfg);
    free(sample2);
    free(cond2);
    free_inputs(&x);
    free_cn(&k);
}

/* CFG's batch of one latent (halves_equal, unet.h): the residuals equal the unshared call's bit for
 * bit, in fewer FLOPs; with halves that differ, item 1 moves (the flag is taken). */
static void check_halves_equal(const mx_ctx *c, const char *what) {
    cn_case k;
    cn_inputs x;
    CHECK(load_cn(&k, c, "controlnet_tiny", "diffusion_pytorch_model.safetensors") == 0);
    CHECK(read_inputs(&x, "controlnet_tiny") == 0);
    if (!k.m || !x.sample) return;
    CHECK(x.in.B == 2);
    int f = 1 << (k.cfg.n_cond_emb - 1);
    size_t ns = (size_t)k.cfg.in_channels * x.in.H * x.in.W;
    size_t nc = (size_t)k.cfg.conditioning_channels * x.in.H * f * x.in.W * f;
    memcpy(x.sample + ns, x.sample, ns * sizeof(float));
    memcpy(x.cond + nc, x.cond, nc * sizeof(float));
    x.ts[1] = x.ts[0];
    float **res[2] = {alloc_residuals(&k.cfg, 2, x.in.H, x.in.W), alloc_residuals(&k.cfg, 2, x.in.H, x.in.W)};
    int n = mx_unet_num_residuals(&k.cfg);
    mx_controlnet_input in = x.in;
    CHECK(golden_run_controlnet(c, k.m, &in, res[0], res[0][n], 0) == 0);
    in.halves_equal = 1;
    CHECK(golden_run_controlnet(c, k.m, &in, res[1], res[1][n], 0) == 0);
    CHECK(same_residuals(res, 0, 1, &x, &k.cfg));
    mx_fill_random(x.sample + ns, ns, 61, -1.5f, 1.5f); /* halves that differ: item 1 moves */
    CHECK(golden_run_controlnet(c, k.m, &in, res[1], res[1][n], 0) == 0);
    in.halves_equal = 0;
    CHECK(golden_run_controlnet(c, k.m, &in, res[0], res[0][n], 0) == 0);
    CHECK(!same_residuals(res, 0, 1, &x, &k.cfg));
    double full = mx_controlnet_flops(k.m, 2, x.in.H, x.in.W, x.in.T, 0),
           half = mx_controlnet_flops(k.m, 2, x.in.H, x.in.W, x.in.T, MX_FLOPS_HALVES_EQUAL);
    CHECK(half > 0.5 * full && half < full);
    printf("controlnet_tiny %s halves_equal: bit-identical; %.4g of %.4g FLOPs\n", what, half, full);
    for (int i = 0; i < 2; i++) free_residuals(res[i], &k.cfg);
    free_inputs(&x);
    free_cn(&k);
}

int main(void) {
    mx_ctx c;
    if (golden_ctx(&c)) return 1;
    check_golden(&c, "controlnet_tiny", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
    check_golden(&c, "controlnet_tiny", "diffusion_pytorch_model.fp16.safetensors", "outputs_fp16w.safetensors");
    check_unet_fp16w_chain(&c, "controlnet_tiny", "unet_tiny");
    check_step_cache(&c);
    check_halves_equal(&c, "fp32");
    int mini = golden_have("controlnet_mini", "inputs.safetensors"); /* outside the repository */
    if (mini) {
        check_golden(&c, "controlnet_mini", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
        check_golden(&c, "controlnet_mini", "diffusion_pytorch_model.fp16.safetensors", "outputs_fp16w.safetensors");
        if (golden_have("unet_mini", "inputs.safetensors")) check_unet_fp16w_chain(&c, "controlnet_mini", "unet_mini");
    }
    mx_ctx_destroy(&c);
    if (golden_bf16_ctx(&c, "test_nn_controlnet") == 0) { /* bf16 arithmetic against the fp32 goldens */
        check_golden(&c, "controlnet_tiny", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
        if (mini) check_golden(&c, "controlnet_mini", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
        check_halves_equal(&c, "bf16");
        mx_ctx_destroy(&c);
    }
    return mx_test_finish("test_nn_controlnet");
}
