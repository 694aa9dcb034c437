/* bf16 pairs for the aarch64 FEAT_BF16 kernels (gemm_neonbf16.c, attention_neonbf16.c): one 32-bit
 * word holds two bf16 (the lower index in the low half), the operand layout of BFDOT, which adds
 * a[2i]·b[2i] + a[2i+1]·b[2i+1] into fp32 lane i. Rounding to nearest even with integer
 * arithmetic, bit-exact with mx_float_to_bf16 (runtime/half.h) including NaN. The same
 * vocabulary as bf16_avx512.h for attention_lanes_simd.inc. Needs -march=...+bf16. */
#ifndef MX_BF16_NEON_H
#define MX_BF16_NEON_H

#include <arm_neon.h>
#include <stdint.h>

/* bf16 bits of each lane (in the low 16 bits of the word), rounded to nearest even. */
static inline uint32x4_t bf16_bits(float32x4_t f) {
    uint32x4_t b = vreinterpretq_u32_f32(f);
    uint32x4_t odd = vandq_u32(vshrq_n_u32(b, 16), vdupq_n_u32(1)); /* ties go to even */
    uint32x4_t r = vshrq_n_u32(vaddq_u32(vaddq_u32(b, vdupq_n_u32(0x7fff)), odd), 16);
    uint32x4_t q = vorrq_u32(vshrq_n_u32(b, 16), vdupq_n_u32(0x40)); /* quiet NaN */
    return vbslq_u32(vceqq_f32(f, f), r, q);
}

/* Words pairing lanes of two rows: w[c] = bf16(even[c]) | bf16(odd[c]) << 16. */
static inline uint32x4_t bf16_pairs_of_rows(float32x4_t even, float32x4_t odd) {
    return vorrq_u32(bf16_bits(even), vshlq_n_u32(bf16_bits(odd), 16));
}

/* dst[0 .. (n+1)/2) = pairs of src[0 .. n) (an odd last value paired with zero); reads nothing past n. */
static inline void bf16_pairs_row(uint32_t *dst, const float *src, int n) {
    int i = 0;
    for (; i + 8 <= n; i += 8) {
        float32x4x2_t eo = vld2q_f32(src + i); /* even and odd positions */
        vst1q_u32(dst + i / 2, bf16_pairs_of_rows(eo.val[0], eo.val[1]));
    }
    if (i < n) {
        float t[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        uint32_t w[4];
        for (int j = 0; j < n - i; j++) t[j] = src[i + j];
        float32x4x2_t eo = vld2q_f32(t);
        vst1q_u32(w, bf16_pairs_of_rows(eo.val[0], eo.val[1]));
        for (int j = 0; j < (n - i + 1) / 2; j++) dst[i / 2 + j] = w[j];
    }
}

/* 4 words of pairs and BFDOT. */
typedef bfloat16x8_t vbw;
static inline vbw vbw_load(const uint32_t *p) { return vreinterpretq_bf16_u32(vld1q_u32(p)); }
static inline vbw vbw_set1(uint32_t w) { return vreinterpretq_bf16_u32(vdupq_n_u32(w)); }
static inline float32x4_t v_dot_bf16(float32x4_t acc, vbw a, vbw b) { return vbfdotq_f32(acc, a, b); }
static inline void bf16_store_pairs_of_rows(uint32_t *dst, float32x4_t even, float32x4_t odd) {
    vst1q_u32(dst, bf16_pairs_of_rows(even, odd));
}

#endif
