/* Block transpose with 4×4 NEON shuffles, for the GEMM packers and the attention key packing of
 * the aarch64 levels. */
#ifndef MX_TRANSPOSE_NEON_H
#define MX_TRANSPOSE_NEON_H

#include <arm_neon.h>
#include <stddef.h>

static inline void transpose_4x4_neon(float *dst, size_t dst_ld, const float *src, size_t src_ld) {
    float32x4_t r0 = vld1q_f32(src), r1 = vld1q_f32(src + src_ld);
    float32x4_t r2 = vld1q_f32(src + 2 * src_ld), r3 = vld1q_f32(src + 3 * src_ld);
    /* t0 = r0[0] r1[0] r0[2] r1[2], t1 = r0[1] r1[1] r0[3] r1[3]; t2, t3 the same of r2, r3 */
    float64x2_t t0 = vreinterpretq_f64_f32(vtrn1q_f32(r0, r1)), t1 = vreinterpretq_f64_f32(vtrn2q_f32(r0, r1));
    float64x2_t t2 = vreinterpretq_f64_f32(vtrn1q_f32(r2, r3)), t3 = vreinterpretq_f64_f32(vtrn2q_f32(r2, r3));
    vst1q_f32(dst, vreinterpretq_f32_f64(vtrn1q_f64(t0, t2)));
    vst1q_f32(dst + dst_ld, vreinterpretq_f32_f64(vtrn1q_f64(t1, t3)));
    vst1q_f32(dst + 2 * dst_ld, vreinterpretq_f32_f64(vtrn2q_f64(t0, t2)));
    vst1q_f32(dst + 3 * dst_ld, vreinterpretq_f32_f64(vtrn2q_f64(t1, t3)));
}

/* dst[c*dst_ld + r] = src[r*src_ld + c] for r < rows, c < cols. */
static inline void transpose_neon(float *dst, size_t dst_ld, const float *src, size_t src_ld, int rows, int cols) {
    int r = 0;
    for (; r + 4 <= rows; r += 4) {
        int c = 0;
        for (; c + 4 <= cols; c += 4)
            transpose_4x4_neon(dst + (size_t)c * dst_ld + r, dst_ld, src + (size_t)r * src_ld + c, src_ld);
        for (; c < cols; c++)
            for (int i = 0; i < 4; i++) dst[(size_t)c * dst_ld + r + i] = src[(size_t)(r + i) * src_ld + c];
    }
    for (; r < rows; r++)
        for (int c = 0; c < cols; c++) dst[(size_t)c * dst_ld + r] = src[(size_t)r * src_ld + c];
}

#endif
