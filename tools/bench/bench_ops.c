/* bench_ops: matex's GEMM and 3×3 conv against OpenBLAS (cblas_sgemm; conv anchor = im2col +
 * sgemm) on the SD1.5 UNet shapes at a 64×64 latent, same thread count for both, plus
 * attention at 4096 tokens × 8 heads × 40 dims. Where the CPU has AVX512_BF16 the bf16 kernels
 * run too, interleaved with the fp32 ones and OpenBLAS, so their ratios come from one run.
 * Usage: bench_ops [--threads N] [--repeats R] [--attention-only]. */
#include <cblas.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../ops/ops.h"
#include "../../runtime/log.h"

void openblas_set_num_threads(int num_threads);
char *openblas_get_corename(void);

typedef struct {
    int M, N, K;
} gemm_shape;

typedef struct {
    int C, H, W;
} conv_shape;

static const gemm_shape gemm_shapes[] = {
    {4096, 320, 320}, {4096, 2560, 320}, {4096, 320, 1280}, {1024, 640, 5120}, {77, 768, 768},
};
static const conv_shape conv_shapes[] = {{320, 64, 64}, {640, 32, 32}, {1280, 16, 16}};

static float *random_floats(size_t n, unsigned seed) {
    float *x = malloc(n * sizeof *x);
    if (!x) {
        fprintf(stderr, "bench_ops: out of memory (%zu floats)\n", n);
        exit(1);
    }
    unsigned s = seed * 2654435761u + 1;
    for (size_t i = 0; i < n; i++) {
        s = s * 1664525u + 1013904223u;
        x[i] = (float)(s >> 8) / 16777216.0f - 0.5f;
    }
    return x;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *t, int n) {
    qsort(t, (size_t)n, sizeof *t, cmp_double);
    return n % 2 ? t[n / 2] : 0.5 * (t[n / 2 - 1] + t[n / 2]);
}

typedef struct {
    const mx_ctx *ctx; /* the side being timed: fp32 or bf16 kernels */
    const mx_ctx *fp32, *bf16; /* bf16 NULL when the CPU has no bf16 arithmetic */
    const gemm_shape *s;
    const conv_shape *cs;
    float *x, *w, *y, *col;
} bench_args;

typedef void (*bench_fn)(void *arg);

/* One timed side: a function and the context it runs with. */
typedef struct {
    bench_fn fn;
    const mx_ctx *ctx;
} side;

static double process_cpu_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Median wall seconds (med) and process CPU seconds (cpu, may be NULL) of `repeats` runs of each
 * side after one warm-up run each; the sides run in turn, so a change in machine load hits all
 * of them alike. On a shared machine CPU time is the steadier measure for matex (its idle
 * workers sleep), not for OpenBLAS (its idle workers spin). */
static void time_sides(const side *sides, int n, bench_args *a, int repeats, double *med, double *cpu) {
    double t[4][64], c[4][64];
    if (repeats > 64) repeats = 64;
    for (int i = 0; i < n; i++) a->ctx = sides[i].ctx, sides[i].fn(a);
    for (int r = 0; r < repeats; r++)
        for (int i = 0; i < n; i++) {
            a->ctx = sides[i].ctx;
            double s = mx_now(), sc = process_cpu_seconds();
            sides[i].fn(a);
            t[i][r] = mx_now() - s;
            c[i][r] = process_cpu_seconds() - sc;
        }
    for (int i = 0; i < n; i++) {
        med[i] = median(t[i], repeats);
        if (cpu) cpu[i] = median(c[i], repeats);
    }
}

static void run_matex_gemm(void *arg) {
    bench_args *a = arg;
    mx_linear(a->ctx, a->y, a->x, mx_w_f32(a->w), mx_w_none(), a->s->M, a->s->N, a->s->K);
}

static void run_blas_gemm(void *arg) {
    bench_args *a = arg;
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, a->s->M, a->s->N, a->s->K, 1.0f, a->x, a->s->K, a->w,
                a->s->K, 0.0f, a->y, a->s->N);
}

static void run_matex_conv(void *arg) {
    bench_args *a = arg;
    const conv_shape *c = a->cs;
    mx_conv2d(a->ctx, a->y, a->x, 1, c->C, c->H, c->W, mx_w_f32(a->w), mx_w_none(), c->C, 3, 3, 1, 1);
}

