/* bench_nets: the full SD1.5 set (UNet, 2 ControlNets, VAE, CLIP text encoder) with golden-v1
 * rule weights in one fp16 matex weight file (bench_sd15.h: cached outside the repository).
 * Reports load time, peak RSS, and the time, FLOPs and GFLOP/s of one ControlNet call (also as a
 * job's later steps make it: their step cache replays the hint embedding and the prompt's K/V,
 * so those FLOPs are not counted either), one UNet
 * call (64×64 latent, batch 2, 77 tokens), one VAE decode (64×64 latent, batch 1) and one CLIP
 * call (batch 2), each in fp32 and, where the CPU has AVX512_BF16, in bf16 right after it (same
 * load on the machine), with the share of the measured peak of these cores (bench_sd15.h).
 * Each context keeps the weights packed once (mx_ctx_pack_weights), as a texture job does, and
 * each network's first call there (it packs them and touches the arena's pages) runs untimed
 * before the timed one: the timed call is one of the many calls of a job; the first call's extra
 * time over it and the panels it packed are reported (the packing of a job's first calls).
 * Then, per network and precision, where the time went (ops/profile.h), as shares of the CPU
 * time of the call (what survives other people's load on a shared machine): each op, the GEMM's
 * parts (micro-kernel with the bias it adds, packing of A and B — B is the input band of a conv —,
 * the rest: task setup, waiting at the end of a phase), the micro-kernel's own GFLOP/s, the cores'
 * idle time (threads × wall − CPU: idle on a quiet machine, also preempted on a loaded one; the
 * call's line splits off the time its threads waited on the run queue, so that what is left is
 * its own idle time — joins, serial parts — even on a shared machine) and
 * the minor page faults. The timers read a CPU clock a few times per GEMM task and twice per op
 * (well under 1 % here); --no-profile runs without.
 * Usage: bench_nets [--threads N] [--weights PATH] [--skip-vae] [--skip-controlnet] [--skip-unet] [--no-profile]
 *                   [--batch 1|2] (2, the default: a default job's CFG calls; 1: --fast's) */
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../../ops/ops.h"
#include "../../ops/cpu/wpack.h"
#include "../../ops/profile.h"
#include "../../pipeline/nn/clip.h"
#include "../../pipeline/nn/controlnet.h"
#include "../../pipeline/nn/netcfg.h"
#include "../../pipeline/nn/registry.h"
#include "../../pipeline/nn/unet.h"
#include "../../pipeline/nn/vae.h"
#include "../../pipeline/texture/models.h"
#include "../../runtime/log.h"
#include "../../weights/weights.h"
#include "bench_sd15.h"

static double peak_rss_mb(void) {
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_maxrss / 1024.0;
}

/* ---- the runs ---- */

/* Network `kind` of wf under `prefix` (NULL: the kind's name), through its registry entry. */
static int load_net(const mx_weightfile *wf, const char *kind, const char *prefix, mx_binder *b, void **net,
                    mx_status *st) {
    char p[80];
    snprintf(p, sizeof p, "%s.", prefix ? prefix : kind);
    return mx_binder_wf(b, wf, p, st) || mx_net_load_kind(kind, net, wf, prefix, b, st) ? -1 : 0;
}

/* One network in fp32 ([0]) and bf16 ([1]; 0 without bf16): wall seconds, process CPU seconds
 * (all threads), minor page faults, where the time went, and its FLOPs. */
typedef struct net_time {
    const char *what;
    double first[2]; /* wall seconds of the untimed first call (packs the weights, touches the arena) */
    size_t packed[2]; /* bytes of panels its first call added to the context's cache */
    double secs[2], cpu[2], flops;
    double waited[2]; /* seconds its threads waited for a CPU while runnable (runqueue_wait_seconds) */
    long faults[2];
    mx_profile prof[2];
} net_time;

/* A line: per precision the wall time, the GFLOP/s over CPU time (what `threads` cores of its
 * own would give: on a shared machine wall time also counts other people's work) and its share
 * of the measured peak; then the bf16 speed-up in wall and in CPU time. */
