/* UNet2DConditionModel against the golden vectors of unet_tiny and unet_mini (fp32 and fp16
 * weights, with and without ControlNet residuals), plus golden-free checks: batch
 * independence and a non-square latent, the dry-run arena size being exactly enough. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/unet.h"
#include "nn_golden.h"

typedef struct unet_case {
    golden_net n;
    mx_unet *u;
    mx_unet_config cfg;
} unet_case;

static int load_unet(unet_case *k, const mx_ctx *c, const char *net, const char *wfile) {
    memset(k, 0, sizeof *k);
    if (golden_net_load(&k->n, c, net, wfile, "unet")) return -1;
    k->u = k->n.net;
    k->cfg = *mx_unet_cfg(k->u);
    return 0;
}

static void free_unet(unet_case *k) { golden_net_free(&k->n); }

/* The golden outputs of one weight variant: out_plain, and with residuals the
 * out_controlnet_scale{0,1} cases. The residuals stored in the inputs come from the fp32
 * ControlNet, so the fp16-weight residual cases are checked by test_nn_controlnet, which
 * chains the fp16 ControlNet into the fp16 UNet. */
static void check_golden(const mx_ctx *c, const char *net, const char *wfile, const char *outfile, int residuals) {
    unet_case k;
    mx_safetensors in, out;
    CHECK(load_unet(&k, c, net, wfile) == 0);
    if (!k.u) return;
    CHECK(golden_open(&in, net, "inputs.safetensors") == 0);
    CHECK(golden_open(&out, net, outfile) == 0);
    size_t ns, ne, nt;
    float *sample = golden_f32(&in, "sample", &ns), *ehs = golden_f32(&in, "encoder_hidden_states", &ne);
    float *ts = golden_f32(&in, "timestep", &nt);
    const mx_st_tensor *st_s = mx_st_find(&in, "sample"), *st_e = mx_st_find(&in, "encoder_hidden_states");
    CHECK(sample && ehs && ts && st_s && st_e);
    if (!sample || !ehs || !ts || !st_s || !st_e) return;
    mx_unet_input ui = {.sample = sample, .timesteps = ts, .encoder_hidden_states = ehs, .B = (int)st_s->shape[0],
                        .H = (int)st_s->shape[2], .W = (int)st_s->shape[3], .T = (int)st_e->shape[1]};
    float *got = calloc((size_t)ui.B * k.cfg.out_channels * ui.H * ui.W, sizeof *got);
    int nres = mx_unet_num_residuals(&k.cfg);
    for (int s = -1; s < (residuals ? 2 : 0); s++) {
        char oname[64], label[160];
        float *res[MX_UNET_MAX_RES + 1] = {0};
        if (s >= 0) {
            for (int i = 0; i <= nres; i++) {
                char rn[96];
                if (i < nres)
                    snprintf(rn, sizeof rn, "residual.scale%d.down_block_res_sample.%d", s, i);
                else
                    snprintf(rn, sizeof rn, "residual.scale%d.mid_block_res_sample", s);
                res[i] = golden_f32(&in, rn, NULL);
                CHECK(res[i] != NULL);
            }
            ui.down_residuals = (const float *const *)res;
            ui.mid_residual = res[nres];
            snprintf(oname, sizeof oname, "out_controlnet_scale%d", s);
        } else {
            ui.down_residuals = NULL;
            ui.mid_residual = NULL;
            snprintf(oname, sizeof oname, "out_plain");
        }
        size_t nw;
        float *want = golden_f32(&out, oname, &nw);
        CHECK(want != NULL);
        CHECK(golden_run_unet(c, k.u, &ui, got) == 0);
        char tag[64];
        golden_label(tag, sizeof tag, c, net);
        snprintf(label, sizeof label, "%s %s %s", tag, outfile, oname);
        if (want) mx_check_close(label, got, want, nw, golden_bound(c, GOLDEN_BF16));
        free(want);
        for (int i = 0; i <= nres; i++) free(res[i]);
    }
    free(got);
    free(sample);
    free(ehs);
    free(ts);
    mx_st_close(&in);
    mx_st_close(&out);
    free_unet(&k);
}