/* The usual anchor: a full im2col copy (3×3, stride 1, pad 1), then one sgemm. */
static void run_blas_conv(void *arg) {
    bench_args *a = arg;
    const conv_shape *c = a->cs;
    int HW = c->H * c->W;
    for (int ci = 0; ci < c->C; ci++)
        for (int t = 0; t < 9; t++) {
            int ky = t / 3, kx = t % 3;
            float *dst = a->col + ((size_t)ci * 9 + t) * HW;
            for (int oy = 0; oy < c->H; oy++)
                for (int ox = 0; ox < c->W; ox++) {
                    int iy = oy + ky - 1, ix = ox + kx - 1;
                    int in = iy >= 0 && iy < c->H && ix >= 0 && ix < c->W;
                    dst[oy * c->W + ox] = in ? a->x[((size_t)ci * c->H + iy) * c->W + ix] : 0.0f;
                }
        }
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, c->C, HW, c->C * 9, 1.0f, a->w, c->C * 9, a->col, HW,
                0.0f, a->y, HW);
}

static void run_attention(void *arg) {
    bench_args *a = arg;
    /* q = x, k = w, v = col: [4096, 320] each, 8 heads of 40 */
    mx_attention(a->ctx, a->y, a->x, a->w, a->col, 1, 8, 4096, 4096, 40, 320, 320, 320, 0, 0.15811388f);
}

/* One line of GFLOP/s (wall): matex fp32, OpenBLAS, their ratio, and matex bf16 with its speed-up
 * over matex fp32 in wall and in CPU time ("-" without bf16). Returns the fp32/OpenBLAS ratio;
 * *bf16_ratio the bf16 speed-up in CPU time. */
static double report_line(const char *name, double flop, bench_args *a, bench_fn matex, bench_fn blas, int repeats,
                          double *bf16_ratio) {
    side sides[3] = {{matex, a->fp32}, {blas, NULL}, {matex, a->bf16}};
    double t[3], cpu[3];
    time_sides(sides, a->bf16 ? 3 : 2, a, repeats, t, cpu);
    double gm = flop / t[0] * 1e-9, gb = flop / t[1] * 1e-9;
    printf("%-28s %10.1f %10.1f %7.3f", name, gm, gb, gm / gb);
    if (a->bf16)
        printf(" %10.1f %7.3f %7.3f   GFLOP/s\n", flop / t[2] * 1e-9, t[0] / t[2], cpu[0] / cpu[2]);
    else
        printf(" %10s %7s %7s   GFLOP/s\n", "-", "-", "-");
    *bf16_ratio = a->bf16 ? cpu[0] / cpu[2] : 0;
    return gm / gb;
}

static void print_header(const char *what) {
    printf("%-28s %10s %10s %7s %10s %7s %7s\n", what, "fp32", "openblas", "ratio", "bf16", "bf/fp", "(cpu)");
}

/* Worst matex fp32 / OpenBLAS ratio over the shapes; *bf16_min the worst bf16 / fp32 ratio. */
static double bench_gemms(bench_args *base, int repeats, double *bf16_min) {
    double worst = 1e30;
    *bf16_min = 1e30;
    print_header("gemm M N K");
    for (size_t i = 0; i < sizeof gemm_shapes / sizeof gemm_shapes[0]; i++) {
        const gemm_shape *s = &gemm_shapes[i];
        bench_args a = *base;
        a.s = s;
        a.x = random_floats((size_t)s->M * s->K, 1), a.w = random_floats((size_t)s->N * s->K, 2);
        a.y = random_floats((size_t)s->M * s->N, 3);
        char name[64];
        snprintf(name, sizeof name, "%d %d %d", s->M, s->N, s->K);
        double bf, r = report_line(name, 2.0 * s->M * s->N * s->K, &a, run_matex_gemm, run_blas_gemm, repeats, &bf);
        if (r < worst) worst = r;
        if (bf < *bf16_min) *bf16_min = bf;
        free(a.x), free(a.w), free(a.y);
    }
    return worst;
}

static double bench_convs(bench_args *base, int repeats, double *bf16_min) {
    double worst = 1e30;
    *bf16_min = 1e30;
    print_header("conv3x3 HxWxC (Cin=Cout)");
    for (size_t i = 0; i < sizeof conv_shapes / sizeof conv_shapes[0]; i++) {
        const conv_shape *c = &conv_shapes[i];
        size_t HW = (size_t)c->H * c->W;
        bench_args a = *base;
        a.cs = c;
        a.x = random_floats(c->C * HW, 4), a.w = random_floats((size_t)c->C * c->C * 9, 5);
        a.y = random_floats(c->C * HW, 6), a.col = random_floats((size_t)c->C * 9 * HW, 7);
        char name[64];
        snprintf(name, sizeof name, "%dx%dx%d", c->H, c->W, c->C);
        double bf, r = report_line(name, 2.0 * c->C * HW * c->C * 9, &a, run_matex_conv, run_blas_conv, repeats, &bf);
        if (r < worst) worst = r;
        if (bf < *bf16_min) *bf16_min = bf;
        free(a.x), free(a.w), free(a.y), free(a.col);
    }
    return worst;
}

