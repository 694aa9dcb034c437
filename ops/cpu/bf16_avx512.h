/* bf16 pair packing for the AVX512_BF16 kernels (gemm_avx512bf16.c, attention_avx512bf16.c): one
 * 32-bit word holds two bf16 (the lower index in the low half), the operand layout of vdpbf16ps.
 * Rounding to nearest even by vcvtne2ps2bf16 (which, like vdpbf16ps, reads denormals as zero).
 * The bf16 vocabulary of attention_lanes_simd.inc (vbw, vbw_load, vbw_set1, v_dot_bf16,
 * bf16_pairs_row, bf16_store_pairs_of_rows) is the same in bf16_neon.h; bf16_store_pairs_of_keys
 * is the AMX attention's. */
#ifndef MX_BF16_AVX512_H
#define MX_BF16_AVX512_H

#include <immintrin.h>
#include <stdint.h>

static inline __mmask16 bf16_mask(int n) { return (__mmask16)(n >= 16 ? 0xffff : n <= 0 ? 0 : (1u << n) - 1); }

/* 16 words of pairs from the first n (<= 32) floats of src, zeros after; reads nothing past n. */
static inline __m512i bf16_pairs16(const float *src, int n) {
    __m512 lo = _mm512_maskz_loadu_ps(bf16_mask(n), src);
    __m512 hi = n > 16 ? _mm512_maskz_loadu_ps(bf16_mask(n - 16), src + 16) : _mm512_setzero_ps();
    return (__m512i)_mm512_cvtne2ps_pbh(hi, lo);
}

/* x - bf16(x) for 16 lanes, bf16 by vcvtneps2bf16 (nearest even, denormals as zero): the part a
 * bf16 rounding drops, the low operand of a split product (gemm.h: split kernels); 0 where
 * bf16(x) is not finite. */
static inline __m512 bf16_lo_part(__m512 x) {
    __m512i h = _mm512_cvtepu16_epi32((__m256i)_mm512_cvtneps_pbh(x));
    __m512 hi = _mm512_castsi512_ps(_mm512_slli_epi32(h, 16));
    __mmask16 finite = _mm512_cmp_ps_mask(_mm512_abs_ps(hi), _mm512_set1_ps(__builtin_inff()), _CMP_LT_OQ);
    return _mm512_maskz_sub_ps(finite, x, hi);
}

/* dst[0 .. (n+1)/2) = pairs of the low parts of src[0 .. n) (bf16_lo_part). */
static inline void bf16_pairs_row_lo(uint32_t *dst, const float *src, int n) {
    for (int i = 0; i < n; i += 32) {
        __m512 lo = bf16_lo_part(_mm512_maskz_loadu_ps(bf16_mask(n - i), src + i));
        __m512 hi = n - i > 16 ? bf16_lo_part(_mm512_maskz_loadu_ps(bf16_mask(n - i - 16), src + i + 16))
                               : _mm512_setzero_ps();
        _mm512_mask_storeu_epi32(dst + i / 2, bf16_mask((n - i + 1) / 2), (__m512i)_mm512_cvtne2ps_pbh(hi, lo));
    }
}

/* dst[0 .. (n+1)/2) = pairs of src[0 .. n) (an odd last value paired with zero). */
static inline void bf16_pairs_row(uint32_t *dst, const float *src, int n) {
    for (int i = 0; i < n; i += 32)
        _mm512_mask_storeu_epi32(dst + i / 2, bf16_mask((n - i + 1) / 2), bf16_pairs16(src + i, n - i));
}

/* Words pairing lanes of two rows: w[c] = bf16(even[c]) | bf16(odd[c]) << 16 for 16 columns. */
static inline __m512i bf16_pairs_of_rows(__m512 even, __m512 odd) {
    /* vcvtne2ps2bf16(odd, even) holds even's 16 values, then odd's: interleave them */
    const __m512i interleave = _mm512_set_epi16(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8, 23, 7,
                                                22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
    return _mm512_permutexvar_epi16(interleave, (__m512i)_mm512_cvtne2ps_pbh(odd, even));
}

/* 16 words of pairs (vdpbf16ps operands) and the dot product acc[i] += a[2i]·b[2i] + a[2i+1]·b[2i+1]. */
typedef __m512bh vbw;
static inline vbw vbw_load(const uint32_t *p) { return (__m512bh)_mm512_loadu_si512(p); }
static inline vbw vbw_set1(uint32_t w) { return (__m512bh)_mm512_set1_epi32((int)w); }
static inline __m512 v_dot_bf16(__m512 acc, vbw a, vbw b) { return _mm512_dpbf16_ps(acc, a, b); }
/* dst[c] = bf16(even[c]) | bf16(odd[c]) << 16 for the 16 lanes. */
static inline void bf16_store_pairs_of_rows(uint32_t *dst, __m512 even, __m512 odd) {
    _mm512_storeu_si512(dst, bf16_pairs_of_rows(even, odd));
}
/* dst[i] = bf16(lo_hi[2i]) | bf16(lo_hi[2i+1]) << 16 for the 2·16 values of lo then hi. */
static inline void bf16_store_pairs_of_keys(uint32_t *dst, __m512 lo, __m512 hi) {
    _mm512_storeu_si512(dst, (__m512i)_mm512_cvtne2ps_pbh(hi, lo));
}

#endif
