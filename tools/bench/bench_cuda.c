/* bench_cuda: the SD1.5 networks on the CUDA backend at the shapes of one guided view step
 * (latent 64x64, classifier-free guidance: batch 2): the depth ControlNet, the UNet with its
 * residuals, one guided step (two ControlNets, the second accumulating its residuals into the
 * first's, then the UNet: the depth ControlNet stands in for the inpaint one, same architecture and
 * shapes), and one VAE decode. The last line, `matex: controlnet_ms=... unet_ms=... guided_step_ms=...
 * vae_decode_ms=...`, is what gpu_check.sh divides by the peer's (tools/scripts/gpu_check.sh). Per network: the median wall time of a call over --calls calls
 * (each call waited for: one 4-byte download after it), its GFLOP and TFLOP/s. With --profile, one
 * more call of each with the per-op wall time (ops/profile.h); run it under MATEX_CUDA_SYNC=1,
 * which makes every op wait for its kernels, so an op's wall time is its GPU time plus one launch
 * and one wait. The anchor for the TFLOP/s (the card's measured matrix peak) is measured by the
 * caller in the same run (tools/scripts/gpu_check.sh).
 * With --load, only the load, as a texture job does it (a pool of every CPU): its time against
 * issue 39's goal (the 3.6 GB fp16 set onto the GPU in under 1 s) and its parts.
 * In a build without the CUDA backend (plain `make bench`) it says so and times nothing.
 * Usage: bench_cuda [WEIGHTS.mxw (default: bench_sd15.h's file)] [--calls N] [--profile] [--load] */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../ops/ops.h"
#include "../../ops/profile.h"
#include "../../ops/record.h"
#include "../../pipeline/nn/controlnet.h"
#include "../../pipeline/nn/unet.h"
#include "../../pipeline/nn/vae.h"
#include "../../pipeline/texture/models.h"
#include "../../runtime/arena.h"
#include "../../pipeline/texture/digest.h"
#include "../../runtime/log.h"
#include "bench_sd15.h"

#ifdef MX_WITH_CUDA
#include "../../ops/cuda/cuda_backend.h"

enum { B = 2, H = 64, W = 64, T = 77, MAX_CALLS = 101 };

typedef struct {
    mx_ctx c;
    mx_models m;
    mx_arena a;
    float *sample, *ehs, *ts, *cond, *out, *img;
    float *res[MX_UNET_MAX_RES + 1];
    int nres;
    mx_record step; /* the guided step as a recorded region: a CUDA graph under MATEX_CUDA_GRAPH=1 */
} bench;

/* n floats on the device, filled from a fixed sequence in [lo, hi). */
static float *device_filled(bench *b, size_t n, float lo, float hi, unsigned seed, mx_status *st) {
    float *host = bench_filled(n, lo, hi, seed);
    float *d = host ? mx_dev_from_host(&b->c, host, n, st) : NULL;
    free(host);
    return d;
}

static int setup_buffers(bench *b, mx_status *st) {
    const mx_unet_config *cfg = mx_controlnet_cfg(b->m.cn_depth);
    int D = cfg->cross_attention_dim, C, h, w;
    float ts[B] = {981, 981};
    b->nres = mx_unet_num_residuals(cfg);
    for (int i = 0; i <= b->nres; i++) {
        mx_unet_residual_shape(cfg, i, H, W, &C, &h, &w);
        if (!(b->res[i] = mx_dev_alloc(&b->c, (size_t)B * C * h * w, st))) return -1;
    }
    size_t ub, cb, vb;
    if (!(b->sample = device_filled(b, (size_t)B * 4 * H * W, -1, 1, 1, st)) ||
        !(b->ehs = device_filled(b, (size_t)B * T * D, -1, 1, 2, st)) ||
        !(b->cond = device_filled(b, (size_t)B * 3 * H * 8 * W * 8, 0, 1, 3, st)) ||
        !(b->ts = mx_dev_from_host(&b->c, ts, B, st)) || !(b->out = mx_dev_alloc(&b->c, (size_t)B * 4 * H * W, st)) ||
        !(b->img = mx_dev_alloc(&b->c, (size_t)3 * H * 8 * W * 8, st)) ||
        mx_unet_arena_bytes(b->m.unet, B, H, W, T, &ub, st) ||
        mx_controlnet_arena_bytes(b->m.cn_depth, B, H, W, T, &cb, st) ||
        mx_vae_decode_arena_bytes(b->m.vae, 1, H, W, &vb, st))
        return -1;
    size_t need = ub > cb ? ub : cb;
    return mx_arena_create_on(&b->a, b->c.be, need > vb ? need : vb, st);
}

