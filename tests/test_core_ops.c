/* Op tests: known answers for the scalar references, then every SIMD level this CPU has
 * against the scalar reference on random inputs of awkward sizes. */
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

static void test_known_timestep_embedding(void) {
    float t[1] = {10}, y[4];
    mx_timestep_embedding(y, t, 1, 4, 1, 0, 10000);
    /* half = 2: freqs 1 and 10000^-0.5 = 0.01; flip: [cos | sin] */
    const float want[4] = {cosf(10), cosf(0.1f), sinf(10), sinf(0.1f)};
    mx_check_close("known timestep embedding", y, want, 4, 1e-6);
}

/* ---- SIMD levels against the scalar reference ---- */

typedef struct {
    const mx_ctx *ref, *simd;
    const char *isa;
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

static void test_linear_case(const levels *lv, int M, int N, int K, mx_dtype dt, int with_bias) {
    void *ws, *bs;
    float *x = rnd((size_t)M * K, 1), *y = rnd((size_t)M * N, 9), *want = rnd((size_t)M * N, 8);
    mx_wptr w = rnd_weight((size_t)N * K, 2, dt, &ws), b = rnd_weight((size_t)N, 3, dt, &bs);
    if (!with_bias) b = mx_w_none();
    mx_linear(lv->ref, want, x, w, b, M, N, K);
    mx_linear(lv->simd, y, x, w, b, M, N, K);
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
    float *x = rnd((size_t)B * Cin * H * W, 4), *y = rnd(ny, 9), *want = rnd(ny, 8);
    mx_wptr w = rnd_weight((size_t)Cout * Cin * ks * ks, 5, dt, &ws), b = rnd_weight((size_t)Cout, 6, dt, &bs);
    mx_conv2d(lv->ref, want, x, B, Cin, H, W, w, b, Cout, ks, ks, stride, pad);
    mx_conv2d(lv->simd, y, x, B, Cin, H, W, w, b, Cout, ks, ks, stride, pad);
    char name[96];
    snprintf(name, sizeof name, "%s conv B=%d %dx%dx%d->%d k%d s%d p%d %s", lv->isa, B, Cin, H, W, Cout, ks, stride,
             pad, mx_dtype_name(dt));
    mx_check_close(name, y, want, ny, 1e-5);
    free(x), free(y), free(want), free(ws), free(bs);
}

static void test_gemm_ops(const levels *lv) {
    test_linear_case(lv, 1, 1, 1, MX_F32, 1);
    test_linear_case(lv, 13, 37, 29, MX_F32, 1);
    test_linear_case(lv, 77, 67, 300, MX_F16, 1);
    test_linear_case(lv, 50, 33, 530, MX_BF16, 0);
    test_linear_case(lv, 130, 100, 17, MX_F32, 0);
    test_conv_case(lv, 1, 3, 9, 11, 5, 3, 1, 1, MX_F32);
    test_conv_case(lv, 2, 7, 13, 10, 17, 3, 2, 1, MX_F16);
    test_conv_case(lv, 2, 33, 1, 1, 19, 1, 1, 0, MX_BF16);
    test_conv_case(lv, 1, 40, 17, 19, 13, 3, 1, 1, MX_F32);
    test_conv_case(lv, 1, 9, 6, 7, 70, 1, 1, 0, MX_F32);
}

static void test_attention_case(const levels *lv, int B, int H, int Tq, int Tk, int D, int causal) {
    int qs = H * D + 3, kvs = H * D + 5, os = H * D + 1; /* strides wider than H*D, as in fused qkv */
    size_t nq = (size_t)B * Tq * qs, nkv = (size_t)B * Tk * kvs, no = (size_t)B * Tq * os;
    float *q = rnd(nq, 11), *k = rnd(nkv, 12), *v = rnd(nkv, 13), *y = rnd(no, 14), *want = rnd(no, 14);
    for (size_t i = 0; i < nq; i++) q[i] *= 3; /* peaked softmax rows */
    mx_attention(lv->ref, want, q, k, v, B, H, Tq, Tk, D, qs, kvs, os, causal, 1.0f / sqrtf((float)D));
    mx_attention(lv->simd, y, q, k, v, B, H, Tq, Tk, D, qs, kvs, os, causal, 1.0f / sqrtf((float)D));
    char name[96];
    snprintf(name, sizeof name, "%s attention B=%d H=%d Tq=%d Tk=%d D=%d%s", lv->isa, B, H, Tq, Tk, D,
             causal ? " causal" : "");
    mx_check_close(name, y, want, no, 1e-5);
    free(q), free(k), free(v), free(y), free(want);
}

static void test_attention_ops(const levels *lv) {
    test_attention_case(lv, 2, 3, 37, 45, 40, 0);
    test_attention_case(lv, 1, 2, 77, 77, 64, 1);
    test_attention_case(lv, 2, 1, 70, 77, 80, 0);
    test_attention_case(lv, 1, 2, 20, 150, 160, 0);
    test_attention_case(lv, 1, 1, 1, 3, 13, 0);
    test_attention_case(lv, 1, 1, 9, 5, 7, 1);
    test_attention_case(lv, 1, 1, 3, 2, 300, 0);
}

static void test_simd_levels(void) {
    mx_status st;
    mx_pool *pool = mx_pool_create(2, &st);
    mx_arena scratch;
    CHECK(pool != NULL);
    CHECK(mx_arena_create(&scratch, (size_t)8 << 20, &st) == 0);
    mx_ctx ref = {pool, mx_kernels_scalar(), NULL};
    for (mx_isa isa = MX_ISA_AVX2; isa <= MX_ISA_AVX512; isa++) {
        const mx_kernels *k = mx_kernels_for(isa);
        if (k->isa != isa) {
            printf("%s: not supported by this CPU, skipped\n", mx_isa_name(isa));
            continue;
        }
        mx_ctx simd = {pool, k, &scratch};
        levels lv = {&ref, &simd, mx_isa_name(isa)};
        test_gemm_ops(&lv);
        test_attention_ops(&lv);
        CHECK(scratch.used == 0);
    }
    mx_arena_destroy(&scratch);
    mx_pool_destroy(pool);
}

int main(void) {
    mx_ctx c = {NULL, mx_kernels_scalar(), NULL};
    test_simd_levels();
    test_known_linear(&c);
    test_known_conversions();
    test_known_attention(&c);
    test_known_group_norm(&c);
    test_known_timestep_embedding();
    return mx_test_finish("test_core_ops");
}
