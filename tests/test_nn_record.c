/* Recorded regions (ops/record.h) and the denoising step as one (pipeline/nn/sd_pipeline.c):
 * - cpu-strict refuses an allocation, a free, an upload or a download inside a region's later calls,
 *   naming the call (what a CUDA graph cannot capture), and a later call whose ops or arguments
 *   differ from the second's (a host value a graph's replay would not have); the first runs freely;
 * - a region reading a device value written before each call (the timestep's pattern) gives each
 *   call's result; on CUDA under MATEX_CUDA_GRAPH=1 it must have been captured as a graph;
 * - the tiny networks' denoising loop on MX_TEST_DEVICE (cpu-strict in make test, so every region
 *   is checked): DPM-Solver++ with CFG and two ControlNets over two latents, LCM without CFG, step
 *   caches on: the latents with the backend's region hook equal those without it, bit for bit. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/record.h"
#include "../pipeline/nn/sd_pipeline.h"
#include "nn_golden.h"
#include "tiny_nets.h"
#include "util_test.h"

enum { N = 64 };

/* What a region does (bad_region); DO_SCALAR passes a host value that changes call by call. */
typedef enum { DO_OPS, DO_UPLOAD, DO_DOWNLOAD, DO_ALLOC, DO_FREE, DO_SCALAR } region_kind;

typedef struct region_arg {
    const mx_ctx *c;
    region_kind kind;
    float *dev, *freed; /* freed: a buffer made before the call that the region frees (DO_FREE) */
    float host[N];
    int call;
} region_arg;

static int bad_region(void *user, mx_status *st) {
    region_arg *r = user;
    mx_fill(r->c, r->dev, 1.0f, N);
    switch (r->kind) {
    case DO_UPLOAD: return mx_upload(r->c, r->dev, r->host, N, st);
    case DO_DOWNLOAD: return mx_download(r->c, r->host, r->dev, N, st);
    case DO_ALLOC: {
        float *p = mx_dev_alloc(r->c, N, st);
        mx_dev_free(r->c, p);
        return p ? 0 : -1;
    }
    case DO_FREE: mx_dev_free(r->c, r->freed); return 0;
    case DO_SCALAR: mx_fill(r->c, r->dev, (float)r->call, N); return 0;
    default: return 0;
    }
}

/* Three calls of a region of `kind` on cpu-strict: the first always runs; the later ones pass
 * only for ops, else fail naming `call`; a changing scalar fails the third (the second is the one
 * a graph captures). */
static void check_refusal(const mx_ctx *c, region_kind kind, const char *call) {
    region_arg r = {c, kind, NULL, NULL, {0}, 0};
    mx_record rec = {0};
    mx_status st = {0};
    r.dev = golden_dev_alloc(c, N);
    for (int i = 0; i < 3; i++) {
        if (kind == DO_FREE) r.freed = golden_dev_alloc(c, N);
        memset(&st, 0, sizeof st);
        r.call = i;
        int rc = mx_ctx_recorded(c, &rec, bad_region, &r, &st);
        int want_fail = kind == DO_SCALAR ? i == 2 : i > 0 && kind != DO_OPS;
        printf("cpu-strict region %d, call %d: %s\n", (int)kind, i + 1, rc ? st.msg : "ran");
        CHECK((rc != 0) == want_fail);
        if (want_fail) CHECK(strstr(st.msg, call) && strstr(st.msg, "recorded region"));
        if (kind == DO_SCALAR && i == 2) CHECK(strstr(st.msg, "differs") != NULL);
    }
    mx_record_free(c, &rec);
    mx_dev_free(c, r.dev);
}

