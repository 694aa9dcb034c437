/* Op tests: known answers for the scalar references, then every SIMD level this CPU has
 * against the scalar reference on random inputs of awkward sizes. A level the CPU lacks is
 * reported as not tested. The bf16 level (bf16 products, fp32 sums) is compared with the
 * reference run on the same inputs rounded to bf16, so the bound stays the fp32 one wherever
 * only the inputs are rounded. The AMX GEMM is also run on the software emulation of its tiles
 * (tests/amx_emu.c) wherever AVX512_BF16 is there, so its packing, tiling and edges are
 * tested on CPUs without AMX. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/ops.h"
#include "util_test.h"

static void test_known_linear(const mx_ctx *c) {
    const float x[2 * 3] = {1, 2, 3, -1, 0, 2};
    const float w[2 * 3] = {1, 0, 1, 0.5f, 0.5f, 0};
    const float b[2] = {10, -10};
    float y[4];
    mx_linear(c, y, x, mx_w_f32(w), mx_w_f32(b), 2, 2, 3);
    const float want[4] = {14, -8.5f, 11, -10.5f};
    mx_check_close("known linear 2x2x3", y, want, 4, 1e-7);
}

static void test_known_conversions(void) {
    CHECK(mx_float_to_half(1.0f) == 0x3c00);
    CHECK(mx_float_to_half(65504.0f) == 0x7bff);
    CHECK(mx_float_to_half(65520.0f) == 0x7c00);
    CHECK(mx_float_to_half(-2.0f) == 0xc000);
    CHECK(mx_float_to_half(5.9604645e-8f) == 0x0001);
    CHECK(mx_float_to_half(1.0f + 1.0f / 2048) == 0x3c00); /* tie rounds to even */
    CHECK(mx_float_to_half(1.0f + 3.0f / 2048) == 0x3c02);
    CHECK((mx_float_to_half(NAN) & 0x7c00) == 0x7c00 && (mx_float_to_half(NAN) & 0x3ff) != 0);
    CHECK(mx_half_to_float(0x3555) == 0.333251953125f);
    CHECK(mx_half_to_float(0x0001) == 5.9604645e-8f);
    CHECK(isinf(mx_half_to_float(0xfc00)) && mx_half_to_float(0xfc00) < 0);
    CHECK(mx_float_to_bf16(1.0f) == 0x3f80);
    CHECK(mx_float_to_bf16(1.00390625f) == 0x3f80); /* tie to even */
    CHECK(mx_float_to_bf16(1.01171875f) == 0x3f82);
    CHECK(mx_bf16_to_float(0xc040) == -3.0f);
    CHECK(isnan(mx_bf16_to_float(mx_float_to_bf16(NAN))));
}

static void test_known_attention(const mx_ctx *c) {
    /* one key: the output is that key's value, whatever the scores */
    float q[2 * 4] = {1, 2, 3, 4, -1, 0, 5, 2}, k[4] = {0.5f, 1, -1, 2}, v[4] = {3, -2, 7, 1}, out[8];
    mx_attention(c, out, q, k, v, 1, 1, 2, 1, 4, 4, 4, 4, 0, 0.5f);
    const float want[8] = {3, -2, 7, 1, 3, -2, 7, 1};
    mx_check_close("known attention Tk=1", out, want, 8, 1e-7);
}

static void test_known_group_norm(const mx_ctx *c) {
    float x[8] = {1, 2, 3, 4, 10, 10, 10, 10}, y[8];
    mx_group_norm(c, y, x, 1, 2, 4, 2, mx_w_none(), mx_w_none(), 1e-5f, 0);
    const float s = 1.0f / sqrtf(1.25f + 1e-5f);
    const float want[8] = {-1.5f * s, -0.5f * s, 0.5f * s, 1.5f * s, 0, 0, 0, 0};
    mx_check_close("known group norm", y, want, 8, 1e-6);
}

/* conv2d_up2x's reference is the 3×3 conv of the stored upsample, to the bit (the same sums in double). */
static void test_known_conv_up2x(const mx_ctx *c) {
    enum { B = 2, CI = 3, H = 4, W = 5, CO = 6 };
    float x[B * CI * H * W], w[CO * CI * 9], bias[CO], u[B * CI * 4 * H * W], want[B * CO * 4 * H * W],
        y[B * CO * 4 * H * W];
    mx_fill_random(x, B * CI * H * W, 11, -1.0f, 1.0f);
    mx_fill_random(w, CO * CI * 9, 12, -1.0f, 1.0f);
    mx_fill_random(bias, CO, 13, -1.0f, 1.0f);
    mx_upsample_nearest2x(c, u, x, B * CI, H, W);
    mx_conv2d(c, want, u, B, CI, 2 * H, 2 * W, mx_w_f32(w), mx_w_f32(bias), CO, 3, 3, 1, 1);
    mx_conv2d_up2x(c, y, x, B, CI, H, W, mx_w_f32(w), mx_w_f32(bias), CO);
    mx_check_close("known conv2d_up2x (= upsample, then conv2d)", y, want, B * CO * 4 * H * W, 0);
}

static void test_known_timestep_embedding(void) {
    float t[1] = {10}, y[4];
    mx_timestep_embedding(NULL, y, t, 1, 4, 1, 0, 10000);
    /* half = 2: freqs 1 and 10000^-0.5 = 0.01; flip: [cos | sin] */
    const float want[4] = {cosf(10), cosf(0.1f), sinf(10), sinf(0.1f)};
    mx_check_close("known timestep embedding", y, want, 4, 1e-6);
}

/* ---- SIMD levels against the scalar reference ---- */

typedef struct {
    const mx_ctx *ref, *simd;
    const char *isa;
    int bf16; /* the level rounds the inputs of its matrix products to bf16 */
} levels;