static void report(const net_time *t, const double peak[2], int threads) {
    double g = t->flops * 1e-9, r[2];
    for (int p = 0; p < 2; p++) r[p] = t->cpu[p] > 0 ? g / (t->cpu[p] / threads) : 0;
    printf("%-32s %6.0f %7.2f %7.1f %4.0f%%", t->what, g, t->secs[0], r[0], 100 * r[0] / peak[0]);
    if (t->secs[1] > 0)
        printf(" %7.2f %7.1f %4.0f%% %5.2fx %5.2fx\n", t->secs[1], r[1], 100 * r[1] / peak[1], t->secs[0] / t->secs[1],
               r[1] / r[0]);
    else
        printf(" %7s %7s %5s %6s %6s\n", "-", "-", "-", "-", "-");
}

static long minor_faults(void) {
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_minflt;
}

/* Seconds the process's threads have waited for a CPU while runnable (their time on the run
 * queue: other processes' load on a shared machine, not this one's joins), summed over its threads
 * (/proc/self/task/N/schedstat, second field, ns); 0 where the kernel does not report it. */
static double runqueue_wait_seconds(void) {
    DIR *d = opendir("/proc/self/task");
    double sum = 0;
    struct dirent *e;
    while (d && (e = readdir(d))) {
        char path[300];
        unsigned long long run, wait;
        if (e->d_name[0] == '.') continue;
        snprintf(path, sizeof path, "/proc/self/task/%s/schedstat", e->d_name);
        FILE *f = fopen(path, "r");
        if (f && fscanf(f, "%llu %llu", &run, &wait) == 2) sum += (double)wait * 1e-9;
        if (f) fclose(f);
    }
    if (d) closedir(d);
    return sum;
}

/* Starts (secs, cpu, faults; the context's profile when profiling) or, with stop, turns them
 * into elapsed values. */
static void clock_net(net_time *t, mx_ctx *c, int p, int stop, int profile) {
    double now = mx_now(), cpu = bench_cpu_seconds(CLOCK_PROCESS_CPUTIME_ID);
    long faults = minor_faults();
    double waited = runqueue_wait_seconds();
    t->waited[p] = stop ? waited - t->waited[p] : waited;
    t->secs[p] = stop ? now - t->secs[p] : now;
    t->cpu[p] = stop ? cpu - t->cpu[p] : cpu;
    t->faults[p] = stop ? faults - t->faults[p] : faults;
    c->prof = profile && !stop ? &t->prof[p] : NULL;
}

/* The roofline of every profile of these networks: the peaks measured before the runs and the
 * memory bandwidth (GFLOP/s, GB/s; 0: none). */
static void set_roofline(net_time *const *nets, int n, const double peak[2], double bw) {
    for (int i = 0; i < n; i++)
        for (int p = 0; p < 2; p++) {
            nets[i]->prof[p].peak_flops = peak[p] * 1e9;
            nets[i]->prof[p].bandwidth = bw * 1e9;
        }
}

/* Starts (or, with stop, ends) timing network t's untimed first call on context c of precision p:
 * its wall time and the bytes of panels it packs into the context's cache. */
static void clock_first_call(net_time *t, const mx_ctx *c, int p, int stop) {
    t->first[p] = stop ? mx_now() - t->first[p] : mx_now();
    t->packed[p] = stop ? mx_wpack_bytes(c->wpack) - t->packed[p] : mx_wpack_bytes(c->wpack);
}

/* The first calls' wall times and the packed weights they left in each context; then per network
 * and precision what the first call costs beyond a later one (packing its weights — reading them
 * from the file, widening, writing the panels into fresh memory — and touching the arena) and the
 * panels it packed. */