enum { NET_CONTROLNET, NET_UNET, NET_GUIDED_STEP, NET_VAE_DECODE, NETS };

/* One ControlNet call: its residuals written (accumulate 0) or added into b->res (1). */
static int run_controlnet(bench *b, int accumulate, mx_status *st) {
    mx_controlnet_input ci = {b->sample, b->ts, b->ehs, b->cond, B, H, W, T, 0.8f, 0};
    return mx_controlnet_forward(&b->c, b->m.cn_depth, &ci, b->res, b->res[b->nres], accumulate, &b->a, st);
}

/* Queues one call of network `net` (NET_*). */
static int queue_net(bench *b, int net, mx_status *st) {
    int rc;
    if (net == NET_CONTROLNET) {
        rc = run_controlnet(b, 0, st);
    } else if (net == NET_UNET || net == NET_GUIDED_STEP) {
        if (net == NET_GUIDED_STEP && (run_controlnet(b, 0, st) || run_controlnet(b, 1, st))) return -1;
        mx_unet_input ui = {.sample = b->sample, .timesteps = b->ts, .encoder_hidden_states = b->ehs, .B = B, .H = H,
                            .W = W, .T = T, .down_residuals = (const float *const *)b->res,
                            .mid_residual = b->res[b->nres]};
        rc = mx_unet_forward(&b->c, b->m.unet, &ui, b->out, &b->a, st);
    } else {
        rc = mx_vae_decode(&b->c, b->m.vae, b->sample, 1, H, W, b->img, &b->a, st);
    }
    return rc;
}

static int queue_guided_step(void *arg, mx_status *st) { return queue_net((bench *)arg, NET_GUIDED_STEP, st); }

/* One call of network `net`, waited for (a 4-byte download). The guided step is a recorded region
 * (ops/record.h), as the denoising loop's: under MATEX_CUDA_GRAPH=1 its second call is captured and
 * the later ones (the timed calls) replay it. */
static int run_net(bench *b, int net, mx_status *st) {
    float one;
    int rc = net == NET_GUIDED_STEP ? mx_ctx_recorded(&b->c, &b->step, queue_guided_step, b, st) : queue_net(b, net, st);
    return rc || mx_download(&b->c, &one, b->out, 1, st) ? -1 : 0;
}

/* The launches of one guided step, counted by capturing it as one CUDA graph (not run); or why it
 * cannot be one graph yet. */
static void count_launches(bench *b) {
    size_t n = 0;
    mx_status st;
    if (mx_cuda_backend_capture_count(b->c.be, queue_guided_step, b, &n, &st) == 0)
        printf("guided step: %zu launches (kernels, copies, memsets), captured as one CUDA graph\n", n);
    else
        printf("guided step: launches not counted, the step cannot be captured as one CUDA graph: %s\n", st.msg);
}

static int cmp_double(const void *x, const void *y) {
    double a = *(const double *)x, b = *(const double *)y;
    return a < b ? -1 : a > b;
}

static void print_profile(const mx_profile *p, double wall) {
    int done[MX_OP_COUNT] = {0};
    double in_ops = 0;
    for (int op = 0; op < MX_OP_COUNT; op++) in_ops += p->op_wall[op];
    for (;;) {
        int best = -1;
        for (int op = 0; op < MX_OP_COUNT; op++)
            if (!done[op] && p->op_calls[op] && (best < 0 || p->op_wall[op] > p->op_wall[best])) best = op;
        if (best < 0) break;
        done[best] = 1;
        printf("    %-20s %8.2f ms %5.1f%%  %5ld calls  %7.1f us/call\n", mx_op_name(best), 1e3 * p->op_wall[best],
               100 * p->op_wall[best] / wall, p->op_calls[best], 1e6 * p->op_wall[best] / (double)p->op_calls[best]);
    }
    printf("    %-20s %8.2f ms %5.1f%%\n", "outside ops", 1e3 * (wall - in_ops), 100 * (wall - in_ops) / wall);
}