static float *rnd(size_t n, uint64_t seed) {
    float *x = malloc((n ? n : 1) * sizeof *x);
    mx_fill_random(x, n, seed, -1.0f, 1.0f);
    return x;
}

/* A weight of dtype dt holding n random values; *store is the buffer to free. */
static mx_wptr rnd_weight(size_t n, uint64_t seed, mx_dtype dt, void **store) {
    float *f = rnd(n, seed);
    if (dt == MX_F32) {
        *store = f;
        return mx_w_f32(f);
    }
    uint16_t *h = malloc((n ? n : 1) * sizeof *h);
    for (size_t i = 0; i < n; i++) h[i] = dt == MX_F16 ? mx_float_to_half(f[i]) : mx_float_to_bf16(f[i]);
    free(f);
    *store = h;
    mx_wptr w = {h, dt};
    return w;
}

/* The values the reference sees: x itself, or a copy rounded to bf16 on a bf16 level (free it). */
static float *ref_input(const levels *lv, const float *x, size_t n, float **store) {
    *store = NULL;
    if (!lv->bf16) return (float *)x;
    float *r = malloc((n ? n : 1) * sizeof *r);
    for (size_t i = 0; i < n; i++) r[i] = mx_bf16_to_float(mx_float_to_bf16(x[i]));
    *store = r;
    return r;
}

/* The same for a weight (widened to fp32 first). */
static mx_wptr ref_weight(const levels *lv, mx_wptr w, size_t n, float **store) {
    *store = NULL;
    if (!lv->bf16) return w;
    float *f = malloc((n ? n : 1) * sizeof *f);
    for (size_t i = 0; i < n; i++) f[i] = mx_bf16_to_float(mx_float_to_bf16(mx_w_get(w, i)));
    *store = f;
    return mx_w_f32(f);
}

static void test_linear_case(const levels *lv, int M, int N, int K, mx_dtype dt, int with_bias) {
    void *ws, *bs;
    float *x = rnd((size_t)M * K, 1), *y = rnd((size_t)M * N, 9), *want = rnd((size_t)M * N, 8), *xr_s, *wr_s;
    mx_wptr w = rnd_weight((size_t)N * K, 2, dt, &ws), b = rnd_weight((size_t)N, 3, dt, &bs);
    if (!with_bias) b = mx_w_none();
    mx_linear(lv->ref, want, ref_input(lv, x, (size_t)M * K, &xr_s), ref_weight(lv, w, (size_t)N * K, &wr_s), b, M,
              N, K);
    mx_linear(lv->simd, y, x, w, b, M, N, K);
    free(xr_s), free(wr_s);
    char name[96];
    snprintf(name, sizeof name, "%s linear M=%d N=%d K=%d %s%s", lv->isa, M, N, K, mx_dtype_name(dt),
             with_bias ? " +bias" : "");
    mx_check_close(name, y, want, (size_t)M * N, 1e-5);
    free(x), free(y), free(want), free(ws), free(bs);
}

static void test_conv_case(const levels *lv, int B, int Cin, int H, int W, int Cout, int ks, int stride, int pad,
                           mx_dtype dt) {
    int Ho = (H + 2 * pad - ks) / stride + 1, Wo = (W + 2 * pad - ks) / stride + 1;
    size_t ny = (size_t)B * Cout * Ho * Wo;
    void *ws, *bs;
    size_t nx = (size_t)B * Cin * H * W, nw = (size_t)Cout * Cin * ks * ks;
    float *x = rnd(nx, 4), *y = rnd(ny, 9), *want = rnd(ny, 8), *xr_s, *wr_s;
    mx_wptr w = rnd_weight(nw, 5, dt, &ws), b = rnd_weight((size_t)Cout, 6, dt, &bs);
    mx_conv2d(lv->ref, want, ref_input(lv, x, nx, &xr_s), B, Cin, H, W, ref_weight(lv, w, nw, &wr_s), b, Cout, ks, ks,
              stride, pad);
    mx_conv2d(lv->simd, y, x, B, Cin, H, W, w, b, Cout, ks, ks, stride, pad);
    free(xr_s), free(wr_s);
    char name[96];
    snprintf(name, sizeof name, "%s conv B=%d %dx%dx%d->%d k%d s%d p%d %s", lv->isa, B, Cin, H, W, Cout, ks, stride,
             pad, mx_dtype_name(dt));
    mx_check_close(name, y, want, ny, 1e-5);
    free(x), free(y), free(want), free(ws), free(bs);
}

/* conv2d_up2x's phase kernels [4·Cout][Cin][2][2] (row phase·Cout + co, phase = 2a + b) from the 3×3
 * weights by the definition: tap ky of output row 2i+a reads upsampled row 2i+a+ky-1, input row
 * i + floor((a+ky-1)/2), which is tap ty = floor((a+ky-1)/2) - a + 1 of the 2×2 conv's row i+a;
 * rounded to bf16 as a bf16 level rounds them. */
static float *phase_kernels(mx_wptr w, int Cout, int Cin, int bf16) {
    float *k = calloc((size_t)16 * Cout * Cin, sizeof *k);
    for (int ph = 0; ph < 4; ph++)
        for (int co = 0; co < Cout; co++)
            for (int ci = 0; ci < Cin; ci++)
                for (int ky = 0; ky < 3; ky++)
                    for (int kx = 0; kx < 3; kx++) {
                        int a = ph / 2, b = ph % 2, ty = (a + ky + 1) / 2 - a, tx = (b + kx + 1) / 2 - b;
                        k[(((size_t)ph * Cout + co) * Cin + ci) * 4 + ty * 2 + tx] +=
                            mx_w_get(w, (((size_t)co * Cin + ci) * 3 + ky) * 3 + kx);
                    }
    for (size_t i = 0; bf16 && i < (size_t)16 * Cout * Cin; i++) k[i] = mx_bf16_to_float(mx_float_to_bf16(k[i]));
    return k;
}