static void report_first_calls(const net_time *const nets[3], const mx_ctx *c, int nprec) {
    printf("first calls, untimed (they pack the weights and touch the arena), wall s fp32%s:", nprec == 2 ? "/bf16" : "");
    for (int i = 0; i < 3; i++)
        if (nets[i]) printf(" %s %.2f%s%.2f", nets[i]->what, nets[i]->first[0], nprec == 2 ? "/" : "", nets[i]->first[1]);
    printf("; weights packed: %.0f MB fp32", mx_wpack_bytes(c[0].wpack) / 1e6);
    if (nprec == 2) printf(", %.0f MB bf16", mx_wpack_bytes(c[1].wpack) / 1e6);
    printf("\n");
    for (int i = 0; i < 3; i++)
        for (int p = 0; p < nprec && nets[i]; p++)
            printf("  packing, %-32s %s: first call %.2f s - later call %.2f s = %.2f s for %.0f MB of panels\n",
                   nets[i]->what, p ? "bf16" : "fp32", nets[i]->first[p], nets[i]->secs[p],
                   nets[i]->first[p] - nets[i]->secs[p], nets[i]->packed[p] / 1e6);
}

/* ---- where the time went ---- */

/* One part of the breakdown: its share of the call's CPU time. */
static void part(const char *name, double secs, double whole) {
    if (secs > 0) printf(" %s %.1f%%", name, 100 * secs / whole);
}

/* The GEMM line of a user (linear or conv2d): the op's share of the CPU time, its parts, and
 * the micro-kernel's own rate (FLOPs over its CPU seconds, per `threads` cores). */
/* An op's threads idle while it ran: threads × its wall time − its CPU time, as a share of the
 * former (waits at the joins of its parallel loops, serial parts, preemption). */
static void op_idle(const mx_profile *pr, int op, int threads) {
    double tw = threads * pr->op_wall[op];
    if (tw > 0) printf(", idle %.1f%%", 100 * (tw - pr->op_secs[op]) / tw);
}

/* An op's roofline floor (ops/profile.h: its calls' FLOPs at the peak or bytes at the bandwidth,
 * whichever takes longer, summed) as a share of its wall time, and which bound dominates. */
static void op_floor(const mx_profile *pr, int op) {
    if (pr->bandwidth <= 0 || pr->op_wall[op] <= 0) return;
    printf(", floor %.0f%% of its wall (%s)", 100 * pr->op_floor[op] / pr->op_wall[op],
           pr->op_bytes[op] / pr->bandwidth > pr->op_flops[op] / pr->peak_flops ? "bytes" : "FLOPs");
}

static void report_gemm(const mx_profile *pr, int user, int op, double cpu, int threads, double peak) {
    static const char *const user_name[MX_GEMM_USERS] = {"linear", "conv2d"};
    const double *s = pr->gemm_secs[user];
    double busy = 0, whole = cpu;
    for (int q = 0; q < MX_GEMM_PARTS; q++) busy += s[q];
    printf("  %-18s %5.1f%% (%ld calls", user_name[user], 100 * pr->op_secs[op] / cpu, pr->op_calls[op]);
    op_idle(pr, op, threads);
    op_floor(pr, op);
    printf("):");
    part("micro", s[MX_GEMM_MICRO], whole);
    part(user == MX_GEMM_CONV ? "pack-A(weights)" : "pack-A(x)", s[MX_GEMM_PACK_A], whole);
    part(user == MX_GEMM_CONV ? "pack-B(input)" : "pack-B(weights)", s[MX_GEMM_PACK_B], whole);
    part("rest", pr->op_secs[op] - busy, whole);
    if (s[MX_GEMM_MICRO] > 0 && peak > 0)
        printf("; micro-kernel %.0f GFLOP/s = %.0f%% of peak", pr->gemm_flops[user] * 1e-9 / (s[MX_GEMM_MICRO] / threads),
               100 * pr->gemm_flops[user] * 1e-9 / (s[MX_GEMM_MICRO] / threads) / peak);
    printf("\n");
}

/* The call's roofline floor: the sum of its ops' floors, and what FLOPs alone and bytes alone
 * would take; the call's wall time as a multiple of the floor. */