static void test_strict_refusals(void) {
    mx_ctx c;
    mx_status st;
    if (mx_ctx_create_on(&c, MX_BACKEND_CPU_STRICT, 1, mx_cpu_isa_for(MX_PREC_FP32), (size_t)1 << 20, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        CHECK(0);
        return;
    }
    check_refusal(&c, DO_OPS, "");
    check_refusal(&c, DO_UPLOAD, "mx_upload");
    check_refusal(&c, DO_DOWNLOAD, "mx_download");
    check_refusal(&c, DO_ALLOC, "mx_dev_alloc");
    check_refusal(&c, DO_FREE, "mx_dev_free");
    check_refusal(&c, DO_SCALAR, "(fill)");
    mx_ctx_destroy(&c);
}

/* y = 2·x + 1, x written before the region each call. */
typedef struct affine_arg {
    const mx_ctx *c;
    float *x, *y;
} affine_arg;

static int affine_region(void *user, mx_status *st) {
    affine_arg *a = user;
    (void)st;
    mx_affine(a->c, a->y, a->x, 2.0f, 1.0f, N);
    return 0;
}

/* 1 when this run must replay CUDA graphs (MATEX_CUDA_GRAPH=1 on CUDA, not synchronising each op). */
static int graphs_expected(const mx_ctx *c) {
    const char *g = getenv("MATEX_CUDA_GRAPH"), *s = getenv("MATEX_CUDA_SYNC");
    return c->be && c->be->kind == MX_BACKEND_CUDA && g && !strcmp(g, "1") && !(s && !strcmp(s, "1"));
}

static void test_changing_input(const mx_ctx *c) {
    affine_arg a = {c, golden_dev_alloc(c, N), golden_dev_alloc(c, N)};
    mx_record rec = {0};
    mx_status st = {0};
    float got[N];
    int ok = 1;
    for (int call = 0; call < 5 && ok; call++) {
        mx_fill(c, a.x, (float)(10 * call), N); /* outside the region, as the timestep */
        ok = mx_ctx_recorded(c, &rec, affine_region, &a, &st) == 0 && mx_download(c, got, a.y, N, &st) == 0;
        for (int i = 0; ok && i < N; i++) ok = got[i] == 20.0f * call + 1.0f;
        if (!ok) fprintf(stderr, "region call %d: %s\n", call + 1, st.msg[0] ? st.msg : "wrong result");
    }
    printf("a region with a changing device input: %s; %s\n", ok ? "every call right" : "WRONG",
           rec.graph ? "captured by the backend" : "run op by op");
    CHECK(ok);
    CHECK(!graphs_expected(c) || rec.graph != NULL);
    mx_record_free(c, &rec);
    mx_dev_free(c, a.x);
    mx_dev_free(c, a.y);
}

/* The LCM step's fresh noise: a fixed sequence per step. */
static int step_noise(void *user, int step, float *noise, size_t numel) {
    (void)user;
    mx_fill_random(noise, numel, 100 + (uint64_t)step, -1.0f, 1.0f);
    return 0;
}

enum { LAT = 2, H = 8, W = 8, T = 77, STEPS = 4 };

typedef struct loop_inputs {
    float *text, *uncond, *control; /* [LAT, T, Ct] each; [LAT, 3, 8H, 8W] */
    float lat[LAT * 4 * H * W];
} loop_inputs;

/* The loop on c: DPM-Solver++ with CFG and two ControlNets, or LCM without CFG and one, into out. */
static int run_loop(const tiny_nets *n, const mx_ctx *c, const loop_inputs *in, int lcm, float *out, mx_status *st) {
    mx_sched_config base, cfg;
    mx_sched s;
    mx_sched_config_sd15(&base);
    if (lcm) mx_sched_config_lcm(&cfg, &base);
    else cfg = base;
    if (mx_sched_init(&s, c, &cfg, STEPS, sizeof in->lat / sizeof in->lat[0], st)) return -1;
    s.noise_fn = step_noise;
    float item_w[LAT] = {0.3f, 0.6f};
    mx_sd_control two[2] = {{n->cnet, in->control, 0.5f, NULL}, {n->cnet, in->control, 0.0f, item_w}};
    mx_sd_request rq = {.unet = n->unet, .controls = two, .n_controls = lcm ? 1 : 2, .cond_text = in->text,
                        .uncond_text = in->uncond, .T = T, .guidance = lcm ? 1.0f : 7.5f, .sched = &s};
    memcpy(out, in->lat, sizeof in->lat);
    int rc = mx_sd_denoise(&rq, c, out, LAT, H, W, st);
    mx_sched_free(&s);
    return rc;
}

static void test_loop(const tiny_nets *n, const mx_ctx *c) {
    size_t text = (size_t)LAT * T * (size_t)n->ucfg.cross_attention_dim, ctl = (size_t)LAT * 3 * 8 * H * 8 * W;
    loop_inputs in = {malloc(text * sizeof(float)), malloc(text * sizeof(float)), malloc(ctl * sizeof(float)), {0}};
    /* the same device and weights without the region hook: every step op by op */
    mx_backend plain = *c->be;
    mx_ctx cc = *c;
    plain.recorded = NULL;
    cc.be = &plain;
    if (!in.text || !in.uncond || !in.control) {
        CHECK(0);
        goto done;
    }
    mx_fill_random(in.text, text, 1, -1.0f, 1.0f);
    mx_fill_random(in.uncond, text, 2, -1.0f, 1.0f);
    mx_fill_random(in.control, ctl, 3, 0.0f, 1.0f);
    mx_fill_random(in.lat, sizeof in.lat / sizeof in.lat[0], 4, -1.0f, 1.0f);
    for (int lcm = 0; lcm < 2; lcm++) {
        float with[LAT * 4 * H * W], without[LAT * 4 * H * W];
        mx_status st = {0};
        int ok = run_loop(n, c, &in, lcm, with, &st) == 0;
        if (ok) ok = run_loop(n, &cc, &in, lcm, without, &st) == 0;
        if (!ok) fprintf(stderr, "%s loop: %s\n", lcm ? "LCM" : "DPM", st.msg);
        CHECK(ok);
        int same = ok && memcmp(with, without, sizeof with) == 0;
        printf("%s, %d latents, %d steps: latents with the step as a recorded region %s those without\n",
               lcm ? "LCM, one ControlNet" : "DPM-Solver++, CFG, two ControlNets", LAT, STEPS,
               same ? "bit-equal to" : "DIFFER from");
        CHECK(same);
    }
done:
    free(in.text);
    free(in.uncond);
    free(in.control);
}

static void test_all(const tiny_nets *n, const mx_ctx *c) {
    test_changing_input(c);
    test_loop(n, c);
}

int main(void) {
    test_strict_refusals();
    return tiny_nets_main("test_nn_record", TINY_UNET | TINY_CONTROLNET, test_all);
}