/* unet_tiny with random inputs of a batch of 2 on a non-square latent (8×16), 5 tokens. */
typedef struct pair_case {
    unet_case k;
    int H, W, T;
    size_t ns, ne, no;              /* floats per item of sample, encoder_hidden_states, output */
    float *sample, *ehs, *out, *out2; /* 2 items each */
} pair_case;

static int pair_open(pair_case *p, const mx_ctx *c, uint64_t seed) {
    memset(p, 0, sizeof *p);
    if (load_unet(&p->k, c, "unet_tiny", "diffusion_pytorch_model.safetensors") || !p->k.u) return -1;
    p->H = 8, p->W = 16, p->T = 5;
    p->ns = (size_t)p->k.cfg.in_channels * p->H * p->W;
    p->ne = (size_t)p->T * p->k.cfg.cross_attention_dim;
    p->no = (size_t)p->k.cfg.out_channels * p->H * p->W;
    p->sample = malloc(2 * p->ns * sizeof(float)), p->ehs = malloc(2 * p->ne * sizeof(float));
    p->out = malloc(2 * p->no * sizeof(float)), p->out2 = malloc(2 * p->no * sizeof(float));
    if (!p->sample || !p->ehs || !p->out || !p->out2) return -1;
    mx_fill_random(p->sample, 2 * p->ns, seed, -1.5f, 1.5f);
    mx_fill_random(p->ehs, 2 * p->ne, seed + 1, -2.0f, 2.0f);
    return 0;
}

static void pair_close(pair_case *p) {
    free(p->sample);
    free(p->ehs);
    free(p->out);
    free(p->out2);
    free_unet(&p->k);
}

/* Golden-free: item 1 of a batch of 2 equals the same item run alone, on a non-square latent;
 * and the result does not depend on the thread count. */
static void check_batch_independence(const mx_ctx *c) {
    pair_case p;
    CHECK(pair_open(&p, c, 11) == 0);
    if (!p.out2) {
        pair_close(&p);
        return;
    }
    size_t no = p.no;
    float *out1 = p.out2, *out_st = p.out2 + no, ts[2] = {999.0f, 250.0f};
    mx_unet_input both = {.sample = p.sample, .timesteps = ts, .encoder_hidden_states = p.ehs, .B = 2, .H = p.H,
                          .W = p.W, .T = p.T};
    mx_unet_input one = {.sample = p.sample + p.ns, .timesteps = ts + 1, .encoder_hidden_states = p.ehs + p.ne,
                         .B = 1, .H = p.H, .W = p.W, .T = p.T};
    CHECK(golden_run_unet(c, p.k.u, &both, p.out) == 0);
    CHECK(golden_run_unet(c, p.k.u, &one, out1) == 0);
    mx_check_close("unet_tiny 8x16: batch item 1 vs alone", out1, p.out + no, no, 1e-6);
    mx_ctx serial = *c;
    serial.pool = NULL;
    CHECK(golden_run_unet(&serial, p.k.u, &one, out_st) == 0);
    CHECK(memcmp(out_st, out1, no * sizeof(float)) == 0);
    double ss = 0;
    for (size_t i = 0; i < no; i++) ss += (double)out1[i] * out1[i];
    CHECK(isfinite(ss) && ss > 0);
    /* a latent that is not a multiple of 2 (tiny has 2 levels) is refused with a message */
    mx_status st;
    size_t bytes;
    CHECK(mx_unet_arena_bytes(p.k.u, 1, 7, 16, p.T, &bytes, &st) == -1 && strstr(st.msg, "multiple"));
    pair_close(&p);
}

/* CFG's batch of one latent (halves_equal): the output equals the unshared call's bit for bit, in
 * fewer FLOPs. With halves that differ the flag shows it is taken: item 1 is then computed from
 * item 0's sample until the first cross-attention, so its output moves. */
