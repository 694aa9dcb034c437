/* fp16/bf16 <-> fp32 array conversions, aarch64 NEON: FCVTL/FCVTN for fp16 (round to nearest even,
 * NaN made quiet with its payload kept, as the scalar conversion), integer shifts with
 * round-to-nearest-even for bf16. Bit-exact with the scalar conversions (runtime/half.h). */
#include <arm_neon.h>

#include "kernels.h"

void mx_f16_to_f32_neon(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    size_t i = 0;
    for (; i + 4 <= n; i += 4) vst1q_f32(y + i, vcvt_f32_f16(vreinterpret_f16_u16(vld1_u16(x + i))));
    mx_f16_to_f32_ref(c, y + i, x + i, n - i);
}

void mx_f32_to_f16_neon(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    size_t i = 0;
    for (; i + 4 <= n; i += 4) vst1_u16(y + i, vreinterpret_u16_f16(vcvt_f16_f32(vld1q_f32(x + i))));
    mx_f32_to_f16_ref(c, y + i, x + i, n - i);
}

void mx_bf16_to_f32_neon(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    size_t i = 0;
    for (; i + 4 <= n; i += 4) vst1q_f32(y + i, vreinterpretq_f32_u32(vshll_n_u16(vld1_u16(x + i), 16)));
    mx_bf16_to_f32_ref(c, y + i, x + i, n - i);
}

void mx_f32_to_bf16_neon(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    size_t i = 0;
    for (; i + 4 <= n; i += 4) {
        float32x4_t f = vld1q_f32(x + i);
        uint32x4_t b = vreinterpretq_u32_f32(f);
        uint32x4_t odd = vandq_u32(vshrq_n_u32(b, 16), vdupq_n_u32(1)); /* ties go to even */
        uint32x4_t r = vshrq_n_u32(vaddq_u32(vaddq_u32(b, vdupq_n_u32(0x7fff)), odd), 16);
        uint32x4_t q = vorrq_u32(vshrq_n_u32(b, 16), vdupq_n_u32(0x40)); /* quiet NaN */
        vst1_u16(y + i, vmovn_u32(vbslq_u32(vceqq_f32(f, f), r, q)));
    }
    mx_f32_to_bf16_ref(c, y + i, x + i, n - i);
}
