/* aarch64 NEON GEMM micro-kernel (gemm_micro_neon.inc with fp32 FMLA by element, one k per step),
 * weight widening (FCVTL for fp16, shifts for bf16; shared with the bf16 level), and linear +
 * conv2d on the GEMM engine. */
#include <arm_neon.h>

#include "gemm.h"
#include "simd_neon.h"
#include "transpose_neon.h"

#define MICRO_NAME micro_8x12
#define MICRO_STEPS(kc) (kc)
#define MICRO_VEC float32x4_t
#define MICRO_LOAD(p) vreinterpretq_f32_u32(vld1q_u32(p))
#define MICRO_FMA(acc, b, a, lane) vfmaq_laneq_f32(acc, b, a, lane)
#include "gemm_micro_neon.inc"

void mx_gemm_widen_neon(float *y, mx_wptr w, size_t off, size_t n) {
    const uint16_t *x = (const uint16_t *)w.data + off;
    size_t i = 0;
    if (w.dtype == MX_F16)
        for (; i + 4 <= n; i += 4) vst1q_f32(y + i, vcvt_f32_f16(vreinterpret_f16_u16(vld1_u16(x + i))));
    else
        for (; i + 4 <= n; i += 4) vst1q_f32(y + i, vreinterpretq_f32_u32(vshll_n_u16(vld1_u16(x + i), 16)));
    for (; i < n; i++) y[i] = mx_w_get(w, off + i);
}

#include "gemm_bias_simd.inc"

static const mx_gemm_kernel kernel_neon = {.mr = MR, .nr = NR, .micro = micro_8x12, .add_bias = mx_gemm_add_bias_neon,
                                          .widen = mx_gemm_widen_neon, .transpose = transpose_neon};

void mx_linear_neon(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    mx_gemm_linear(c, &kernel_neon, y, x, w, bias, M, N, K);
}

void mx_conv2d_neon(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                    mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    mx_gemm_conv2d(c, &kernel_neon, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad);
}

void mx_conv2d_up2x_neon(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                         mx_wptr bias, int Cout) {
    mx_gemm_conv2d_up2x(c, &kernel_neon, y, x, B, Cin, H, W, w, bias, Cout);
}