static void check_halves_equal(const mx_ctx *c, const char *what) {
    pair_case p;
    CHECK(pair_open(&p, c, 21) == 0); /* the uncond and cond prompts differ */
    if (!p.out2) {
        pair_close(&p);
        return;
    }
    size_t no = p.no;
    float *plain = p.out, *shared = p.out2, ts[2] = {500.0f, 500.0f};
    memcpy(p.sample + p.ns, p.sample, p.ns * sizeof(float));
    mx_unet_input in = {.sample = p.sample, .timesteps = ts, .encoder_hidden_states = p.ehs, .B = 2, .H = p.H,
                        .W = p.W, .T = p.T};
    CHECK(golden_run_unet(c, p.k.u, &in, plain) == 0);
    in.halves_equal = 1;
    CHECK(golden_run_unet(c, p.k.u, &in, shared) == 0);
    CHECK(memcmp(plain, shared, 2 * no * sizeof(float)) == 0);
    CHECK(memcmp(plain, plain + no, no * sizeof(float)) != 0); /* the prompts part the items */
    mx_fill_random(p.sample + p.ns, p.ns, 23, -1.5f, 1.5f);   /* halves that differ: the flag is taken */
    in.halves_equal = 0;
    CHECK(golden_run_unet(c, p.k.u, &in, plain) == 0);
    in.halves_equal = 1;
    CHECK(golden_run_unet(c, p.k.u, &in, shared) == 0);
    CHECK(memcmp(plain, shared, no * sizeof(float)) == 0 && memcmp(plain + no, shared + no, no * sizeof(float)) != 0);
    double full = mx_unet_flops(p.k.u, 2, p.H, p.W, p.T, 0);
    double half = mx_unet_flops(p.k.u, 2, p.H, p.W, p.T, MX_FLOPS_HALVES_EQUAL);
    CHECK(half > 0.5 * full && half < full);
    printf("unet_tiny %s halves_equal: bit-identical; %.4g of %.4g FLOPs\n", what, half, full);
    pair_close(&p);
}

/* use_linear_projection: a linear proj_in/proj_out with the 1×1 conv weights (same memory
 * layout, [C, C] vs [C, C, 1, 1]) must give the conv model's output. The wrapper binder
 * serves the linear shapes from the conv tensors. */
typedef struct linear_view {
    mx_binder *inner;
} linear_view;

static int bind_linear_view(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out,
                            mx_status *st) {
    linear_view *lv = b->impl;
    size_t n = strlen(name);
    int proj = ndim == 2 && n > 14 && (!strcmp(name + n - 14, "proj_in.weight") || !strcmp(name + n - 15, "proj_out.weight"));
    if (!proj) return lv->inner->bind(lv->inner, name, ndim, shape, out, st);
    int64_t conv_shape[4] = {shape[0], shape[1], 1, 1};
    return lv->inner->bind(lv->inner, name, 4, conv_shape, out, st);
}

static void check_linear_projection(const mx_ctx *c) {
    unet_case k;
    mx_status st;
    CHECK(load_unet(&k, c, "unet_tiny", "diffusion_pytorch_model.safetensors") == 0);
    if (!k.u) return;
    mx_unet_config lcfg = k.cfg;
    lcfg.use_linear_projection = 1;
    linear_view lv = {&k.n.g.dev}; /* binds through the device binder */
    mx_binder view = {bind_linear_view, &lv, "", 0};
    mx_unet *ul = NULL;
    CHECK(mx_unet_load(&ul, &lcfg, &view, &st) == 0);
    int H = 8, W = 8, T = 7, C = k.cfg.in_channels;
    size_t ns = (size_t)C * H * W, ne = (size_t)T * k.cfg.cross_attention_dim, no = (size_t)k.cfg.out_channels * H * W;
    float *sample = malloc(ns * sizeof(float)), *ehs = malloc(ne * sizeof(float));
    float *o1 = malloc(no * sizeof(float)), *o2 = malloc(no * sizeof(float)), ts[1] = {500.0f};
    mx_fill_random(sample, ns, 31, -1.0f, 1.0f);
    mx_fill_random(ehs, ne, 32, -1.0f, 1.0f);
    mx_unet_input in = {.sample = sample, .timesteps = ts, .encoder_hidden_states = ehs, .B = 1, .H = H, .W = W, .T = T};
    CHECK(golden_run_unet(c, k.u, &in, o1) == 0);
    if (ul) CHECK(golden_run_unet(c, ul, &in, o2) == 0);
    if (ul) mx_check_close("unet_tiny linear projection vs 1x1 conv", o2, o1, no, 1e-5);
    mx_unet_free(ul);
    free(sample);
    free(ehs);
    free(o1);
    free(o2);
    free_unet(&k);
}

