/* matex bench: times matex's own kernels (GEMM, 3×3 conv, the upsamplers' conv, attention) on the
 * SD1.5 UNet shapes at a 64×64 latent and prints GFLOP/s (no OpenBLAS; tools/bench/bench_ops.c
 * compares with it). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../ops/ops.h"
#include "../../runtime/log.h"
#include "cli.h"
#include "cli_args.h"

typedef struct {
    const char *name;
    /* 0 linear M N K, 1 conv3x3 C H W, 2 attention T heads D; an upsampler's 3×3 conv on the 2×
     * upsample of C H W: 3 as the upsample then conv2d, 4 as conv2d_up2x (both in GFLOP/s of the
     * 3×3 conv at 2H×2W, so their times compare) */
    int kind;
    int a, b, c;
} bench_case;

static const bench_case cases[] = {
    {"gemm 4096x320x320", 0, 4096, 320, 320},     {"gemm 4096x2560x320", 0, 4096, 2560, 320},
    {"gemm 4096x320x1280", 0, 4096, 320, 1280},   {"gemm 1024x640x5120", 0, 1024, 640, 5120},
    {"gemm 77x768x768", 0, 77, 768, 768},         {"conv3x3 64x64x320", 1, 320, 64, 64},
    {"conv3x3 32x32x640", 1, 640, 32, 32},        {"conv3x3 16x16x1280", 1, 1280, 16, 16},
    {"upsample+conv3x3 16x16x1280", 3, 1280, 16, 16}, {"conv2d_up2x 16x16x1280", 4, 1280, 16, 16},
    {"upsample+conv3x3 32x32x640", 3, 640, 32, 32}, {"conv2d_up2x 32x32x640", 4, 640, 32, 32},
    {"attention 4096 tok 8x40", 2, 4096, 8, 40},
};

static void usage(FILE *f) {
    fprintf(f, "usage: matex bench [--threads N] [--repeats R] [--precision fp32|bf16] [--json]\n"
               "Times matex's GEMM, 3x3 conv, upsampler conv (upsample then conv, and conv2d_up2x;\n"
               "both in GFLOP/s of the 3x3 conv on the upsampled input) and attention kernels on the\n"
               "SD1.5 UNet shapes at a 64x64 latent and prints GFLOP/s (median of R runs after a\n"
               "warm-up; default R=5).\n"
               "  --threads N   worker threads (default: all CPUs)\n"
               "  --precision P fp32 (default) or bf16 kernels (bf16 needs AVX512_BF16)\n"
               "  --json        one JSON object on stdout instead of the table\n"
               "MATEX_ISA=");
    /* the levels from the code's own table (runtime/backend.h), not a copy of it */
    for (int i = 0; i < MX_ISA_COUNT; i++) fprintf(f, "%s%s", i ? "|" : "", mx_isa_name((mx_isa)i));
    fprintf(f, " lowers the kernel level (`matex --version` shows the one used).\n");
}

static double flops_of(const bench_case *b) {
    if (b->kind == 0) return 2.0 * b->a * b->b * b->c;
    if (b->kind == 1) return 2.0 * b->a * b->a * 9.0 * b->b * b->c;
    if (b->kind >= 3) return 2.0 * b->a * b->a * 9.0 * 4.0 * b->b * b->c;
    return 4.0 * b->a * (double)b->a * b->b * b->c; /* QK^T and PV */
}

/* Buffer sizes (floats) for x, w and y of a case. */
static void sizes_of(const bench_case *b, size_t n[3]) {
    if (b->kind == 0) {
        n[0] = (size_t)b->a * b->c, n[1] = (size_t)b->b * b->c, n[2] = (size_t)b->a * b->b;
    } else if (b->kind == 1) {
        n[0] = n[2] = (size_t)b->a * b->b * b->c, n[1] = (size_t)b->a * b->a * 9;
    } else if (b->kind >= 3) { /* x, then (kind 3) the upsampled x */
        n[2] = (size_t)b->a * 4 * b->b * b->c, n[0] = (size_t)b->a * b->b * b->c + (b->kind == 3 ? n[2] : 0);
        n[1] = (size_t)b->a * b->a * 9;
    } else {
        n[0] = n[2] = (size_t)b->a * b->b * b->c, n[1] = 2 * n[0]; /* k and v */
    }
}

