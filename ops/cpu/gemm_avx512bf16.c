/* AVX512_BF16 GEMM: the AVX-512 micro-kernel (gemm_micro_avx512.inc) with vdpbf16ps, two k per
 * step (bf16 products summed in fp32), panels of bf16 k-pairs made by to_pairs, and linear +
 * conv2d on the GEMM engine. Note: vdpbf16ps and vcvtne2ps2bf16 treat bf16/fp32 denormals as
 * zero; the networks' activations and weights are far from that range. */
#include <immintrin.h>

#include "bf16_avx512.h"
#include "gemm.h"

#define MICRO_NAME micro_12x32_bf16
#define MICRO_STEPS(kc) (((kc) + 1) / 2)
#define ROW_FMA(i)                                                                                           \
    {                                                                                                        \
        __m512bh ai = (__m512bh)_mm512_set1_ps(a[i]); /* the row's k-pair word in every lane */          \
        c##i##0 = _mm512_dpbf16_ps(c##i##0, ai, (__m512bh)b0);                                              \
        c##i##1 = _mm512_dpbf16_ps(c##i##1, ai, (__m512bh)b1);                                              \
    }
#include "gemm_micro_avx512.inc"

/* Word c: bf16(even[c]) in the low half, bf16(odd[c]) (or 0) in the high. */
void mx_gemm_to_pairs_avx512bf16(uint32_t *dst, const float *even, const float *odd, int n) {
    for (int c = 0; c < n; c += 16) {
        __mmask16 m = bf16_mask(n - c);
        __m512 e = _mm512_maskz_loadu_ps(m, even + c);
        __m512 o = odd ? _mm512_maskz_loadu_ps(m, odd + c) : _mm512_setzero_ps();
        _mm512_mask_storeu_epi32(dst + c, m, bf16_pairs_of_rows(e, o));
    }
}

/* The same of the low parts (bf16_lo_part), for the AMX level's split products. */
void mx_gemm_to_pairs_lo_avx512bf16(uint32_t *dst, const float *even, const float *odd, int n) {
    for (int c = 0; c < n; c += 16) {
        __mmask16 m = bf16_mask(n - c);
        __m512 e = bf16_lo_part(_mm512_maskz_loadu_ps(m, even + c));
        __m512 o = odd ? bf16_lo_part(_mm512_maskz_loadu_ps(m, odd + c)) : _mm512_setzero_ps();
        _mm512_mask_storeu_epi32(dst + c, m, bf16_pairs_of_rows(e, o));
    }
}

static const mx_gemm_kernel kernel_avx512bf16 = {.mr = MR, .nr = NR, .micro = micro_12x32_bf16,
                                                 .add_bias = mx_gemm_add_bias_avx512, .widen = mx_gemm_widen_avx512,
                                                 .transpose = mx_gemm_transpose, .to_pairs = mx_gemm_to_pairs_avx512bf16,
                                                 .row_pairs = bf16_pairs_row, .pair_align = 1,
                                                 .micro_rows = micro_12x32_bf16_rows,
                                                 .micro_bias = micro_12x32_bf16_bias};

void mx_linear_avx512bf16(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    mx_gemm_linear(c, &kernel_avx512bf16, y, x, w, bias, M, N, K);
}

void mx_conv2d_avx512bf16(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                          mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    mx_gemm_conv2d(c, &kernel_avx512bf16, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad);
}

void mx_conv2d_up2x_avx512bf16(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                               mx_wptr bias, int Cout) {
    mx_gemm_conv2d_up2x(c, &kernel_avx512bf16, y, x, B, Cin, H, W, w, bias, Cout);
}
