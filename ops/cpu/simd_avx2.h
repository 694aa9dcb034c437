/* The vector vocabulary of the shared SIMD kernel templates (*_simd.inc), AVX2+FMA flavour:
 * 8 floats per vector. Included only by *_avx2.c files (compiled with AVX2 flags). */
#ifndef MX_SIMD_AVX2_H
#define MX_SIMD_AVX2_H

#include <immintrin.h>

#include "transpose_avx.h"

#define VL 8
#define KFN(name) name##_avx2
typedef __m256 vf;

static inline __m256i v_mask(int n) {
    return _mm256_cmpgt_epi32(_mm256_set1_epi32(n), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
}
static inline vf v_load(const float *p) { return _mm256_loadu_ps(p); }
/* First n lanes from p, zeros after (masked lanes are not read). */
static inline vf v_loadn(const float *p, int n) { return _mm256_maskload_ps(p, v_mask(n)); }
static inline void v_store(float *p, vf v) { _mm256_storeu_ps(p, v); }
static inline void v_storen(float *p, vf v, int n) { _mm256_maskstore_ps(p, v_mask(n), v); }
/* lanes from n on set to 0 */
static inline vf v_firstn(vf v, int n) { return _mm256_and_ps(v, _mm256_castsi256_ps(v_mask(n))); }
static inline vf v_set1(float x) { return _mm256_set1_ps(x); }
static inline vf v_zero(void) { return _mm256_setzero_ps(); }
static inline vf v_add(vf a, vf b) { return _mm256_add_ps(a, b); }
static inline vf v_sub(vf a, vf b) { return _mm256_sub_ps(a, b); }
static inline vf v_mul(vf a, vf b) { return _mm256_mul_ps(a, b); }
static inline vf v_div(vf a, vf b) { return _mm256_div_ps(a, b); }
static inline vf v_max(vf a, vf b) { return _mm256_max_ps(a, b); }
static inline vf v_min(vf a, vf b) { return _mm256_min_ps(a, b); }
static inline vf v_fmadd(vf a, vf b, vf c) { return _mm256_fmadd_ps(a, b, c); }
static inline vf v_abs(vf a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), a); }
static inline vf v_copysign(vf a, vf s) {
    vf m = _mm256_set1_ps(-0.0f);
    return _mm256_or_ps(_mm256_andnot_ps(m, a), _mm256_and_ps(m, s));
}
static inline vf v_zero_below(vf v, vf x, float lo) {
    return _mm256_and_ps(v, _mm256_cmp_ps(x, _mm256_set1_ps(lo), _CMP_NLT_UQ));
}
/* neg where x < 0, else pos */
static inline vf v_blend_negative(vf x, vf pos, vf neg) {
    return _mm256_blendv_ps(pos, neg, _mm256_cmp_ps(x, _mm256_setzero_ps(), _CMP_LT_OQ));
}
/* 1 when some lane of a is greater than the same lane of b */
static inline int v_any_gt(vf a, vf b) { return _mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_GT_OQ)) != 0; }
static inline float v_hsum(vf v) {
    __m128 s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
    s = _mm_add_ps(s, _mm_movehl_ps(s, s));
    s = _mm_add_ss(s, _mm_movehdup_ps(s));
    return _mm_cvtss_f32(s);
}
static inline float v_hmax(vf v) {
    __m128 s = _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
    s = _mm_max_ps(s, _mm_movehl_ps(s, s));
    s = _mm_max_ss(s, _mm_movehdup_ps(s));
    return _mm_cvtss_f32(s);
}
static inline vf v_round(vf x) { return _mm256_round_ps(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC); }
static inline vf v_pow2i(vf n) {
    __m256i e = _mm256_add_epi32(_mm256_cvtps_epi32(n), _mm256_set1_epi32(127));
    return _mm256_castsi256_ps(_mm256_slli_epi32(e, 23));
}
/* the float whose bits are t's shifted left by 23: moves a biased exponent held in t's low bits
 * into the exponent field */
static inline vf v_shl23(vf t) { return _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_castps_si256(t), 23)); }
/* dst[c*dst_ld + r] = src[r*src_ld + c] for r < rows, c < cols. */
static inline void v_transpose(float *dst, size_t dst_ld, const float *src, size_t src_ld, int rows, int cols) {
    transpose_avx(dst, dst_ld, src, src_ld, rows, cols);
}

#endif