/* The step cache (step_cache.h): forwards with a cache give the uncached outputs bit for bit, and
 * the later ones really replay the first one's cross-attention K/V: a call with other
 * encoder_hidden_states on the recorded cache gives the result of the recorded ones. */
static void check_step_cache(const mx_ctx *c) {
    unet_case k;
    CHECK(load_unet(&k, c, "unet_tiny", "diffusion_pytorch_model.safetensors") == 0);
    if (!k.u) return;
    mx_status st;
    int B = 2, H = 8, W = 8, T = 7;
    size_t ns = (size_t)B * k.cfg.in_channels * H * W, ne = (size_t)B * T * k.cfg.cross_attention_dim;
    size_t no = (size_t)B * k.cfg.out_channels * H * W, floats = 0;
    float *x = malloc(2 * ns * sizeof(float)), *e = malloc(2 * ne * sizeof(float)), *plain = malloc(3 * no * sizeof(float));
    float *got = malloc(no * sizeof(float)), ts[4] = {999.0f, 999.0f, 400.0f, 400.0f};
    mx_fill_random(x, 2 * ns, 41, -1.5f, 1.5f);
    mx_fill_random(e, 2 * ne, 42, -2.0f, 2.0f);
    /* (x0, t0, e0), (x1, t1, e0), (x1, t1, e1): steps 1 and 2 of a view, then another prompt */
    mx_unet_input in[3] = {{.sample = x, .timesteps = ts, .encoder_hidden_states = e, .B = B, .H = H, .W = W, .T = T},
                           {.sample = x + ns, .timesteps = ts + 2, .encoder_hidden_states = e, .B = B, .H = H, .W = W,
                            .T = T},
                           {.sample = x + ns, .timesteps = ts + 2, .encoder_hidden_states = e + ne, .B = B, .H = H,
                            .W = W, .T = T}};
    for (int i = 0; i < 3; i++) CHECK(golden_run_unet(c, k.u, &in[i], plain + i * no) == 0);
    CHECK(mx_unet_cache_floats(k.u, B, H, W, T, &floats, &st) == 0);
    /* every cross-attention keeps K and V of the B·T tokens */
    size_t per_layer = (size_t)B * T * k.cfg.block_out_channels[0];
    CHECK(floats >= 2 * per_layer);
    mx_step_cache cache = {.mem = golden_dev_alloc(c, floats), .cap = floats};
    CHECK(golden_run_unet_cached(c, k.u, &in[0], &cache, got) == 0 && cache.recorded);
    CHECK(memcmp(got, plain, no * sizeof(float)) == 0);
    CHECK(golden_run_unet_cached(c, k.u, &in[1], &cache, got) == 0);
    CHECK(memcmp(got, plain + no, no * sizeof(float)) == 0);
    CHECK(cache.cursor == floats);
    CHECK(golden_run_unet_cached(c, k.u, &in[2], &cache, got) == 0); /* replays e0's K/V */
    CHECK(memcmp(got, plain + no, no * sizeof(float)) == 0 && memcmp(got, plain + 2 * no, no * sizeof(float)) != 0);
    printf("unet_tiny step cache: %zu floats, bit-identical, replayed\n", floats);
    mx_dev_free(c, cache.mem);
    free(x);
    free(e);
    free(plain);
    free(got);
    free_unet(&k);
}

/* The class of bug of weights bound through a host binder and run on a device context (on CUDA:
 * host pointers in GPU kernels) fails here on any machine: cpu-strict refuses the first op's host
 * weight, the op does not run, and the download reports it, naming the op, the argument and the
 * tensor's shape (time_embedding.linear_1.weight, [128, 32] in unet_tiny, is the first). */