/* Attention with the fp32 kernel and (interleaved) the bf16 one: ms[0], ms[1] (0 without bf16). */
static void bench_attention(bench_args *base, int repeats, double ms[2]) {
    size_t n = (size_t)4096 * 320;
    bench_args a = *base;
    a.x = random_floats(n, 8), a.w = random_floats(n, 9), a.y = random_floats(n, 10), a.col = random_floats(n, 11);
    side sides[2] = {{run_attention, a.fp32}, {run_attention, a.bf16}};
    double cpu[2];
    time_sides(sides, a.bf16 ? 2 : 1, &a, repeats, ms, cpu);
    ms[0] *= 1e3;
    ms[1] = a.bf16 ? ms[1] * 1e3 : 0;
    /* 4·T²·D multiply-adds per head: q·k and p·v; CPU time per thread gives the rate on cores of
     * its own */
    double gflop = 4.0 * 4096 * 4096 * 40 * 8 * 1e-9, nth = mx_pool_threads(a.fp32->pool);
    printf("attention 4096x4096 tokens, 8 heads x 40: fp32 %.1f ms wall, %.0f GFLOP/s over CPU time", ms[0],
           gflop / (cpu[0] / nth));
    if (a.bf16)
        printf("; bf16 %.1f ms wall, %.0f GFLOP/s over CPU time; bf16/fp32 speed-up %.2fx wall, %.2fx CPU\n", ms[1],
               gflop / (cpu[1] / nth), ms[0] / ms[1], cpu[0] / cpu[1]);
    else
        printf("; bf16 not available on this CPU\n");
    free(a.x), free(a.w), free(a.y), free(a.col);
}

int main(int argc, char **argv) {
    int threads = 2, repeats = 5, attention_only = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--attention-only"))
            attention_only = 1;
        else if (!strcmp(argv[i], "--threads") && i + 1 < argc)
            threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--repeats") && i + 1 < argc)
            repeats = atoi(argv[++i]);
        else {
            fprintf(stderr, "usage: bench_ops [--threads N] [--repeats R] [--attention-only]\n");
            return 2;
        }
    }
    if (threads < 1 || repeats < 1) {
        fprintf(stderr, "bench_ops: --threads and --repeats must be >= 1\n");
        return 2;
    }
    mx_ctx fp32, bf16;
    mx_status st;
    mx_isa bf16_isa = mx_cpu_isa_for(MX_PREC_BF16);
    int has_bf16 = mx_isa_precision(bf16_isa) == MX_PREC_BF16;
    if (mx_ctx_create(&fp32, threads, mx_cpu_isa_for(MX_PREC_FP32), (size_t)64 << 20, &st) != 0 ||
        (has_bf16 && mx_ctx_create(&bf16, threads, bf16_isa, (size_t)64 << 20, &st) != 0)) {
        fprintf(stderr, "bench_ops: %s\n", st.msg);
        return 1;
    }
    openblas_set_num_threads(threads);
    printf("bench_ops: %d threads, kernels %s and %s, median of %d; OpenBLAS kernels: %s\n", threads,
           mx_isa_name(fp32.k->isa), has_bf16 ? mx_isa_name(bf16.k->isa) : "(no bf16)", repeats,
           openblas_get_corename());
    bench_args base = {NULL, &fp32, has_bf16 ? &bf16 : NULL, NULL, NULL, NULL, NULL, NULL, NULL};
    double gb = 0, cb = 0, g = 0, c = 0, ms[2];
    if (!attention_only) {
        g = bench_gemms(&base, repeats, &gb);
        c = bench_convs(&base, repeats, &cb);
    }
    bench_attention(&base, attention_only ? repeats : repeats < 3 ? repeats : 3, ms);
    if (!attention_only) {
        printf("bench-summary: gemm_ratio_min=%.3f conv_ratio_min=%.3f attention_ms=%.1f", g, c, ms[0]);
        if (has_bf16)
            printf(" bf16_gemm_speedup_min=%.3f bf16_conv_speedup_min=%.3f attention_bf16_ms=%.1f\n", gb, cb, ms[1]);
        else
            printf(" bf16=na\n");
    }
    mx_ctx_destroy(&fp32);
    if (has_bf16) mx_ctx_destroy(&bf16);
    return 0;
}