static void report_floor(const mx_profile *pr, double wall) {
    if (pr->bandwidth <= 0) return;
    double floor = 0, flops = 0, bytes = 0;
    for (int op = 0; op < MX_OP_COUNT; op++) floor += pr->op_floor[op], flops += pr->op_flops[op], bytes += pr->op_bytes[op];
    printf("  roofline floor %.3f s (%.0f GFLOP alone %.3f s at %.0f GFLOP/s, %.1f GB alone %.3f s at %.1f GB/s): "
           "the call took %.2fx it\n", floor, flops * 1e-9, flops / pr->peak_flops, pr->peak_flops * 1e-9, bytes * 1e-9,
           bytes / pr->bandwidth, pr->bandwidth * 1e-9, floor > 0 ? wall / floor : 0);
}

/* The breakdown of one run: the GEMM users, then every other op with ≥ 0.1 % of the CPU time
 * (largest first), then the time outside any op (the network's own code: arena, loops). */
static void report_profile(const net_time *t, int p, double peak, int threads) {
    const mx_profile *pr = &t->prof[p];
    double wall = t->secs[p], cpu = t->cpu[p], in_ops = 0;
    double tw = threads * wall;
    printf("%s, %s: %.2f s wall, %.2f s CPU, cores idle %.1f%% of threads x wall (%.1f%% waiting for a CPU that "
           "others held, %.1f%% the call's own waits), %ld minor page faults\n",
           t->what, p ? "bf16" : "fp32", wall, cpu, 100 * (tw - cpu) / tw, 100 * t->waited[p] / tw,
           100 * (tw - cpu - t->waited[p]) / tw, t->faults[p]);
    for (int op = 0; op < MX_OP_COUNT; op++) in_ops += pr->op_secs[op];
    report_floor(pr, wall);
    report_gemm(pr, MX_GEMM_CONV, MX_OP_ID_conv2d, cpu, threads, peak);
    report_gemm(pr, MX_GEMM_LINEAR, MX_OP_ID_linear, cpu, threads, peak);
    int done[MX_OP_COUNT] = {0};
    done[MX_OP_ID_conv2d] = done[MX_OP_ID_linear] = 1;
    for (;;) {
        int best = -1;
        for (int op = 0; op < MX_OP_COUNT; op++)
            if (!done[op] && (best < 0 || pr->op_secs[op] > pr->op_secs[best])) best = op;
        if (best < 0 || pr->op_secs[best] < 1e-3 * cpu) break;
        done[best] = 1;
        printf("  %-18s %5.1f%% (%ld calls", mx_op_name(best), 100 * pr->op_secs[best] / cpu, pr->op_calls[best]);
        op_idle(pr, best, threads);
        op_floor(pr, best);
        printf(")\n");
    }
    printf("  %-18s %5.1f%%\n", "outside ops", 100 * (cpu - in_ops) / cpu);
}

typedef struct bench_opts {
    int threads, skip_vae, skip_cn, skip_unet, profile;
    int batch; /* 2: CFG's calls (the default job); 1: --fast's */
    const char *weights;
} bench_opts;