static void run_case(const mx_ctx *c, const bench_case *b, float *x, float *w, float *y) {
    if (b->kind == 0)
        mx_linear(c, y, x, mx_w_f32(w), mx_w_none(), b->a, b->b, b->c);
    else if (b->kind == 1)
        mx_conv2d(c, y, x, 1, b->a, b->b, b->c, mx_w_f32(w), mx_w_none(), b->a, 3, 3, 1, 1);
    else if (b->kind == 3) {
        float *u = x + (size_t)b->a * b->b * b->c;
        mx_upsample_nearest2x(c, u, x, b->a, b->b, b->c);
        mx_conv2d(c, y, u, 1, b->a, 2 * b->b, 2 * b->c, mx_w_f32(w), mx_w_none(), b->a, 3, 3, 1, 1);
    } else if (b->kind == 4)
        mx_conv2d_up2x(c, y, x, 1, b->a, b->b, b->c, mx_w_f32(w), mx_w_none(), b->a);
    else {
        int C = b->b * b->c;
        mx_attention(c, y, x, w, w + (size_t)b->a * C, 1, b->b, b->a, b->a, b->c, C, C, C, 0, 0.158f);
    }
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median_seconds(const mx_ctx *c, const bench_case *b, float *x, float *w, float *y, int repeats) {
    double t[32];
    run_case(c, b, x, w, y); /* warm-up */
    for (int r = 0; r < repeats; r++) {
        double t0 = mx_now();
        run_case(c, b, x, w, y);
        t[r] = mx_now() - t0;
    }
    qsort(t, (size_t)repeats, sizeof *t, cmp_double);
    return t[repeats / 2];
}

int cmd_bench(int argc, char **argv) {
    int threads = 0, repeats = 5, json = 0;
    mx_precision prec = MX_PREC_FP32;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(argv[i], "--threads") && i + 1 < argc) {
            if (mx_arg_int("bench", "--threads", argv[++i], 1, 256, &threads)) return 2;
        } else if (!strcmp(argv[i], "--repeats") && i + 1 < argc) {
            if (mx_arg_int("bench", "--repeats", argv[++i], 1, 31, &repeats)) return 2;
        } else if (!strcmp(argv[i], "--precision") && i + 1 < argc) {
            if (mx_precision_parse(argv[++i], &prec)) {
                fprintf(stderr, "matex bench: --precision wants fp32 or bf16, got '%s'\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(argv[i], "--json"))
            json = 1;
        else {
            fprintf(stderr, "matex bench: unknown option '%s'\n", argv[i]);
            usage(stderr);
            return 2;
        }
    }
    mx_ctx ctx;
    mx_status st;
    if (mx_ctx_create(&ctx, threads, mx_cpu_isa_for(prec), (size_t)64 << 20, &st) != 0) {
        fprintf(stderr, "matex bench: %s\n", st.msg);
        return 1;
    }
    int nthreads = mx_pool_threads(ctx.pool), rc = 0;
    if (json)
        printf("{\"isa\": \"%s\", \"threads\": %d, \"results\": [", mx_isa_name(ctx.k->isa), nthreads);
    else
        printf("matex bench: kernels %s, %d threads, median of %d\n", mx_isa_name(ctx.k->isa), nthreads, repeats);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const bench_case *b = &cases[i];
        size_t n[3];
        sizes_of(b, n);
        float *buf[3];
        for (int j = 0; j < 3; j++) {
            buf[j] = malloc(n[j] * sizeof(float));
            if (buf[j]) memset(buf[j], 0, n[j] * sizeof(float));
            for (size_t e = 0; buf[j] && e < n[j]; e += 7) buf[j][e] = (float)(e % 13) * 0.01f;
        }
        if (!buf[0] || !buf[1] || !buf[2]) {
            fprintf(stderr, "matex bench: out of memory for %s\n", b->name);
            rc = 1;
        } else {
            double s = median_seconds(&ctx, b, buf[0], buf[1], buf[2], repeats), gf = flops_of(b) / s * 1e-9;
            if (json)
                printf("%s{\"name\": \"%s\", \"ms\": %.3f, \"gflops\": %.2f}", i ? ", " : "", b->name, s * 1e3, gf);
            else
                printf("%-26s %9.2f ms %9.1f GFLOP/s\n", b->name, s * 1e3, gf);
            fflush(stdout);
        }
        for (int j = 0; j < 3; j++) free(buf[j]);
        if (rc) break;
    }
    if (json) printf("]}\n");
    mx_ctx_destroy(&ctx);
    return rc;
}