/* The reference of a bf16 level's conv2d_up2x: the 2×2 phase conv (padding 1) with the rounded phase
 * kernels, on the rounded input, interleaved: output (2i+a, 2j+b) is phase 2a+b at (i+a, j+b). */
static void phase_reference(const levels *lv, float *want, const float *xr, int B, int Cin, int H, int W,
                            mx_wptr w, mx_wptr bias, int Cout) {
    float *k = phase_kernels(w, Cout, Cin, 1);
    size_t zp = (size_t)(H + 1) * (W + 1);
    float *z = malloc((size_t)B * 4 * Cout * zp * sizeof *z);
    mx_conv2d(lv->ref, z, xr, B, Cin, H, W, mx_w_f32(k), mx_w_none(), 4 * Cout, 2, 2, 1, 1);
    for (int n = 0; n < B; n++)
        for (int co = 0; co < Cout; co++)
            for (int y = 0; y < 2 * H; y++)
                for (int x = 0; x < 2 * W; x++) {
                    int a = y % 2, b = x % 2, ph = 2 * a + b;
                    float v = z[((size_t)n * 4 * Cout + (size_t)ph * Cout + co) * zp + (size_t)(y / 2 + a) * (W + 1) +
                                (size_t)(x / 2 + b)];
                    want[(((size_t)n * Cout + co) * 2 * H + y) * 2 * W + x] = v + (float)mx_w_get(bias, (size_t)co);
                }
    free(k), free(z);
}

static void test_conv_up2x_case(const levels *lv, int B, int Cin, int H, int W, int Cout, mx_dtype dt) {
    size_t nx = (size_t)B * Cin * H * W, ny = (size_t)B * Cout * 4 * H * W, nw = (size_t)Cout * Cin * 9;
    void *ws, *bs;
    float *x = rnd(nx, 4), *y = rnd(ny, 9), *want = rnd(ny, 8), *xr_s;
    mx_wptr w = rnd_weight(nw, 5, dt, &ws), b = rnd_weight((size_t)Cout, 6, dt, &bs);
    if (lv->bf16)
        phase_reference(lv, want, ref_input(lv, x, nx, &xr_s), B, Cin, H, W, w, b, Cout);
    else
        mx_conv2d_up2x(lv->ref, want, ref_input(lv, x, nx, &xr_s), B, Cin, H, W, w, b, Cout);
    mx_conv2d_up2x(lv->simd, y, x, B, Cin, H, W, w, b, Cout);
    free(xr_s);
    char name[96];
    snprintf(name, sizeof name, "%s conv2d_up2x B=%d %dx%dx%d->%d %s", lv->isa, B, Cin, H, W, Cout, mx_dtype_name(dt));
    mx_check_close(name, y, want, ny, 1e-5);
    free(x), free(y), free(want), free(ws), free(bs);
}

static void test_gemm_ops(const levels *lv) {
    test_linear_case(lv, 1, 1, 1, MX_F32, 1);
    test_linear_case(lv, 13, 37, 29, MX_F32, 1);
    test_linear_case(lv, 77, 67, 300, MX_F16, 1);
    test_linear_case(lv, 50, 33, 530, MX_BF16, 0);
    test_linear_case(lv, 130, 100, 17, MX_F32, 0);
    test_linear_case(lv, 4200, 45, 21, MX_F32, 1); /* crosses the 4096-row outer block */
    test_linear_case(lv, 3, 4133, 19, MX_F16, 1);  /* crosses the 4096-column outer block */
    /* the splits of gemm.c (choose_split): COLUMNS, then ROWS (many row blocks, few columns) */
    test_linear_case(lv, 50, 3000, 700, MX_F16, 1);
    test_linear_case(lv, 800, 20, 700, MX_F16, 1);
    test_conv_case(lv, 2, 80, 5, 6, 700, 3, 1, 1, MX_F16); /* and over batch items and K blocks */
    test_conv_case(lv, 1, 3, 9, 11, 5, 3, 1, 1, MX_F32);
    test_conv_case(lv, 2, 7, 13, 10, 17, 3, 2, 1, MX_F16);
    test_conv_case(lv, 2, 33, 1, 1, 19, 1, 1, 0, MX_BF16);
    test_conv_case(lv, 1, 40, 17, 19, 13, 3, 1, 1, MX_F32);
    test_conv_case(lv, 1, 9, 6, 7, 70, 1, 1, 0, MX_F32);
    test_conv_case(lv, 1, 2, 70, 71, 3, 3, 1, 1, MX_F32); /* 4970 pixels: two outer blocks */
    test_conv_case(lv, 2, 80, 70, 60, 13, 3, 1, 1, MX_F16); /* batch × K blocks (K = 720) × outer blocks */
    test_linear_case(lv, 40, 37, 1500, MX_F32, 1);          /* three K blocks */
    test_linear_case(lv, 20, 33, 4500, MX_F16, 1);          /* several K blocks of the AMX level too */
    test_linear_case(lv, 25, 70, 641, MX_F16, 1);           /* two K blocks of odd length (321, 320) */
    test_conv_case(lv, 1, 3, 8, 8, 33, 3, 1, 1, MX_F32);    /* K = 27: an odd last k-pair */
    test_linear_case(lv, 64, 64, 64, MX_F32, 1);            /* whole AMX tiles (32×32 blocks, 16 k-pairs) */
    test_linear_case(lv, 33, 65, 33, MX_BF16, 1);           /* one row / column / k-pair past the tiles */
    test_conv_case(lv, 1, 16, 8, 8, 32, 3, 1, 1, MX_F16);   /* K = 144: 72 k-pairs, padded to 80 */
    /* the band packer (gemm_conv.c): K groups, stride, padding and band bounds */
    test_conv_case(lv, 1, 1, 5, 7, 4, 3, 1, 1, MX_F32);      /* Cin = 1: one channel paired with zero */
    test_conv_case(lv, 2, 4, 9, 37, 6, 1, 1, 0, MX_BF16);    /* 1×1, batch 2, W past one panel */
    test_conv_case(lv, 1, 5, 13, 45, 7, 3, 2, 0, MX_F16);    /* stride 2, pad 0, odd Cin */
    test_conv_case(lv, 2, 3, 33, 70, 9, 3, 2, 1, MX_F32);    /* stride 2, pad 1: strided copies */
    test_conv_case(lv, 1, 151, 20, 23, 20, 3, 1, 1, MX_F16); /* 3 K groups, the last one smaller */
    test_conv_case(lv, 1, 40, 11, 12, 5, 5, 1, 2, MX_BF16);  /* 5×5: groups of 25 taps */
    test_conv_case(lv, 1, 2, 20, 20, 3, 19, 1, 9, MX_F16);   /* 361 taps: past a K block on pairs */
    test_conv_case(lv, 1, 512, 4, 1100, 3, 3, 1, 1, MX_F32); /* band of 1 output row (8 MiB bound) */
    /* B panels read in place (micro_rows, on the column tasks: ≥ 8 of them), each half of a
     * panel within one output row */
    test_conv_case(lv, 2, 24, 40, 64, 40, 3, 1, 1, MX_F16); /* two panels per row */
    test_conv_case(lv, 8, 40, 16, 16, 50, 3, 1, 1, MX_F16); /* a panel's halves in two rows */
    test_conv_case(lv, 8, 8, 9, 48, 20, 3, 1, 1, MX_F32);   /* 48 wide: halves in one row or two */
    test_conv_case(lv, 8, 33, 5, 64, 14, 1, 1, 0, MX_BF16); /* 1×1 unpadded: the input is the band */
    /* conv2d_up2x's phase form: edges of the phase grid, K blocks, blocks of rows */
    test_conv_up2x_case(lv, 1, 3, 5, 7, 4, MX_F32);
    test_conv_up2x_case(lv, 1, 40, 1, 1, 5, MX_BF16);    /* one input pixel: every tap at an edge */
    test_conv_up2x_case(lv, 2, 17, 9, 6, 33, MX_F16);    /* batch 2, odd channels, panel edges */
    test_conv_up2x_case(lv, 1, 200, 6, 5, 13, MX_F16);   /* K = 800: two K blocks */
    test_conv_up2x_case(lv, 1, 8, 3, 70, 9, MX_F32);     /* 71-wide phase rows: panels across rows */
    test_conv_up2x_case(lv, 1, 4, 2, 600, 1024, MX_F32); /* phase planes past 16 MiB a row: 3 blocks */
}

