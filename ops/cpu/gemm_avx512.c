/* AVX-512F GEMM micro-kernel (gemm_micro_avx512.inc with fp32 FMAs, one k per step), weight
 * widening with F16C / integer shifts (shared with the bf16 level), and linear + conv2d on the
 * GEMM engine. */
#include <immintrin.h>

#include "gemm.h"
#include "simd_avx512.h"

#define MICRO_NAME micro_12x32
#define MICRO_STEPS(kc) (kc)
#define ROW_FMA(i)                                                                                           \
    {                                                                                                        \
        __m512 ai = _mm512_set1_ps(a[i]);                                                                    \
        c##i##0 = _mm512_fmadd_ps(ai, b0, c##i##0);                                                          \
        c##i##1 = _mm512_fmadd_ps(ai, b1, c##i##1);                                                          \
    }
#include "gemm_micro_avx512.inc"

void mx_gemm_widen_avx512(float *y, mx_wptr w, size_t off, size_t n) {
    const uint16_t *x = (const uint16_t *)w.data + off;
    size_t i = 0;
    if (w.dtype == MX_F16)
        for (; i + 16 <= n; i += 16)
            _mm512_storeu_ps(y + i, _mm512_cvtph_ps(_mm256_loadu_si256((const __m256i *)(x + i))));
    else
        for (; i + 16 <= n; i += 16) {
            __m512i v = _mm512_cvtepu16_epi32(_mm256_loadu_si256((const __m256i *)(x + i)));
            _mm512_storeu_ps(y + i, _mm512_castsi512_ps(_mm512_slli_epi32(v, 16)));
        }
    for (; i < n; i++) y[i] = mx_w_get(w, off + i);
}

#include "gemm_bias_simd.inc"

static const mx_gemm_kernel kernel_avx512 = {.mr = MR, .nr = NR, .micro = micro_12x32, .add_bias = mx_gemm_add_bias_avx512,
                                            .widen = mx_gemm_widen_avx512, .transpose = mx_gemm_transpose,
                                            .micro_rows = micro_12x32_rows, .micro_bias = micro_12x32_bias};

void mx_linear_avx512(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    mx_gemm_linear(c, &kernel_avx512, y, x, w, bias, M, N, K);
}

void mx_conv2d_avx512(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                      mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    mx_gemm_conv2d(c, &kernel_avx512, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad);
}

void mx_conv2d_up2x_avx512(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                           mx_wptr bias, int Cout) {
    mx_gemm_conv2d_up2x(c, &kernel_avx512, y, x, B, Cin, H, W, w, bias, Cout);
}
