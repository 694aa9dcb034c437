/* fp16/bf16 <-> fp32 array conversions, AVX-512: F16C-style vcvtph2ps/vcvtps2ph for fp16,
 * integer shifts with round-to-nearest-even for bf16 (no AVX512-BF16 needed). Bit-exact with
 * the scalar conversions in ops.c. */
#include <immintrin.h>

#include "kernels.h"

void mx_f16_to_f32_avx512(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    size_t i = 0;
    for (; i + 16 <= n; i += 16) _mm512_storeu_ps(y + i, _mm512_cvtph_ps(_mm256_loadu_si256((const __m256i *)(x + i))));
    mx_f16_to_f32_ref(c, y + i, x + i, n - i);
}

void mx_f32_to_f16_avx512(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    size_t i = 0;
    for (; i + 16 <= n; i += 16)
        _mm256_storeu_si256((__m256i *)(y + i), _mm512_cvtps_ph(_mm512_loadu_ps(x + i), _MM_FROUND_TO_NEAREST_INT));
    mx_f32_to_f16_ref(c, y + i, x + i, n - i);
}

void mx_bf16_to_f32_avx512(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    size_t i = 0;
    for (; i + 16 <= n; i += 16) {
        __m512i v = _mm512_cvtepu16_epi32(_mm256_loadu_si256((const __m256i *)(x + i)));
        _mm512_storeu_ps(y + i, _mm512_castsi512_ps(_mm512_slli_epi32(v, 16)));
    }
    mx_bf16_to_f32_ref(c, y + i, x + i, n - i);
}

void mx_f32_to_bf16_avx512(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    size_t i = 0;
    const __m512i one = _mm512_set1_epi32(1), bias = _mm512_set1_epi32(0x7fff);
    for (; i + 16 <= n; i += 16) {
        __m512 f = _mm512_loadu_ps(x + i);
        __m512i b = _mm512_castps_si512(f);
        __m512i odd = _mm512_and_si512(_mm512_srli_epi32(b, 16), one); /* ties go to even */
        __m512i r = _mm512_srli_epi32(_mm512_add_epi32(_mm512_add_epi32(b, bias), odd), 16);
        __m512i q = _mm512_or_si512(_mm512_srli_epi32(b, 16), _mm512_set1_epi32(0x40)); /* quiet NaN */
        r = _mm512_mask_mov_epi32(r, _mm512_cmp_ps_mask(f, f, _CMP_UNORD_Q), q);
        _mm256_storeu_si256((__m256i *)(y + i), _mm512_cvtepi32_epi16(r));
    }
    mx_f32_to_bf16_ref(c, y + i, x + i, n - i);
}
