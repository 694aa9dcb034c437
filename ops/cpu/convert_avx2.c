/* fp16/bf16 <-> fp32 array conversions, AVX2 + F16C: vcvtph2ps/vcvtps2ph for fp16, integer
 * shifts with round-to-nearest-even for bf16. Bit-exact with the scalar conversions in ops.c. */
#include <immintrin.h>

#include "kernels.h"

void mx_f16_to_f32_avx2(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    size_t i = 0;
    for (; i + 8 <= n; i += 8) _mm256_storeu_ps(y + i, _mm256_cvtph_ps(_mm_loadu_si128((const __m128i *)(x + i))));
    mx_f16_to_f32_ref(c, y + i, x + i, n - i);
}

void mx_f32_to_f16_avx2(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    size_t i = 0;
    for (; i + 8 <= n; i += 8)
        _mm_storeu_si128((__m128i *)(y + i), _mm256_cvtps_ph(_mm256_loadu_ps(x + i), _MM_FROUND_TO_NEAREST_INT));
    mx_f32_to_f16_ref(c, y + i, x + i, n - i);
}

void mx_bf16_to_f32_avx2(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        __m256i v = _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)(x + i)));
        _mm256_storeu_ps(y + i, _mm256_castsi256_ps(_mm256_slli_epi32(v, 16)));
    }
    mx_bf16_to_f32_ref(c, y + i, x + i, n - i);
}

void mx_f32_to_bf16_avx2(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    size_t i = 0;
    const __m256i one = _mm256_set1_epi32(1), bias = _mm256_set1_epi32(0x7fff);
    for (; i + 8 <= n; i += 8) {
        __m256 f = _mm256_loadu_ps(x + i);
        __m256i b = _mm256_castps_si256(f);
        __m256i odd = _mm256_and_si256(_mm256_srli_epi32(b, 16), one); /* ties go to even */
        __m256i r = _mm256_srli_epi32(_mm256_add_epi32(_mm256_add_epi32(b, bias), odd), 16);
        __m256i q = _mm256_or_si256(_mm256_srli_epi32(b, 16), _mm256_set1_epi32(0x40)); /* quiet NaN */
        r = _mm256_blendv_epi8(r, q, _mm256_castps_si256(_mm256_cmp_ps(f, f, _CMP_UNORD_Q)));
        /* pack 8 × 32-bit (values < 65536) to 16-bit: packus works per 128-bit lane, then fix the order */
        __m256i p = _mm256_permute4x64_epi64(_mm256_packus_epi32(r, r), 0xd8);
        _mm_storeu_si128((__m128i *)(y + i), _mm256_castsi256_si128(p));
    }
    mx_f32_to_bf16_ref(c, y + i, x + i, n - i);
}
