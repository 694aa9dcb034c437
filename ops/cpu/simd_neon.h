/* The vector vocabulary of the shared SIMD kernel templates (*_simd.inc), aarch64 NEON (Advanced
 * SIMD) flavour: 4 floats per vector. Included only by *_neon.c and *_neonbf16.c files. NEON has no
 * masked loads: partial vectors go through a small zeroed buffer, so nothing past n is touched. */
#ifndef MX_SIMD_NEON_H
#define MX_SIMD_NEON_H

#include <arm_neon.h>

#include "transpose_neon.h"

#define VL 4
#define KFN(name) name##_neon
typedef float32x4_t vf;

static inline uint32x4_t v_mask(int n) {
    const int32_t lane[4] = {0, 1, 2, 3};
    return vcltq_s32(vld1q_s32(lane), vdupq_n_s32(n));
}
static inline vf v_load(const float *p) { return vld1q_f32(p); }
/* First n lanes from p, zeros after (reads nothing past p + n). */
static inline vf v_loadn(const float *p, int n) {
    if (n >= VL) return vld1q_f32(p);
    float t[VL] = {0, 0, 0, 0};
    for (int i = 0; i < n; i++) t[i] = p[i];
    return vld1q_f32(t);
}
static inline void v_store(float *p, vf v) { vst1q_f32(p, v); }
static inline void v_storen(float *p, vf v, int n) {
    if (n >= VL) {
        vst1q_f32(p, v);
        return;
    }
    float t[VL];
    vst1q_f32(t, v);
    for (int i = 0; i < n; i++) p[i] = t[i];
}
/* lanes from n on set to 0 */
static inline vf v_firstn(vf v, int n) { return vreinterpretq_f32_u32(vandq_u32(vreinterpretq_u32_f32(v), v_mask(n))); }
static inline vf v_set1(float x) { return vdupq_n_f32(x); }
static inline vf v_zero(void) { return vdupq_n_f32(0.0f); }
static inline vf v_add(vf a, vf b) { return vaddq_f32(a, b); }
static inline vf v_sub(vf a, vf b) { return vsubq_f32(a, b); }
static inline vf v_mul(vf a, vf b) { return vmulq_f32(a, b); }
static inline vf v_div(vf a, vf b) { return vdivq_f32(a, b); }
static inline vf v_max(vf a, vf b) { return vmaxq_f32(a, b); }
static inline vf v_min(vf a, vf b) { return vminq_f32(a, b); }
static inline vf v_fmadd(vf a, vf b, vf c) { return vfmaq_f32(c, a, b); }
static inline vf v_abs(vf a) { return vabsq_f32(a); }
/* a with the sign of s */
static inline vf v_copysign(vf a, vf s) { return vbslq_f32(vdupq_n_u32(0x80000000u), s, a); }
/* lanes where x < lo become 0 (NaN lanes kept, as the x86 vocabularies' not-less-than compare) */
static inline vf v_zero_below(vf v, vf x, float lo) {
    return vreinterpretq_f32_u32(vbicq_u32(vreinterpretq_u32_f32(v), vcltq_f32(x, vdupq_n_f32(lo))));
}
/* neg where x < 0, else pos */
static inline vf v_blend_negative(vf x, vf pos, vf neg) { return vbslq_f32(vcltq_f32(x, vdupq_n_f32(0.0f)), neg, pos); }
/* 1 when some lane of a is greater than the same lane of b */
static inline int v_any_gt(vf a, vf b) { return vmaxvq_u32(vcgtq_f32(a, b)) != 0; }
/* Horizontal reductions, fixed order (determinism): pairwise. */
static inline float v_hsum(vf v) { return vaddvq_f32(v); }
static inline float v_hmax(vf v) { return vmaxvq_f32(v); }
/* round to nearest integer (ties to even) and 2^n for integral n in [-126, 127] */
static inline vf v_round(vf x) { return vrndnq_f32(x); }
static inline vf v_pow2i(vf n) {
    int32x4_t e = vaddq_s32(vcvtq_s32_f32(n), vdupq_n_s32(127));
    return vreinterpretq_f32_s32(vshlq_n_s32(e, 23));
}
/* the float whose bits are t's shifted left by 23: moves a biased exponent held in t's low bits
 * into the exponent field */
static inline vf v_shl23(vf t) { return vreinterpretq_f32_u32(vshlq_n_u32(vreinterpretq_u32_f32(t), 23)); }
/* dst[c*dst_ld + r] = src[r*src_ld + c] for r < rows, c < cols. */
static inline void v_transpose(float *dst, size_t dst_ld, const float *src, size_t src_ld, int rows, int cols) {
    transpose_neon(dst, dst_ld, src, src_ld, rows, cols);
}

#endif