/* The median wall time of one call of `net` (seconds) into *median. */
static int bench_net(bench *b, int net, int calls, int profile, double *median, mx_status *st) {
    static const char *const names[NETS] = {"ControlNet 64x64 batch 2", "UNet 64x64 batch 2 (+residuals)",
                                            "guided step: 2 ControlNets + UNet", "VAE decode 64x64 batch 1"};
    double cn = mx_controlnet_flops(b->m.cn_depth, B, H, W, T, 0), unet = mx_unet_flops(b->m.unet, B, H, W, T, 0);
    double flops = net == NET_CONTROLNET ? cn
                 : net == NET_UNET       ? unet
                 : net == NET_GUIDED_STEP ? 2 * cn + unet
                                          : mx_vae_decode_flops(b->m.vae, 1, H, W);
    double secs[MAX_CALLS];
    for (int i = 0; i < 2; i++)
        if (run_net(b, net, st)) return -1; /* warm-up: cuBLASLt plans, module load */
    for (int i = 0; i < calls; i++) {
        double t0 = mx_now();
        if (run_net(b, net, st)) return -1;
        secs[i] = mx_now() - t0;
    }
    qsort(secs, (size_t)calls, sizeof secs[0], cmp_double);
    double med = secs[calls / 2];
    *median = med;
    printf("%-34s %8.2f ms median (min %.2f, max %.2f) %7.1f GFLOP %7.1f TFLOP/s%s\n", names[net], 1e3 * med,
           1e3 * secs[0], 1e3 * secs[calls - 1], flops / 1e9, flops / med / 1e12,
           net == NET_GUIDED_STEP && b->step.graph ? " (one CUDA graph)" : "");
    if (profile) {
        mx_profile p;
        memset(&p, 0, sizeof p);
        b->c.prof = &p;
        double t0 = mx_now();
        int rc = run_net(b, net, st);
        double wall = mx_now() - t0;
        b->c.prof = NULL;
        if (rc) return -1;
        printf("  per op, one call (%.2f ms with MATEX_CUDA_SYNC=%s):\n", 1e3 * wall,
               getenv("MATEX_CUDA_SYNC") ? getenv("MATEX_CUDA_SYNC") : "unset");
        print_profile(&p, wall);
    }
    return 0;
}

/* Where loading went (issue 39: the 3.6 GB fp16 set onto the GPU in under 1 s): the weight file's
 * stream (read by several threads into pinned chunks, copied while read) against the goal, the
 * other uploads through the staging halves, the device allocations. */
static void print_load(mx_backend *be) {
    mx_cuda_upload_stats us;
    mx_cuda_backend_upload_stats(be, &us);
    printf("load: weight file %.2f GB onto the GPU in %.3f s (%.1f GB/s; goal for the 3.6 GB set: under 1 s): "
           "%d readers in pread %.2f s (summed), waiting for reads %.3f s, for copies %.3f s, in the digest %.3f s\n",
           us.file_bytes / 1e9, us.file_s, us.file_s > 0 ? us.file_bytes / 1e9 / us.file_s : 0.0, us.file_readers,
           us.file_read_s, us.file_fill_wait_s, us.file_copy_wait_s, us.file_seen_s);
    printf("load: other uploads %.2f GB through pinned staging (host copies %.2f s, waits for the copy engine %.2f s), "
           "%llu device allocations %.3f s\n",
           us.bytes / 1e9, us.copy_s, us.wait_s, us.allocs, us.alloc_s);
}

/* --load: the model set loaded as a texture job loads it (mx_models_load: what report.json's load_s
 * times), the parts printed, and the weight digest (taken from the stream) timed alone, as a
 * second read of the file would cost it. */