static int run_benchmarks(const bench_opts *o, mx_status *st) {
    mx_weightfile *wf = NULL;
    mx_binder bu, bc[2], bv, bt;
    mx_unet *u = NULL;
    mx_controlnet *cn[2] = {NULL, NULL};
    mx_vae *v = NULL;
    mx_clip *clip = NULL;
    double t0 = mx_now();
    if (mx_wf_open(&wf, o->weights, st) || load_net(wf, MX_NET_UNET, NULL, &bu, (void **)&u, st)) return -1;
    const char *cnp[2] = {MX_NET_CONTROLNET "_depth", MX_NET_CONTROLNET "_inpaint"};
    for (int i = 0; i < 2; i++)
        if (load_net(wf, MX_NET_CONTROLNET, cnp[i], &bc[i], (void **)&cn[i], st)) return -1;
    if (load_net(wf, MX_NET_VAE, NULL, &bv, (void **)&v, st) ||
        load_net(wf, MX_NET_TEXT_ENCODER, NULL, &bt, (void **)&clip, st))
        return -1;
    const mx_unet_config ucfg = *mx_unet_cfg(u), ccfg = *mx_controlnet_cfg(cn[0]);
    const mx_clip_config tcfg = clip->cfg;
    printf("%-34s %8.3f s (mmap + bind, 5 networks)\n", "load", mx_now() - t0);

    /* [0] fp32, [1] bf16 (when the CPU has it): each network runs in both, one after the other */
    mx_ctx c[2];
    mx_isa bf16_isa = mx_cpu_isa_for(MX_PREC_BF16);
    int nprec = mx_isa_precision(bf16_isa) == MX_PREC_BF16 ? 2 : 1;
    if (mx_ctx_create(&c[0], o->threads, mx_cpu_isa_for(MX_PREC_FP32), (size_t)512 << 20, st) ||
        (nprec == 2 && mx_ctx_create(&c[1], o->threads, bf16_isa, (size_t)512 << 20, st)))
        return -1;
    /* weights packed once per context: the bf16 one as a texture job does (models.h), the fp32 one
     * with room for all (its fp32 panels of fp16 weights take twice the file: one more file) */
    size_t wbytes = 0;
    for (size_t i = 0; i < mx_wf_count(wf); i++) wbytes += mx_wf_tensor(wf, i)->nbytes;
    if (mx_ctx_pack_weights(&c[0], wbytes, 1, st) || (nprec == 2 && mx_models_pack_weights(&c[1], st))) return -1;
    printf("threads %d, kernels %s%s%s\n", mx_pool_threads(c[0].pool), mx_isa_name(c[0].k->isa),
           nprec == 2 ? " and " : " (bf16 not available on this CPU)", nprec == 2 ? mx_isa_name(c[1].k->isa) : "");
    double bw = o->profile ? bench_bandwidth_gbs(&c[0]) : 0;
    double peak[2] = {bench_peak_gflops(&c[0], 0), nprec == 2 ? bench_peak_gflops(&c[1], 1) : 0};
    int B = o->batch, H = 64, W = 64, T = 77, D = ucfg.cross_attention_dim, cfg = B == 2;
    size_t ns = (size_t)B * ucfg.in_channels * H * W;
    float *sample = bench_filled(ns, -1, 1, 1), *ehs = bench_filled((size_t)B * T * D, -1, 1, 2), ts[2] = {981, 37};
    float *out = malloc(ns * sizeof *out);
    size_t ub, cb, vb;
    mx_arena a;
    if (mx_unet_arena_bytes(u, B, H, W, T, &ub, st) || mx_controlnet_arena_bytes(cn[0], B, H, W, T, &cb, st) ||
        mx_vae_decode_arena_bytes(v, 1, H, W, &vb, st))
        return -1;
    size_t need = ub > cb ? ub : cb;
    if (!o->skip_vae && vb > need) need = vb;
    printf("arena: UNet %.0f MB, ControlNet %.0f MB, VAE decode %.0f MB\n", ub / 1e6, cb / 1e6, vb / 1e6);
    if (mx_arena_create(&a, need, st)) return -1;

    /* residuals of the depth ControlNet, then the UNet with them */
    int nres = mx_unet_num_residuals(&ccfg), C, h, w;
    float *res[MX_UNET_MAX_RES + 1];
    for (int i = 0; i <= nres; i++) {
        mx_unet_residual_shape(&ccfg, i, H, W, &C, &h, &w);
        res[i] = calloc((size_t)B * C * h * w, sizeof(float));
    }
    float *cond = bench_filled((size_t)B * 3 * H * 8 * W * 8, 0, 1, 3);
    float *img = malloc((size_t)3 * H * 8 * W * 8 * sizeof *img);
    char cn_what[40], unet_what[40];
    snprintf(cn_what, sizeof cn_what, "ControlNet 64x64 batch %d", B);
    snprintf(unet_what, sizeof unet_what, "UNet 64x64 batch %d (+residuals)", B);
    net_time nt_cn = {.what = cn_what, .flops = mx_controlnet_flops(cn[0], B, H, W, T, 0)};
    /* a job's CFG call: both items one latent at one timestep, the prompts differ */
    float *sample_cfg = malloc(ns * sizeof *sample_cfg), ts_cfg[2] = {981, 981};
    memcpy(sample_cfg, sample, ns / 2 * sizeof *sample);
    memcpy(sample_cfg + ns / 2, sample, ns / 2 * sizeof *sample);
    int step_how = MX_FLOPS_REPLAYED | (cfg ? MX_FLOPS_HALVES_EQUAL : 0);
    net_time nt_cn_step = {.what = cfg ? "  a later CFG step (cache, halves)" : "  a later step (cache replayed)",
                           .flops = mx_controlnet_flops(cn[0], B, H, W, T, step_how)};
    net_time nt_unet = {.what = unet_what, .flops = mx_unet_flops(u, B, H, W, T, 0)};
    net_time nt_unet_cfg = {.what = "  same, CFG halves shared",
                            .flops = mx_unet_flops(u, B, H, W, T, MX_FLOPS_HALVES_EQUAL)};
    size_t cache_floats = 0;
    if (!o->skip_cn && mx_controlnet_cache_floats(cn[0], B, H, W, T, &cache_floats, st)) return -1;
    float *cache_mem = cache_floats ? malloc(cache_floats * sizeof(float)) : NULL;
    net_time nt_vae = {.what = "VAE decode 64x64 batch 1", .flops = mx_vae_decode_flops(v, 1, H, W)};
    set_roofline((net_time *[]){&nt_cn, &nt_cn_step, &nt_unet, &nt_unet_cfg, &nt_vae}, 5, peak, bw);
    for (int p = 0; p < nprec && !o->skip_cn; p++) {
        mx_controlnet_input ci = {sample, ts, ehs, cond, B, H, W, T, 0.8f, 0};
        mx_controlnet_input ci_cfg = {sample_cfg, ts_cfg, ehs, cond, B, H, W, T, 0.8f, 1};
        if (!cfg) ci_cfg = ci;
        clock_first_call(&nt_cn, &c[p], p, 0);
        if (mx_controlnet_forward(&c[p], cn[0], &ci, res, res[nres], 0, &a, st)) return -1;
        clock_first_call(&nt_cn, &c[p], p, 1);
        clock_net(&nt_cn, &c[p], p, 0, o->profile);
        if (mx_controlnet_forward(&c[p], cn[0], &ci, res, res[nres], 0, &a, st)) return -1;
        clock_net(&nt_cn, &c[p], p, 1, o->profile);
        /* a job's later CFG step: the first call records the step cache, the timed one replays it */
        mx_step_cache k = {.mem = cache_mem, .cap = cache_floats};
        if (!cache_mem) return mx_fail(st, MX_ENOMEM, "bench_nets: no memory for the step cache");
        if (mx_controlnet_forward_cached(&c[p], cn[0], &ci_cfg, &k, res, res[nres], 0, &a, st)) return -1;
        clock_net(&nt_cn_step, &c[p], p, 0, o->profile);
        if (mx_controlnet_forward_cached(&c[p], cn[0], &ci_cfg, &k, res, res[nres], 0, &a, st)) return -1;
        clock_net(&nt_cn_step, &c[p], p, 1, o->profile);
    }
    free(cache_mem);
    mx_unet_input ui = {.sample = sample, .timesteps = ts, .encoder_hidden_states = ehs, .B = B, .H = H, .W = W, .T = T,
                        .down_residuals = o->skip_cn ? NULL : (const float *const *)res,
                        .mid_residual = o->skip_cn ? NULL : res[nres]};
    for (int p = 0; p < nprec && !o->skip_unet; p++) {
        clock_first_call(&nt_unet, &c[p], p, 0);
        if (mx_unet_forward(&c[p], u, &ui, out, &a, st)) return -1;
        clock_first_call(&nt_unet, &c[p], p, 1);
        clock_net(&nt_unet, &c[p], p, 0, o->profile);
        if (mx_unet_forward(&c[p], u, &ui, out, &a, st)) return -1;
        clock_net(&nt_unet, &c[p], p, 1, o->profile);
        if (!cfg) continue;
        mx_unet_input ui_cfg = ui;
        ui_cfg.sample = sample_cfg, ui_cfg.timesteps = ts_cfg, ui_cfg.halves_equal = 1;
        clock_net(&nt_unet_cfg, &c[p], p, 0, o->profile);
        if (mx_unet_forward(&c[p], u, &ui_cfg, out, &a, st)) return -1;
        clock_net(&nt_unet_cfg, &c[p], p, 1, o->profile);
    }
    for (int p = 0; p < nprec && !o->skip_vae; p++) {
        clock_first_call(&nt_vae, &c[p], p, 0);
        if (mx_vae_decode(&c[p], v, sample, 1, H, W, img, &a, st)) return -1;
        clock_first_call(&nt_vae, &c[p], p, 1);
        clock_net(&nt_vae, &c[p], p, 0, o->profile);
        if (mx_vae_decode(&c[p], v, sample, 1, H, W, img, &a, st)) return -1;
        clock_net(&nt_vae, &c[p], p, 1, o->profile);
    }
    double peak_after[2] = {bench_peak_gflops(&c[0], 0), nprec == 2 ? bench_peak_gflops(&c[1], 1) : 0};
    for (int p = 0; p < 2; p++) peak[p] = peak[p] > peak_after[p] ? peak[p] : peak_after[p];
    printf("measured peak of %d threads (best short run of zmm FMA / %s loops, before and after): "
           "fp32 %.0f GFLOP/s, bf16 %.0f GFLOP/s\n", mx_pool_threads(c[0].pool),
           nprec == 2 && c[1].k->isa == MX_ISA_AMX ? "TDPBF16PS" : "vdpbf16ps", peak[0], peak[1]);
    if (bw > 0) printf("memory bandwidth of %d threads (y = x + 1 over 32 MiB, 8 bytes per element, best of 7): %.1f GB/s\n",
                       mx_pool_threads(c[0].pool), bw);
    int nth = mx_pool_threads(c[0].pool);
    printf("%-32s %6s %7s %7s %5s %7s %7s %5s %6s %6s\n", "network (GFLOP/s over CPU time)", "GFLOP", "fp32 s",
           "GFLOP/s", "peak", "bf16 s", "GFLOP/s", "peak", "wall", "cpu");
    if (!o->skip_cn) report(&nt_cn, peak, nth);
    if (!o->skip_cn) report(&nt_cn_step, peak, nth);
    if (!o->skip_unet) report(&nt_unet, peak, nth);
    if (!o->skip_unet && cfg) report(&nt_unet_cfg, peak, nth);
    if (!o->skip_vae) report(&nt_vae, peak, nth);
    report_first_calls((const net_time *[]){o->skip_cn ? NULL : &nt_cn, o->skip_unet ? NULL : &nt_unet,
                                            o->skip_vae ? NULL : &nt_vae}, c, nprec);
    if (o->profile) {
        printf("where the time went (shares of each call's CPU time, all threads):\n");
        for (int p = 0; p < nprec; p++) {
            if (!o->skip_cn) report_profile(&nt_cn, p, peak[p], nth);
            if (!o->skip_cn) report_profile(&nt_cn_step, p, peak[p], nth);
            if (!o->skip_unet) report_profile(&nt_unet, p, peak[p], nth);
            if (!o->skip_unet && cfg) report_profile(&nt_unet_cfg, p, peak[p], nth);
            if (!o->skip_vae) report_profile(&nt_vae, p, peak[p], nth);
        }
    }
    {
        int32_t ids[2 * 77];
        for (int i = 0; i < 2 * 77; i++) ids[i] = i % 77 == 0 ? 49406 : i % 77 < 9 ? 320 + i % 77 : 49407;
        size_t nt = (size_t)2 * 77 * tcfg.hidden_size;
        float *last = malloc(nt * sizeof *last), *pooled = malloc((size_t)2 * tcfg.hidden_size * sizeof *pooled);
        mx_arena dry, ca;
        mx_arena_measure(&dry);
        if (mx_clip_forward(clip, &c[0], &dry, ids, 2, 77, last, pooled, NULL, st) ||
            mx_arena_create(&ca, dry.peak + 256, st))
            return -1;
        for (int call = 0; call < 2; call++) { /* the first untimed, as above */
            t0 = mx_now();
            if (mx_clip_forward(clip, &c[0], &ca, ids, 2, 77, last, pooled, NULL, st)) return -1;
        }
        printf("%-32s %8.2f s (fp32)\n", "CLIP text encoder batch 2", mx_now() - t0);
        mx_arena_destroy(&ca);
        free(last);
        free(pooled);
    }
    printf("bench-nets-summary: unet_fp32_s=%.2f unet_bf16_s=%.2f unet_bf16_speedup_wall=%.2f "
           "unet_bf16_speedup_cpu=%.2f peak_fp32_gflops=%.0f peak_bf16_gflops=%.0f\n",
           nt_unet.secs[0], nt_unet.secs[1], nt_unet.secs[1] > 0 ? nt_unet.secs[0] / nt_unet.secs[1] : 0,
           nt_unet.cpu[1] > 0 ? nt_unet.cpu[0] / nt_unet.cpu[1] : 0, peak[0], peak[1]);
    free(img);
    printf("%-34s %8.0f MB\n", "peak RSS", peak_rss_mb());
    for (int i = 0; i <= nres; i++) free(res[i]);
    free(cond);
    free(sample);
    free(sample_cfg);
    free(ehs);
    free(out);
    mx_arena_destroy(&a);
    for (int p = 0; p < nprec; p++) mx_ctx_destroy(&c[p]);
    mx_unet_free(u);
    mx_controlnet_free(cn[0]);
    mx_controlnet_free(cn[1]);
    mx_vae_free(v);
    mx_clip_free(clip);
    mx_binder_free(&bu);
    mx_binder_free(&bc[0]);
    mx_binder_free(&bc[1]);
    mx_binder_free(&bv);
    mx_binder_free(&bt);
    mx_wf_close(wf);
    return 0;
}

