/* bench_ops: matex's GEMM and 3×3 conv against OpenBLAS (cblas_sgemm; conv anchor = im2col +
 * sgemm) on the SD1.5 UNet shapes at a 64×64 latent, same thread count for both, plus
 * attention at 4096 tokens × 8 heads × 40 dims. Usage: bench_ops [--threads N] [--repeats R]. */
#include <cblas.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/ops.h"
#include "../runtime/log.h"

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

typedef void (*bench_fn)(void *arg);

/* Median seconds of `repeats` runs of each of two functions after one warm-up run each; the
 * runs alternate, so a change in machine load hits both sides alike. */
static void time_pair(bench_fn f0, bench_fn f1, void *arg, int repeats, double *t0_med, double *t1_med) {
    double t0[64], t1[64];
    if (repeats > 64) repeats = 64;
    f0(arg);
    f1(arg);
    for (int r = 0; r < repeats; r++) {
        double s = mx_now();
        f0(arg);
        double m = mx_now();
        f1(arg);
        t0[r] = m - s;
        t1[r] = mx_now() - m;
    }
    *t0_med = median(t0, repeats);
    *t1_med = median(t1, repeats);
}

static double time_median(bench_fn fn, void *arg, int repeats) {
    double t, unused;
    time_pair(fn, fn, arg, repeats, &t, &unused);
    return t;
}

typedef struct {
    const mx_ctx *ctx;
    const gemm_shape *s;
    const conv_shape *cs;
    float *x, *w, *y, *col;
} bench_args;

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

static double bench_gemms(const mx_ctx *ctx, int repeats) {
    double worst = 1e30;
    printf("%-28s %10s %10s %7s\n", "gemm M N K", "matex", "openblas", "ratio");
    for (size_t i = 0; i < sizeof gemm_shapes / sizeof gemm_shapes[0]; i++) {
        const gemm_shape *s = &gemm_shapes[i];
        bench_args a = {ctx, s, NULL, random_floats((size_t)s->M * s->K, 1), random_floats((size_t)s->N * s->K, 2),
                        random_floats((size_t)s->M * s->N, 3), NULL};
        double flop = 2.0 * s->M * s->N * s->K;
        double tm, tb;
        time_pair(run_matex_gemm, run_blas_gemm, &a, repeats, &tm, &tb);
        double gm = flop / tm * 1e-9, gb = flop / tb * 1e-9;
        char name[64];
        snprintf(name, sizeof name, "%d %d %d", s->M, s->N, s->K);
        printf("%-28s %10.1f %10.1f %7.3f   GFLOP/s\n", name, gm, gb, gm / gb);
        if (gm / gb < worst) worst = gm / gb;
        free(a.x), free(a.w), free(a.y);
    }
    return worst;
}

static double bench_convs(const mx_ctx *ctx, int repeats) {
    double worst = 1e30;
    printf("%-28s %10s %10s %7s\n", "conv3x3 HxWxC (Cin=Cout)", "matex", "openblas", "ratio");
    for (size_t i = 0; i < sizeof conv_shapes / sizeof conv_shapes[0]; i++) {
        const conv_shape *c = &conv_shapes[i];
        size_t HW = (size_t)c->H * c->W;
        bench_args a = {ctx, NULL, c, random_floats(c->C * HW, 4), random_floats((size_t)c->C * c->C * 9, 5),
                        random_floats(c->C * HW, 6), random_floats((size_t)c->C * 9 * HW, 7)};
        double flop = 2.0 * c->C * HW * c->C * 9;
        double tm, tb;
        time_pair(run_matex_conv, run_blas_conv, &a, repeats, &tm, &tb);
        double gm = flop / tm * 1e-9, gb = flop / tb * 1e-9;
        char name[64];
        snprintf(name, sizeof name, "%dx%dx%d", c->H, c->W, c->C);
        printf("%-28s %10.1f %10.1f %7.3f   GFLOP/s\n", name, gm, gb, gm / gb);
        if (gm / gb < worst) worst = gm / gb;
        free(a.x), free(a.w), free(a.y), free(a.col);
    }
    return worst;
}

static double bench_attention(const mx_ctx *ctx, int repeats) {
    size_t n = (size_t)4096 * 320;
    bench_args a = {ctx, NULL, NULL, random_floats(n, 8), random_floats(n, 9), random_floats(n, 10),
                    random_floats(n, 11)};
    double ms = time_median(run_attention, &a, repeats) * 1e3;
    printf("attention 4096x4096 tokens, 8 heads x 40: %.1f ms\n", ms);
    free(a.x), free(a.w), free(a.y), free(a.col);
    return ms;
}

int main(int argc, char **argv) {
    int threads = 2, repeats = 5;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--threads") && i + 1 < argc)
            threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--repeats") && i + 1 < argc)
            repeats = atoi(argv[++i]);
        else {
            fprintf(stderr, "usage: bench_ops [--threads N] [--repeats R]\n");
            return 2;
        }
    }
    if (threads < 1 || repeats < 1) {
        fprintf(stderr, "bench_ops: --threads and --repeats must be >= 1\n");
        return 2;
    }
    mx_ctx ctx;
    mx_status st;
    if (mx_ctx_create(&ctx, threads, mx_cpu_best_isa(), (size_t)64 << 20, &st) != 0) {
        fprintf(stderr, "bench_ops: %s\n", st.msg);
        return 1;
    }
    openblas_set_num_threads(threads);
    printf("bench_ops: %d threads, kernels %s, median of %d; OpenBLAS kernels: %s\n", threads, mx_isa_name(ctx.k->isa),
           repeats, openblas_get_corename());
    double g = bench_gemms(&ctx, repeats);
    double c = bench_convs(&ctx, repeats);
    double ms = bench_attention(&ctx, repeats < 3 ? repeats : 3);
    printf("bench-summary: gemm_ratio_min=%.3f conv_ratio_min=%.3f attention_ms=%.1f\n", g, c, ms);
    mx_ctx_destroy(&ctx);
    return 0;
}