static int bench_load(const char *weights) {
    mx_ctx c;
    mx_models m;
    mx_status st;
    char hex[32];
    double t0 = mx_now();
    if (mx_ctx_create_on(&c, MX_BACKEND_CUDA, 0, mx_cpu_isa_for(MX_PREC_FP32), (size_t)64 << 20, &st)) {
        fprintf(stderr, "bench_cuda: %s\n", st.msg);
        return 1;
    }
    double t1 = mx_now();
    if (mx_models_load(&m, &c, weights, MX_MODELS_NEED_DEPTH, &st)) {
        fprintf(stderr, "bench_cuda: %s\n", st.msg);
        mx_ctx_destroy(&c);
        return 1;
    }
    double t2 = mx_now();
    mx_file_digest_hex(c.pool, weights, hex);
    double t3 = mx_now();
    printf("load: %.2f GB set in %.3f s (mx_models_load, report.json's load_s; goal: under 1 s for the 3.6 GB set: %s), "
           "after the CUDA context %.2f s\n",
           bench_file_mb(weights) * (1 << 20) / 1e9, t2 - t1, t2 - t1 < 1.0 ? "met" : "NOT met", t1 - t0);
    print_load(c.be);
    printf("load: the weight digest alone, as a second read (%d threads): %.3f s\n", mx_pool_threads(c.pool), t3 - t2);
    mx_models_free(&m);
    mx_ctx_destroy(&c);
    return 0;
}

int main(int argc, char **argv) {
    const char *weights = NULL;
    char path[1100];
    int calls = 11, profile = 0, bad = 0, load_only = 0;
    for (int i = 1; i < argc && !bad; i++) {
        if (!strcmp(argv[i], "--calls") && i + 1 < argc) calls = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--profile")) profile = 1;
        else if (!strcmp(argv[i], "--load")) load_only = 1;
        else if (argv[i][0] != '-' && !weights) weights = argv[i];
        else bad = 1;
    }
    if (bad || calls < 1 || calls > MAX_CALLS) {
        fprintf(stderr, "usage: bench_cuda [WEIGHTS.mxw] [--calls N (1..%d)] [--profile] [--load]\n", MAX_CALLS);
        return 2;
    }
    if (!weights) {
        if (bench_sd15_file(path, sizeof path, 0)) return 1;
        weights = path;
    }
    if (load_only) return bench_load(weights);
    bench b;
    mx_status st;
    memset(&b, 0, sizeof b);
    double t0 = mx_now();
    if (mx_ctx_create_on(&b.c, MX_BACKEND_CUDA, 1, mx_cpu_isa_for(MX_PREC_FP32), (size_t)64 << 20, &st) ||
        mx_models_load(&b.m, &b.c, weights, MX_MODELS_NEED_DEPTH, &st) || setup_buffers(&b, &st)) {
        fprintf(stderr, "bench_cuda: %s\n", st.msg);
        return 1;
    }
    printf("load + upload %.2f s; %d timed calls per network\n", mx_now() - t0, calls);
    print_load(b.c.be);
    int rc = 0;
    double med[NETS];
    for (int net = 0; net < NETS && !rc; net++)
        if ((rc = bench_net(&b, net, calls, profile && net != NET_GUIDED_STEP, &med[net], &st)))
            fprintf(stderr, "bench_cuda: %s\n", st.msg);
    if (!rc) count_launches(&b);
    if (!rc) /* the names of the peer's line (peer_diffusers.py) */
        printf("matex: controlnet_ms=%.2f unet_ms=%.2f guided_step_ms=%.2f vae_decode_ms=%.2f\n",
               1e3 * med[NET_CONTROLNET], 1e3 * med[NET_UNET], 1e3 * med[NET_GUIDED_STEP],
               1e3 * med[NET_VAE_DECODE]);
    mx_record_free(&b.c, &b.step); /* before the buffers its graph uses */
    float *bufs[] = {b.sample, b.ehs, b.ts, b.cond, b.out, b.img};
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++) mx_dev_free(&b.c, bufs[i]);
    for (int i = 0; i <= b.nres; i++) mx_dev_free(&b.c, b.res[i]);
    mx_arena_destroy(&b.a);
    mx_models_free(&b.m);
    mx_ctx_destroy(&b.c);
    return rc ? 1 : 0;
}
#else
int main(void) {
    printf("bench_cuda: this build has no CUDA backend (make cuda): nothing timed\n");
    return 0;
}
#endif
