/* The vector vocabulary of the shared SIMD kernel templates (*_simd.inc), AVX-512F flavour:
 * 16 floats per vector. Included only by *_avx512.c files (compiled with AVX-512 flags). */
#ifndef MX_SIMD_AVX512_H
#define MX_SIMD_AVX512_H

#include <immintrin.h>

#include "transpose_avx.h"

#define VL 16
#define KFN(name) name##_avx512
typedef __m512 vf;

static inline __mmask16 v_mask(int n) { return (__mmask16)(n >= 16 ? 0xffff : (1u << n) - 1); }
static inline vf v_load(const float *p) { return _mm512_loadu_ps(p); }
/* First n lanes from p, zeros after (reads nothing past p + n). */
static inline vf v_loadn(const float *p, int n) { return _mm512_maskz_loadu_ps(v_mask(n), p); }
static inline void v_store(float *p, vf v) { _mm512_storeu_ps(p, v); }
static inline void v_storen(float *p, vf v, int n) { _mm512_mask_storeu_ps(p, v_mask(n), v); }
/* lanes from n on set to 0 */
static inline vf v_firstn(vf v, int n) { return _mm512_maskz_mov_ps(v_mask(n), v); }
static inline vf v_set1(float x) { return _mm512_set1_ps(x); }
static inline vf v_zero(void) { return _mm512_setzero_ps(); }
static inline vf v_add(vf a, vf b) { return _mm512_add_ps(a, b); }
static inline vf v_sub(vf a, vf b) { return _mm512_sub_ps(a, b); }
static inline vf v_mul(vf a, vf b) { return _mm512_mul_ps(a, b); }
static inline vf v_div(vf a, vf b) { return _mm512_div_ps(a, b); }
static inline vf v_max(vf a, vf b) { return _mm512_max_ps(a, b); }
static inline vf v_min(vf a, vf b) { return _mm512_min_ps(a, b); }
static inline vf v_fmadd(vf a, vf b, vf c) { return _mm512_fmadd_ps(a, b, c); }
static inline vf v_abs(vf a) { return _mm512_abs_ps(a); }
/* a with the sign of s */
static inline vf v_copysign(vf a, vf s) {
    __m512i m = _mm512_set1_epi32((int)0x80000000u);
    return _mm512_castsi512_ps(_mm512_or_si512(_mm512_andnot_si512(m, _mm512_castps_si512(a)),
                                               _mm512_and_si512(m, _mm512_castps_si512(s))));
}
/* lanes where x < lo become 0 */
static inline vf v_zero_below(vf v, vf x, float lo) {
    return _mm512_maskz_mov_ps(_mm512_cmp_ps_mask(x, _mm512_set1_ps(lo), _CMP_NLT_UQ), v);
}
/* neg where x < 0, else pos */
static inline vf v_blend_negative(vf x, vf pos, vf neg) {
    return _mm512_mask_mov_ps(pos, _mm512_cmp_ps_mask(x, _mm512_setzero_ps(), _CMP_LT_OQ), neg);
}
/* 1 when some lane of a is greater than the same lane of b */
static inline int v_any_gt(vf a, vf b) { return _mm512_cmp_ps_mask(a, b, _CMP_GT_OQ) != 0; }
/* Horizontal reductions, fixed order (determinism). */
static inline float v_hsum(vf v) { return _mm512_reduce_add_ps(v); }
static inline float v_hmax(vf v) { return _mm512_reduce_max_ps(v); }
/* round to nearest integer and 2^n for integral n in [-126, 127] */
static inline vf v_round(vf x) { return _mm512_roundscale_ps(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC); }
static inline vf v_pow2i(vf n) {
    __m512i e = _mm512_add_epi32(_mm512_cvtps_epi32(n), _mm512_set1_epi32(127));
    return _mm512_castsi512_ps(_mm512_slli_epi32(e, 23));
}
/* the float whose bits are t's shifted left by 23: moves a biased exponent held in t's low bits
 * into the exponent field */
static inline vf v_shl23(vf t) { return _mm512_castsi512_ps(_mm512_slli_epi32(_mm512_castps_si512(t), 23)); }
/* a · 2^n for integral n (vscalefps): exact, 0 below the range, inf above; lets v_exp2 skip
 * building 2^n from bits and its upper clamp */
#define V_HAS_SCALEF 1
static inline vf v_scalef(vf a, vf n) { return _mm512_scalef_ps(a, n); }
/* dst[c*dst_ld + r] = src[r*src_ld + c] for r < rows, c < cols. */
static inline void v_transpose(float *dst, size_t dst_ld, const float *src, size_t src_ld, int rows, int cols) {
    transpose_avx(dst, dst_ld, src, src_ld, rows, cols);
}

#endif
