/* aarch64 FEAT_BF16 GEMM: the NEON micro-kernel (gemm_micro_neon.inc) with BFDOT by element, one
 * k-pair per step (bf16 products summed in fp32), panels of bf16 k-pairs made by to_pairs, and
 * linear + conv2d on the GEMM engine. BFDOT (without FEAT_EBF16) flushes denormal inputs to zero
 * and rounds its pair sum to odd before the fp32 add: within the bf16 level's bounds, and the
 * networks' activations and weights are far from the denormal range. */
#include <arm_neon.h>

#include "bf16_neon.h"
#include "gemm.h"
#include "transpose_neon.h"

#define MICRO_NAME micro_8x12_bf16
#define MICRO_STEPS(kc) (((kc) + 1) / 2)
#define MICRO_VEC bfloat16x8_t
#define MICRO_LOAD(p) vreinterpretq_bf16_u32(vld1q_u32(p))
#define MICRO_FMA(acc, b, a, lane) vbfdotq_laneq_f32(acc, b, a, lane)
#include "gemm_micro_neon.inc"

/* Word c: bf16(even[c]) in the low half, bf16(odd[c]) (or 0) in the high. */
static void to_pairs_neonbf16(uint32_t *dst, const float *even, const float *odd, int n) {
    int c = 0;
    for (; c + 4 <= n; c += 4)
        vst1q_u32(dst + c, bf16_pairs_of_rows(vld1q_f32(even + c), odd ? vld1q_f32(odd + c) : vdupq_n_f32(0)));
    for (; c < n; c++) dst[c] = (uint32_t)mx_float_to_bf16(even[c]) | (uint32_t)(odd ? mx_float_to_bf16(odd[c]) : 0) << 16;
}

static const mx_gemm_kernel kernel_neonbf16 = {.mr = MR, .nr = NR, .micro = micro_8x12_bf16, .add_bias = mx_gemm_add_bias_neon,
                                               .widen = mx_gemm_widen_neon, .transpose = transpose_neon,
                                               .to_pairs = to_pairs_neonbf16, .row_pairs = bf16_pairs_row, .pair_align = 1};

void mx_linear_neonbf16(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    mx_gemm_linear(c, &kernel_neonbf16, y, x, w, bias, M, N, K);
}

void mx_conv2d_neonbf16(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                        mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    mx_gemm_conv2d(c, &kernel_neonbf16, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad);
}

void mx_conv2d_up2x_neonbf16(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                             mx_wptr bias, int Cout) {
    mx_gemm_conv2d_up2x(c, &kernel_neonbf16, y, x, B, Cin, H, W, w, bias, Cout);
}