int main(int argc, char **argv) {
    char cached[1100];
    bench_opts o = {.profile = 1, .batch = 2};
    setvbuf(stdout, NULL, _IOLBF, 0); /* progress lines show up as they happen */
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--threads") && i + 1 < argc) o.threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--weights") && i + 1 < argc) o.weights = argv[++i];
        else if (!strcmp(argv[i], "--skip-vae")) o.skip_vae = 1;
        else if (!strcmp(argv[i], "--skip-controlnet")) o.skip_cn = 1;
        else if (!strcmp(argv[i], "--skip-unet")) o.skip_unet = 1;
        else if (!strcmp(argv[i], "--no-profile")) o.profile = 0;
        else if (!strcmp(argv[i], "--batch") && i + 1 < argc && (o.batch = atoi(argv[++i])) >= 1 && o.batch <= 2) continue;
        else {
            fprintf(stderr, "usage: bench_nets [--threads N] [--weights PATH] [--skip-vae] [--skip-controlnet] "
                            "[--skip-unet] [--no-profile] [--batch 1|2]\n");
            return 2;
        }
    }
    if (!o.weights && bench_sd15_weights(cached, sizeof cached) == 0) o.weights = cached;
    if (!o.weights) {
        fprintf(stderr, "bench_nets: could not make the SD1.5 weight file %s\n", cached);
        return 1;
    }
    mx_status st;
    mx_status_clear(&st);
    if (run_benchmarks(&o, &st)) {
        fprintf(stderr, "bench_nets: %s\n", st.msg);
        return 1;
    }
    return 0;
}