#ifndef MX_NO_X86_SIMD
/* The AMX kernels on emulated tiles (tests/amx_emu.c). */
void mx_attention_amx_emu(const mx_ctx *, float *out, const float *q, const float *k, const float *v, int B, int H,
                          int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal, float scale);
void mx_linear_x3_amx_emu(const mx_ctx *, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
void mx_conv2d_x3_amx_emu(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                          mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
void mx_linear_amx_emu(const mx_ctx *, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
void mx_conv2d_amx_emu(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                       mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
void mx_conv2d_up2x_amx_emu(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                            mx_wptr bias, int Cout);
void mx_conv2d_up2x_x3_amx_emu(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                               mx_wptr bias, int Cout);

static void test_attention_ops(const levels *lv);

/* The avx512bf16 table with the emulated AMX kernels (their packing needs AVX512_BF16). */
static void test_amx_emulated(const mx_ctx *ref, mx_pool *pool, mx_arena *scratch) {
    const mx_kernels *bf16 = mx_kernels_for(MX_ISA_AVX512_BF16);
    if (bf16->isa != MX_ISA_AVX512_BF16) {
        printf("amx (emulated tiles): NOT TESTED (no AVX512_BF16 on this CPU, or lowered by MATEX_ISA)\n");
        return;
    }
    mx_kernels emu = *bf16;
    emu.linear = mx_linear_amx_emu;
    emu.conv2d = mx_conv2d_amx_emu;
    emu.conv2d_up2x = mx_conv2d_up2x_amx_emu;
    emu.attention = mx_attention_amx_emu;
    mx_ctx simd = {.pool = pool, .k = &emu, .scratch = scratch};
    levels lv = {ref, &simd, "amx (emulated tiles)", 1};
    test_gemm_ops(&lv);
    test_attention_ops(&lv);
    emu.linear = mx_linear_x3_amx_emu;
    emu.conv2d = mx_conv2d_x3_amx_emu;
    emu.conv2d_up2x = mx_conv2d_up2x_x3_amx_emu;
    levels x3 = {ref, &simd, "amx fp32 (3 bf16 products, emulated tiles)", 0};
    test_gemm_ops(&x3);
    CHECK(scratch->used == 0);
}
#endif

/* The bf16 level's bound: the reference has the same rounded q, k, v, and the kernel rounds
 * each probability for ·V (relative error <= 2^-9), so output i is off by at most 2^-9 of
 * Σ_j p_ij |v_j|: the reference run on |v|. In relative L2: 2^-9 ||that|| / ||want||, plus
 * the fp32 bound for the sums. */
static double bf16_attention_bound(const levels *lv, const float *want, const float *q, const float *k, const float *v,
                                   int B, int H, int Tq, int Tk, int D, int causal) {
    int qs = H * D + 3, kvs = H * D + 5, os = H * D + 1;
    size_t nkv = (size_t)B * Tk * kvs, no = (size_t)B * Tq * os;
    float *vabs = malloc(nkv * sizeof *vabs), *yabs = malloc(no * sizeof *yabs);
    for (size_t i = 0; i < nkv; i++) vabs[i] = fabsf(v[i]);
    memcpy(yabs, want, no * sizeof *yabs); /* the gaps between heads stay as in want */
    mx_attention(lv->ref, yabs, q, k, vabs, B, H, Tq, Tk, D, qs, kvs, os, causal, 1.0f / sqrtf((float)D));
    double sa = 0, sw = 0;
    for (size_t i = 0; i < no; i++) sa += (double)yabs[i] * yabs[i], sw += (double)want[i] * want[i];
    free(vabs), free(yabs);
    return ldexp(sqrt(sa / sw), -9) + 1e-5;
}

static void test_attention_case(const levels *lv, int B, int H, int Tq, int Tk, int D, int causal) {
    int qs = H * D + 3, kvs = H * D + 5, os = H * D + 1; /* strides wider than H*D, as in fused qkv */
    size_t nq = (size_t)B * Tq * qs, nkv = (size_t)B * Tk * kvs, no = (size_t)B * Tq * os;
    float *q = rnd(nq, 11), *k = rnd(nkv, 12), *v = rnd(nkv, 13), *y = rnd(no, 14), *want = rnd(no, 14);
    for (size_t i = 0; i < nq; i++) q[i] *= 3; /* peaked softmax rows */
    float *qr, *kr, *vr;
    mx_attention(lv->ref, want, ref_input(lv, q, nq, &qr), ref_input(lv, k, nkv, &kr), ref_input(lv, v, nkv, &vr), B,
                 H, Tq, Tk, D, qs, kvs, os, causal, 1.0f / sqrtf((float)D));
    mx_attention(lv->simd, y, q, k, v, B, H, Tq, Tk, D, qs, kvs, os, causal, 1.0f / sqrtf((float)D));
    char name[96];
    snprintf(name, sizeof name, "%s attention B=%d H=%d Tq=%d Tk=%d D=%d%s", lv->isa, B, H, Tq, Tk, D,
             causal ? " causal" : "");
    mx_check_close(name, y, want, no, lv->bf16 ? bf16_attention_bound(lv, want, qr, kr, vr, B, H, Tq, Tk, D, causal) : 1e-5);
    free(q), free(k), free(v), free(y), free(want), free(qr), free(kr), free(vr);
}

static void test_attention_ops(const levels *lv) {
    test_attention_case(lv, 2, 3, 37, 45, 40, 0);
    test_attention_case(lv, 1, 2, 77, 77, 64, 1);
    test_attention_case(lv, 2, 1, 70, 77, 80, 0);
    test_attention_case(lv, 1, 2, 20, 150, 160, 0);
    test_attention_case(lv, 1, 1, 1, 3, 13, 0);
    test_attention_case(lv, 1, 1, 9, 5, 7, 1);
    test_attention_case(lv, 1, 1, 3, 2, 300, 0);
    test_attention_case(lv, 1, 1, 150, 150, 24, 1);
    test_attention_case(lv, 1, 1, 70, 70, 512, 0);
    test_attention_case(lv, 1, 2, 67, 333, 40, 0); /* keys over several packing tasks and key blocks */
    test_attention_case(lv, 2, 1, 65, 64, 40, 1);  /* causal: query blocks that see only part of the keys */
    test_attention_case(lv, 1, 1, 2, 3, 1100, 0);  /* amx: a head past its buffers, the streaming kernel */
    /* amx: blocks of 128 queries (two threads) over several key chunks, maxima rising between them */
    test_attention_case(lv, 1, 1, 600, 700, 40, 0);
    test_attention_case(lv, 1, 1, 1100, 1100, 40, 1);
}

static void test_group_norm_case(const levels *lv, int B, int C, int HW, int groups, mx_dtype dt, int silu) {
    size_t n = (size_t)B * C * HW;
    void *gs, *bs;
    float *x = rnd(n, 21), *y = rnd(n, 22), *want = rnd(n, 23);
    for (size_t i = 0; i < n; i++) x[i] = 3 * x[i] + 1.5f; /* non-zero mean */
    mx_wptr g = rnd_weight((size_t)C, 24, dt, &gs), b = rnd_weight((size_t)C, 25, dt, &bs);
    mx_group_norm(lv->ref, want, x, B, C, HW, groups, g, b, 1e-5f, silu);
    mx_group_norm(lv->simd, y, x, B, C, HW, groups, g, b, 1e-5f, silu);
    char name[96];
    snprintf(name, sizeof name, "%s group_norm B=%d C=%d HW=%d G=%d %s%s", lv->isa, B, C, HW, groups,
             mx_dtype_name(dt), silu ? " +silu" : "");
    mx_check_close(name, y, want, n, 1e-5);
    mx_group_norm(lv->simd, x, x, B, C, HW, groups, g, b, 1e-5f, silu); /* in place */
    CHECK(memcmp(x, y, n * sizeof *x) == 0);
    free(x), free(y), free(want), free(gs), free(bs);
}

static void test_layer_norm_case(const levels *lv, int M, int C, mx_dtype dt) {
    size_t n = (size_t)M * C;
    void *gs, *bs;
    float *x = rnd(n, 31), *y = rnd(n, 32), *want = rnd(n, 33);
    mx_wptr g = rnd_weight((size_t)C, 34, dt, &gs), b = rnd_weight((size_t)C, 35, dt, &bs);
    mx_layer_norm(lv->ref, want, x, M, C, g, b, 1e-5f);
    mx_layer_norm(lv->simd, y, x, M, C, g, b, 1e-5f);
    char name[96];
    snprintf(name, sizeof name, "%s layer_norm M=%d C=%d %s", lv->isa, M, C, mx_dtype_name(dt));
    mx_check_close(name, y, want, n, 1e-5);
    free(x), free(y), free(want), free(gs), free(bs);
}

typedef void (*unary_op)(const mx_ctx *, float *, size_t);

static void test_unary_case(const levels *lv, const char *op, unary_op fn, size_t n, float range) {
    float *x = malloc(n * sizeof *x), *want = malloc(n * sizeof *want);
    mx_fill_random(x, n, 51, -range, range);
    memcpy(want, x, n * sizeof *x);
    fn(lv->ref, want, n);
    fn(lv->simd, x, n);
    char name[96];
    snprintf(name, sizeof name, "%s %s n=%zu range %g", lv->isa, op, n, range);
    mx_check_close(name, x, want, n, 1e-5);
    free(x), free(want);
}

/* GELU of negative inputs is tiny: check the relative error of each value, not only the L2. */
static void test_gelu_tail(const levels *lv) {
    enum { N = 4001 };
    float x[N], want[N];
    for (int i = 0; i < N; i++) x[i] = -9.0f + 9.0f * (float)i / N;
    memcpy(want, x, sizeof x);
    mx_gelu(lv->ref, want, N);
    mx_gelu(lv->simd, x, N);
    double worst = 0;
    for (int i = 0; i < N; i++)
        if (want[i] != 0) {
            double e = fabs((double)x[i] - want[i]) / fabs((double)want[i]);
            worst = e > worst ? e : worst;
        }
    printf("%s gelu on [-9, 0): max relative error %.2e (bound 2e-6)\n", lv->isa, worst);
    CHECK(worst <= 2e-6);
}

static void test_geglu_case(const levels *lv, int M, int N) {
    size_t n = (size_t)M * N;
    float *x = rnd(2 * n, 61), *y = rnd(n, 62), *want = rnd(n, 63);
    for (size_t i = 0; i < 2 * n; i++) x[i] *= 4;
    mx_geglu(lv->ref, want, x, M, N);
    mx_geglu(lv->simd, y, x, M, N);
    char name[96];
    snprintf(name, sizeof name, "%s geglu M=%d N=%d", lv->isa, M, N);
    mx_check_close(name, y, want, n, 1e-5);
    free(x), free(y), free(want);
}

static void test_binary_case(const levels *lv, mx_binop op, int ndim, const int64_t *as, const int64_t *bs) {
    size_t na = 1, nb = 1, ny = 1;
    for (int d = 0; d < ndim; d++) {
        na *= (size_t)as[d];
        nb *= (size_t)bs[d];
        ny *= (size_t)(as[d] > bs[d] ? as[d] : bs[d]);
    }
    float *a = rnd(na, 71), *b = rnd(nb, 72), *y = rnd(ny, 73), *want = rnd(ny, 74);
    mx_binary(lv->ref, op, want, a, as, b, bs, ndim);
    mx_binary(lv->simd, op, y, a, as, b, bs, ndim);
    char name[128], sa[64], sb[64];
    snprintf(name, sizeof name, "%s binary op%d %s %s", lv->isa, (int)op, mx_shape_str(ndim, as, sa, sizeof sa),
             mx_shape_str(ndim, bs, sb, sizeof sb));
    mx_check_close(name, y, want, ny, 0); /* one rounding either way: exact */
    free(a), free(b), free(y), free(want);
}

/* Both transposes of B items of C × HW at the SIMD level against the reference, bit for bit (sizes
 * off the register blocks and the 64-float tiles). */
static void test_transpose_case(const levels *lv, int B, int C, int HW) {
    size_t n = (size_t)B * C * HW;
    float *x = rnd(n, 91), *y = rnd(n, 92), *want = rnd(n, 93);
    char name[96];
    mx_transpose_chw_hwc(lv->ref, want, x, B, C, HW);
    mx_transpose_chw_hwc(lv->simd, y, x, B, C, HW);
    snprintf(name, sizeof name, "%s transpose_chw_hwc [%d, %d, %d]", lv->isa, B, C, HW);
    mx_check_close(name, y, want, n, 0);
    mx_transpose_hwc_chw(lv->ref, want, x, B, C, HW);
    mx_transpose_hwc_chw(lv->simd, y, x, B, C, HW);
    snprintf(name, sizeof name, "%s transpose_hwc_chw [%d, %d, %d]", lv->isa, B, C, HW);
    mx_check_close(name, y, want, n, 0);
    free(x), free(y), free(want);
}

static void test_elementwise_ops(const levels *lv) {
    test_transpose_case(lv, 2, 320, 4096);
    test_transpose_case(lv, 3, 37, 131);
    test_transpose_case(lv, 1, 1, 7);
    test_transpose_case(lv, 2, 67, 5);
    test_group_norm_case(lv, 2, 12, 37, 3, MX_F32, 0);
    test_group_norm_case(lv, 1, 64, 1, 32, MX_F16, 1);
    test_group_norm_case(lv, 2, 320, 1024, 32, MX_BF16, 1);
    test_group_norm_case(lv, 1, 5, 1001, 5, MX_F32, 1);
    test_layer_norm_case(lv, 7, 77, MX_F32);
    test_layer_norm_case(lv, 3, 768, MX_BF16);
    test_layer_norm_case(lv, 4, 5, MX_F16);
    test_layer_norm_case(lv, 150, 320, MX_F32); /* 51 rows per task: 3 tasks, the last one short */
    test_unary_case(lv, "gelu", mx_gelu, 100003, 8);
    test_unary_case(lv, "gelu", mx_gelu, 37, 0.5f);
    test_gelu_tail(lv);
    test_unary_case(lv, "quick_gelu", mx_quick_gelu, 50001, 12);
    test_unary_case(lv, "silu", mx_silu, 70001, 100);
    test_geglu_case(lv, 7, 37);
    test_geglu_case(lv, 3, 1280);
    const int64_t s1[1] = {1001}, s4a[4] = {2, 5, 7, 9}, s4b[4] = {2, 5, 1, 1}, s4c[4] = {2, 1, 7, 9},
                  s4d[4] = {1, 5, 7, 1}, s2a[2] = {3, 1}, s2b[2] = {1, 4}, s3a[3] = {2, 3, 19}, s3b[3] = {1, 1, 19};
    test_binary_case(lv, MX_BIN_ADD, 1, s1, s1);
    test_binary_case(lv, MX_BIN_ADD, 4, s4a, s4b);
    test_binary_case(lv, MX_BIN_SUB, 4, s4b, s4a);
    test_binary_case(lv, MX_BIN_MUL, 4, s4c, s4d);
    test_binary_case(lv, MX_BIN_SUB, 2, s2a, s2b);
    test_binary_case(lv, MX_BIN_MUL, 3, s3a, s3b);
    float *x = rnd(1037, 81), *y = rnd(1037, 82), *want = rnd(1037, 83);
    mx_scale(lv->ref, want, x, 0.37f, 1037);
    mx_scale(lv->simd, y, x, 0.37f, 1037);
    char name[64];
    snprintf(name, sizeof name, "%s scale n=1037", lv->isa);
    mx_check_close(name, y, want, 1037, 0);
    free(x), free(y), free(want);
}

static void test_simd_levels(void) {
    mx_status st;
    mx_pool *pool = mx_pool_create(2, &st);
    mx_arena scratch;
    CHECK(pool != NULL);
    CHECK(mx_arena_create(&scratch, (size_t)8 << 20, &st) == 0);
    mx_ctx ref = {.pool = pool, .k = mx_kernels_scalar()};
    for (mx_isa isa = MX_ISA_SCALAR + 1; isa < MX_ISA_COUNT; isa++) {
        const mx_kernels *k = mx_kernels_for(isa);
        if (!mx_kernels_compiled(isa)) {
            printf("%s: not a level of this build's architecture\n", mx_isa_name(isa));
            continue;
        }
        if (k->isa != isa) {
            printf("%s: NOT TESTED (%s)\n", mx_isa_name(isa),
                   isa == MX_ISA_AMX ? "no AMX on this CPU, no tile permission from the OS, or lowered by MATEX_ISA"
                                     : "not available on this CPU (or emulated CPU model), or lowered by MATEX_ISA");
            continue;
        }
        mx_ctx simd = {.pool = pool, .k = k, .scratch = &scratch};
        levels lv = {&ref, &simd, mx_isa_name(isa), mx_isa_precision(isa) == MX_PREC_BF16};
        test_gemm_ops(&lv);
        test_attention_ops(&lv);
        test_elementwise_ops(&lv);
        CHECK(scratch.used == 0);
        if (isa == MX_ISA_AMX) { /* its fp32 layers: the GEMMs as three bf16 products, at the fp32 bounds */
            mx_ctx fp32 = mx_ctx_fp32(&simd);
            levels x3 = {&ref, &fp32, "amx fp32 (3 bf16 products)", 0};
            test_gemm_ops(&x3);
            CHECK(scratch.used == 0);
        }
    }
#ifndef MX_NO_X86_SIMD
    test_amx_emulated(&ref, pool, &scratch);
#endif
    mx_arena_destroy(&scratch);
    mx_pool_destroy(pool);
}

/* Layout ops (reference only, shared by all levels): known answers. */
static void test_known_layout(const mx_ctx *c) {
    const float x[4] = {0, 1, 2, 3};
    float y[16];
    mx_upsample_nearest2x(c, y, x, 1, 2, 2);
    const float want_up[16] = {0, 0, 1, 1, 0, 0, 1, 1, 2, 2, 3, 3, 2, 2, 3, 3};
    mx_check_close("known upsample_nearest2x", y, want_up, 16, 0);
    /* [1, 2, 3] <-> [1, 3, 2] */
    const float chw[6] = {1, 2, 3, 4, 5, 6}, hwc_want[6] = {1, 4, 2, 5, 3, 6};
    float t[6], back[6];
    mx_transpose_chw_hwc(c, t, chw, 1, 2, 3);
    mx_check_close("known transpose_chw_hwc", t, hwc_want, 6, 0);
    mx_transpose_hwc_chw(c, back, t, 1, 2, 3);
    mx_check_close("known transpose_hwc_chw", back, chw, 6, 0);
    /* several tasks per item: [2, 300, 37] against the index rule, and the round trip */
    enum { TB = 2, TC = 300, THW = 37, TN = TB * TC * THW };
    float *big = rnd(TN, 95), *tr = malloc(TN * sizeof *tr), *tr_want = malloc(TN * sizeof *tr), *rt = rnd(TN, 96);
    for (int bi = 0; bi < TB; bi++)
        for (int ch = 0; ch < TC; ch++)
            for (int p = 0; p < THW; p++) tr_want[(bi * THW + p) * TC + ch] = big[(bi * TC + ch) * THW + p];
    mx_transpose_chw_hwc(c, tr, big, TB, TC, THW);
    mx_check_close("known transpose_chw_hwc [2, 300, 37]", tr, tr_want, TN, 0);
    mx_transpose_hwc_chw(c, rt, tr, TB, TC, THW);
    mx_check_close("known transpose round trip [2, 300, 37]", rt, big, TN, 0);
    free(big), free(tr), free(tr_want), free(rt);
    /* concat of [2, 1, 2] and [2, 2, 2] along channels */
    const float a[4] = {1, 2, 3, 4}, b[8] = {5, 6, 7, 8, 9, 10, 11, 12};
    const float cat_want[12] = {1, 2, 5, 6, 7, 8, 3, 4, 9, 10, 11, 12};
    float cat[12];
    mx_concat_channels(c, cat, a, 1, b, 2, 2, 2);
    mx_check_close("known concat_channels", cat, cat_want, 12, 0);
}

/* tanh (TAESD's latent clamp) and the rectangle copy (tiled VAE decode). */
static void test_known_tanh_copy_rect(const mx_ctx *c) {
    float t[3] = {0.0f, 1.0f, -20.0f};
    mx_tanh(c, t, 3);
    CHECK(t[0] == 0.0f && fabsf(t[1] - 0.76159416f) < 1e-7f && t[2] == -1.0f);
    /* 2 planes of 4x5 -> the 2x3 rectangle at (1, 2) into 3x4 planes at (1, 0) */
    float x[2 * 20], y[2 * 12], want[2 * 12];
    for (int i = 0; i < 40; i++) x[i] = (float)i;
    for (int i = 0; i < 24; i++) y[i] = want[i] = -1.0f;
    for (int p = 0; p < 2; p++)
        for (int r = 0; r < 2; r++)
            for (int q = 0; q < 3; q++) want[p * 12 + (1 + r) * 4 + q] = x[p * 20 + (1 + r) * 5 + 2 + q];
    mx_copy_rect(c, y, 3, 4, 1, 0, x, 4, 5, 1, 2, 2, 2, 3);
    mx_check_close("known copy_rect 2x3 of 4x5 into 3x4", y, want, 24, 0);
}

/* Empty shapes are no work on every backend: the wrappers' guards (op_list.h) stop them before the
 * kernel table, so a backend never sees them (CUDA used to fail on them). A table whose entries
 * for these ops count their calls proves it; one non-empty call of each proves the count works. */
static int table_calls;
static void count_conv2d(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                         mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    (void)c, (void)y, (void)x, (void)B, (void)Cin, (void)H, (void)W, (void)w, (void)bias, (void)Cout, (void)kh,
        (void)kw, (void)stride, (void)pad;
    table_calls++;
}
static void count_binary(const mx_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b,
                         const int64_t *bshape, int ndim) {
    (void)c, (void)op, (void)y, (void)a, (void)ashape, (void)b, (void)bshape, (void)ndim;
    table_calls++;
}
static void count_upsample(const mx_ctx *c, float *y, const float *x, int BC, int H, int W) {
    (void)c, (void)y, (void)x, (void)BC, (void)H, (void)W;
    table_calls++;
}
static void count_concat(const mx_ctx *c, float *y, const float *a, int Ca, const float *b, int Cb, int B, int HW) {
    (void)c, (void)y, (void)a, (void)Ca, (void)b, (void)Cb, (void)B, (void)HW;
    table_calls++;
}
static void count_transpose(const mx_ctx *c, float *y, const float *x, int B, int C, int HW) {
    (void)c, (void)y, (void)x, (void)B, (void)C, (void)HW;
    table_calls++;
}

/* The empty calls of the layout ops, binary and conv2d (a kernel larger than the padded input); then
 * `full` non-empty ones. NULL data: an empty op must not touch memory. */
static void call_layout_ops(const mx_ctx *c, int full) {
    const int64_t s0[2] = {2, 0}, s1[2] = {2, 1}, s3[2] = {2, 3};
    float y[64] = {0}, x[64] = {0};
    mx_binary(c, MX_BIN_ADD, NULL, NULL, s0, NULL, s1, 2);
    mx_binary(c, MX_BIN_MUL, NULL, NULL, s1, NULL, s0, 2);
    mx_upsample_nearest2x(c, NULL, NULL, 3, 0, 4);
    mx_concat_channels(c, NULL, NULL, 2, NULL, 3, 2, 0);
    mx_concat_channels(c, NULL, NULL, 0, NULL, 0, 2, 5);
    mx_transpose_chw_hwc(c, NULL, NULL, 0, 4, 5);
    mx_transpose_hwc_chw(c, NULL, NULL, 2, 4, 0);
    mx_conv2d(c, NULL, NULL, 1, 2, 2, 2, mx_w_none(), mx_w_none(), 3, 5, 5, 1, 1);
    if (!full) return;
    mx_binary(c, MX_BIN_ADD, y, x, s3, x, s1, 2);
    mx_upsample_nearest2x(c, y, x, 1, 2, 2);
    mx_concat_channels(c, y, x, 0, x, 2, 1, 3);
    mx_transpose_chw_hwc(c, y, x, 1, 2, 3);
    mx_conv2d(c, y, x, 1, 1, 2, 2, mx_w_f32(x), mx_w_none(), 1, 3, 3, 1, 1);
}

static void test_empty_shapes_no_work(void) {
    mx_kernels k = *mx_kernels_scalar();
    k.conv2d = count_conv2d;
    k.binary = count_binary;
    k.upsample_nearest2x = count_upsample;
    k.concat_channels = count_concat;
    k.transpose_chw_hwc = count_transpose;
    k.transpose_hwc_chw = count_transpose;
    mx_ctx c = {.k = &k};
    table_calls = 0;
    call_layout_ops(&c, 0);
    printf("empty shapes: %d kernel calls (want 0)\n", table_calls);
    CHECK(table_calls == 0);
    call_layout_ops(&c, 1);
    CHECK(table_calls == 5);
    mx_ctx ref = {.k = mx_kernels_scalar()}; /* and the reference kernels behind the guards: no crash */
    call_layout_ops(&ref, 0);
}

int main(void) {
    mx_ctx c = {.k = mx_kernels_scalar()};
    test_empty_shapes_no_work();
    test_known_tanh_copy_rect(&c);
    test_simd_levels();
    test_known_linear(&c);
    test_known_conversions();
    test_known_attention(&c);
    test_known_group_norm(&c);
    test_known_timestep_embedding();
    test_known_conv_up2x(&c);
    test_known_layout(&c);
    return mx_test_finish("test_ops_kernels");
}
