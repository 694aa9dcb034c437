/* Shared by the benchmarks that need the SD1.5-architecture model set: the cached weight file
 * (random golden-v1 rule weights, fp16, with tokenizer and both ControlNets; made once by
 * tools/scripts/make_sd15_weights.sh, ~3.6 GB, about a minute) and the peak arithmetic rate of the cores.
 * The cache lives outside the repository: $MATEX_CACHE, else $HOME/.cache/matex. Header-only
 * (each benchmark is one program). */
#ifndef MX_BENCH_SD15_H
#define MX_BENCH_SD15_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../../ops/ops.h"
#include "../../runtime/log.h"

/* n floats uniform in [lo, hi) from a fixed LCG (malloc'd; NULL when out of memory): the
 * benchmarks' inputs, the same for a seed on every run. */
static inline float *bench_filled(size_t n, float lo, float hi, unsigned seed) {
    float *x = malloc(n * sizeof *x);
    unsigned s = seed * 2654435761u + 7;
    for (size_t i = 0; x && i < n; i++) {
        s = s * 1664525u + 1013904223u;
        x[i] = lo + (hi - lo) * (float)(s >> 8) / 16777216.0f;
    }
    return x;
}

/* The weight file's path into buf; makes the file when absent. Returns -1 when it cannot. fast: the
 * file of `texture --fast` (the same plus a random LCM-LoRA merged and a random TAESD). */
static inline int bench_sd15_file(char *buf, size_t cap, int fast) {
    const char *dir = getenv("MATEX_CACHE"), *home = getenv("HOME");
    char d[1024];
    if (dir && *dir)
        snprintf(d, sizeof d, "%s", dir);
    else
        snprintf(d, sizeof d, "%s/.cache/matex", home && *home ? home : "/tmp");
    snprintf(buf, cap, fast ? "%s/sd15_random_f16_fast.mxw" : "%s/sd15_random_f16.mxw", d);
    if (access(buf, R_OK) == 0) return 0;
    char cmd[3072];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s' && sh tools/scripts/make_sd15_weights.sh '%s' '%s'%s", d,
             getenv("MATEX") ? getenv("MATEX") : "./matex", buf, fast ? " --fast" : "");
    fprintf(stderr, "bench: making %s (once, ~3.6 GB, about a minute)\n", buf);
    return system(cmd) == 0 ? 0 : -1;
}

static inline int bench_sd15_weights(char *buf, size_t cap) { return bench_sd15_file(buf, cap, 0); }

static inline double bench_file_mb(const char *path) {
    struct stat sb;
    return stat(path, &sb) == 0 ? (double)sb.st_size / (1 << 20) : 0;
}

/* ---- peak arithmetic rate: independent accumulator chains, one task per pool thread ---- */

#define PEAK_CHAINS 12
#define PEAK_ITERS 1000000
#define PEAK_RUNS 7

#if defined(__x86_64__) && !defined(MX_NO_X86_SIMD)
#include <immintrin.h>

__attribute__((target("avx512f"))) static inline float peak_fma_loop(void) {
    __m512 acc[PEAK_CHAINS], a = _mm512_set1_ps(0.999999f), b = _mm512_set1_ps(1e-7f);
    for (int i = 0; i < PEAK_CHAINS; i++) acc[i] = _mm512_set1_ps((float)i);
    for (int it = 0; it < PEAK_ITERS; it++) /* unrolled: the accumulators stay in registers */
        _Pragma("GCC unroll 16") for (int i = 0; i < PEAK_CHAINS; i++) acc[i] = _mm512_fmadd_ps(acc[i], a, b);
    float s = 0;
    for (int i = 0; i < PEAK_CHAINS; i++) s += _mm512_reduce_add_ps(acc[i]);
    return s;
}

__attribute__((target("avx512f,avx512bf16"))) static inline float peak_dpbf16_loop(void) {
    __m512 acc[PEAK_CHAINS];
    __m512bh a = (__m512bh)_mm512_set1_epi32(0x3f803f80), b = (__m512bh)_mm512_set1_epi32(0x33d633d6);
    for (int i = 0; i < PEAK_CHAINS; i++) acc[i] = _mm512_set1_ps((float)i);
    for (int it = 0; it < PEAK_ITERS; it++)
        _Pragma("GCC unroll 16") for (int i = 0; i < PEAK_CHAINS; i++) acc[i] = _mm512_dpbf16_ps(acc[i], a, b);
    float s = 0;
    for (int i = 0; i < PEAK_CHAINS; i++) s += _mm512_reduce_add_ps(acc[i]);
    return s;
}

/* TDPBF16PS on tiles that stay in the TMUL: 4 accumulators of 16×16 fp32, 2 + 2 operand tiles of
 * 16 × 32 bf16 (zeros), the 2×2 blocking of the AMX GEMM; 16·16·32 multiply-adds each. */
#define PEAK_AMX_ITERS (PEAK_ITERS / 8)

__attribute__((target("amx-tile,amx-bf16"))) static inline float peak_amx_loop(void) {
    struct {
        unsigned char palette, start_row, reserved[14];
        unsigned short colsb[16];
        unsigned char rows[16];
    } cfg = {1, 0, {0}, {0}, {0}};
    static const float zeros[16 * 16];
    for (int t = 0; t < 8; t++) cfg.colsb[t] = 64, cfg.rows[t] = 16;
    __asm__ volatile("" : : "m"(cfg) : "memory"); /* GCC 12 does not see the config read: store it first */
    _tile_loadconfig(&cfg);
    _tile_zero(0);
    _tile_zero(1);
    _tile_zero(2);
    _tile_zero(3);
    _tile_loadd(4, zeros, 64);
    _tile_loadd(5, zeros, 64);
    _tile_loadd(6, zeros, 64);
    _tile_loadd(7, zeros, 64);
    for (int it = 0; it < PEAK_AMX_ITERS; it++) {
        _tile_dpbf16ps(0, 4, 6);
        _tile_dpbf16ps(1, 4, 7);
        _tile_dpbf16ps(2, 5, 6);
        _tile_dpbf16ps(3, 5, 7);
    }
    float out[16 * 16];
    _tile_stored(0, out, 64);
    _tile_release();
    return out[0];
}