static void check_host_weights_refused(void) {
    mx_ctx c;
    mx_status st = {0};
    mx_safetensors wf;
    mx_binder b;
    mx_unet_config cfg;
    mx_unet *u = NULL;
    size_t len, bytes = 0;
    char *text = golden_text("unet_tiny", "config.json", &len);
    CHECK(mx_ctx_create_on(&c, MX_BACKEND_CPU_STRICT, 1, mx_cpu_isa_for(MX_PREC_FP32), (size_t)16 << 20, &st) == 0);
    CHECK(text && mx_unet_config_parse(&cfg, text, len, "unet_tiny", &st) == 0);
    free(text);
    CHECK(golden_open(&wf, "unet_tiny", "diffusion_pytorch_model.safetensors") == 0);
    CHECK(mx_binder_st(&b, &wf, "", &st) == 0 && mx_unet_load(&u, &cfg, &b, &st) == 0); /* no device binder */
    if (!u) return;
    int H = 8, W = 8, T = 7;
    size_t ns = (size_t)cfg.in_channels * H * W, ne = (size_t)T * cfg.cross_attention_dim;
    size_t no = (size_t)cfg.out_channels * H * W;
    float *host = calloc(ns + ne + no + 1, sizeof(float));
    host[ns + ne + no] = 500.0f;
    float *dev = mx_dev_from_host(&c, host, ns + ne + no + 1, &st);
    mx_unet_input in = {.sample = dev, .timesteps = dev + ns + ne + no, .encoder_hidden_states = dev + ns, .B = 1, .H = H,
                        .W = W, .T = T};
    mx_arena a;
    CHECK(mx_unet_arena_bytes(u, 1, H, W, T, &bytes, &st) == 0 && mx_arena_create_on(&a, c.be, bytes, &st) == 0);
    CHECK(mx_unet_forward(&c, u, &in, dev + ns + ne, &a, &st) == 0); /* ops queue; the fault shows at the download */
    CHECK(mx_download(&c, host, dev + ns + ne, no, &st) != 0);
    printf("host-bound unet_tiny on cpu-strict: %s\n", st.msg);
    CHECK(strstr(st.msg, "op linear: weight w [128, 32] (f32)") && strstr(st.msg, "mx_binder_device"));
    mx_arena_destroy(&a);
    mx_dev_free(&c, dev);
    free(host);
    mx_unet_free(u);
    mx_binder_free(&b);
    mx_st_close(&wf);
    mx_ctx_destroy(&c);
}

int main(void) {
    mx_ctx c;
    check_host_weights_refused();
    if (golden_ctx(&c)) return 1;
    check_golden(&c, "unet_tiny", "diffusion_pytorch_model.safetensors", "outputs.safetensors", 1);
    check_golden(&c, "unet_tiny", "diffusion_pytorch_model.fp16.safetensors", "outputs_fp16w.safetensors", 0);
    int mini = golden_have("unet_mini", "inputs.safetensors"); /* outside the repository */
    if (mini) {
        check_golden(&c, "unet_mini", "diffusion_pytorch_model.safetensors", "outputs.safetensors", 1);
        check_golden(&c, "unet_mini", "diffusion_pytorch_model.fp16.safetensors", "outputs_fp16w.safetensors", 0);
    }
    check_batch_independence(&c);
    check_halves_equal(&c, "fp32");
    check_linear_projection(&c);
    check_step_cache(&c);
    mx_ctx_destroy(&c);
    if (golden_bf16_ctx(&c, "test_nn_unet") == 0) { /* bf16 arithmetic against the fp32 goldens */
        check_golden(&c, "unet_tiny", "diffusion_pytorch_model.safetensors", "outputs.safetensors", 1);
        if (mini) check_golden(&c, "unet_mini", "diffusion_pytorch_model.safetensors", "outputs.safetensors", 1);
        check_halves_equal(&c, "bf16");
        mx_ctx_destroy(&c);
    }
    return mx_test_finish("test_nn_unet");
}