/* CPU seconds of the calling thread, or of the whole process: on a shared machine the time a
 * computation really had the cores, where wall time also counts other people's work. */
static inline double bench_cpu_seconds(clockid_t which) {
    struct timespec ts;
    clock_gettime(which, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#define PEAK_MAX_THREADS 256

typedef enum { PEAK_FP32, PEAK_DPBF16, PEAK_AMX } peak_loop;

typedef struct {
    peak_loop loop;
    volatile float sink;
    double secs[PEAK_MAX_THREADS]; /* CPU seconds of each thread's loop */
} peak_job;

static inline void peak_task(void *arg, int task, int thread) {
    (void)task;
    peak_job *j = arg;
    double t0 = bench_cpu_seconds(CLOCK_THREAD_CPUTIME_ID);
    j->sink = j->loop == PEAK_AMX ? peak_amx_loop() : j->loop == PEAK_DPBF16 ? peak_dpbf16_loop() : peak_fma_loop();
    if (thread < PEAK_MAX_THREADS) j->secs[thread] = bench_cpu_seconds(CLOCK_THREAD_CPUTIME_ID) - t0;
}

/* Peak GFLOP/s of the pool's threads on cores of their own, for the level of c's kernels: zmm FMAs
 * (16 multiply-adds per instruction) for fp32, vdpbf16ps (32) for bf16, TDPBF16PS (8192) for
 * bf16 on the amx level; each thread's rate over its own CPU time (so other people's load on a
 * shared machine does not count), summed; the best of PEAK_RUNS runs. 0 when the CPU lacks the
 * instructions. */
static inline double bench_peak_gflops(const mx_ctx *c, int bf16) {
    mx_isa need = bf16 ? MX_ISA_AVX512_BF16 : MX_ISA_AVX512;
    if (mx_cpu_best_isa() < need) return 0;
    peak_loop loop = !bf16 ? PEAK_FP32 : c->k->isa == MX_ISA_AMX ? PEAK_AMX : PEAK_DPBF16;
    int n = mx_pool_threads(c->pool);
    if (n > PEAK_MAX_THREADS) n = PEAK_MAX_THREADS;
    double flop = loop == PEAK_AMX ? 2.0 * 16 * 16 * 32 * 4 * (double)PEAK_AMX_ITERS
                                   : 2.0 * (bf16 ? 32 : 16) * PEAK_CHAINS * (double)PEAK_ITERS;
    double best = 0;
    for (int r = 0; r < PEAK_RUNS; r++) {
        peak_job j = {loop, 0, {0}};
        mx_pool_for(c->pool, n, peak_task, &j);
        double g = 0;
        for (int t = 0; t < n; t++) g += j.secs[t] > 0 ? flop / j.secs[t] * 1e-9 : 0;
        if (g > best) best = g;
    }
    return best;
}
#else
static inline double bench_peak_gflops(const mx_ctx *c, int bf16) {
    (void)c, (void)bf16;
    return 0;
}
#endif

/* ---- memory bandwidth: y = x + 1 over two buffers of the size of the networks' activations ----
 * (an SD1.5 UNet's at 64×64 are 10-84 MB). Where the last-level cache holds them (a 480 MiB L3 on
 * the Xeons here: 42-64 GB/s on 2 threads at 4-64 MiB, against 20-29 GB/s at 256 MiB), so do the
 * ops' own, and a floor must not assume less. Measured before the peak loops: after them the
 * same loop ran at 34 instead of 45 GB/s. */

#define BW_FLOATS ((size_t)8 << 20) /* 32 MiB per buffer */
#define BW_RUNS 7

typedef struct {
    const float *x;
    float *y;
    size_t per_task;
} bw_job;

static inline void bw_task(void *arg, int task, int thread) {
    (void)thread;
    const bw_job *j = arg;
    size_t i0 = (size_t)task * j->per_task, i1 = i0 + j->per_task < BW_FLOATS ? i0 + j->per_task : BW_FLOATS;
    const float *restrict x = j->x;
    float *restrict y = j->y;
    for (size_t i = i0; i < i1; i++) y[i] = x[i] + 1.0f;
}

/* GB/s of the pool's threads streaming one buffer into another, counting 8 bytes per element
 * (what an op's cost counts: each input read once, each output written once; the stores' reads
 * of their lines are part of what this measures, as they are of every op); wall time, the best
 * of BW_RUNS (the first run brings the buffers into the cache where they fit). 0 when out of
 * memory. */
static inline double bench_bandwidth_gbs(const mx_ctx *c) {
    float *x = malloc(BW_FLOATS * sizeof *x), *y = malloc(BW_FLOATS * sizeof *y);
    double best = 0;
    if (x && y) {
        int n = mx_pool_threads(c->pool);
        bw_job j = {x, y, (BW_FLOATS + (size_t)n - 1) / (size_t)n};
        memset(x, 0, BW_FLOATS * sizeof *x);
        memset(y, 0, BW_FLOATS * sizeof *y);
        for (int r = 0; r < BW_RUNS; r++) {
            double t0 = mx_now();
            mx_pool_for(c->pool, n, bw_task, &j);
            double g = 8.0 * BW_FLOATS / (mx_now() - t0) * 1e-9;
            if (g > best) best = g;
        }
    }
    free(x);
    free(y);
    return best;
}

#endif
