/* fp16 / bf16 <-> fp32 by bit manipulation, shared by the weight readers and writers (kept
 * here so that libmx_weights does not depend on the op kernels). Narrowing rounds to nearest
 * even, as torch's .half() / .bfloat16() do; NaN stays NaN. */
#ifndef MX_HALFBITS_H
#define MX_HALFBITS_H

#include <stdint.h>
#include <string.h>

static inline uint32_t mx_hb_f32_bits(float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    return u;
}

static inline float mx_hb_bits_f32(uint32_t u) {
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static inline float mx_hb_f16_to_f32(uint16_t h) {
    uint32_t sign = (uint32_t)(h & 0x8000) << 16, exp = (h >> 10) & 0x1F, man = h & 0x3FF;
    if (exp == 0x1F) return mx_hb_bits_f32(sign | 0x7F800000u | (man << 13));
    if (exp == 0) {
        if (man == 0) return mx_hb_bits_f32(sign);
        /* subnormal: man * 2^-24, exact in fp32 */
        float v = (float)man * (1.0f / 16777216.0f);
        return sign ? -v : v;
    }
    return mx_hb_bits_f32(sign | ((exp + 112) << 23) | (man << 13));
}

static inline uint16_t mx_hb_f32_to_f16(float f) {
    uint32_t u = mx_hb_f32_bits(f);
    uint16_t sign = (uint16_t)((u >> 16) & 0x8000);
    uint32_t a = u & 0x7FFFFFFFu;
    if (a > 0x7F800000u) return (uint16_t)(sign | 0x7E00); /* NaN */
    if (a >= 0x477FF000u) return (uint16_t)(sign | 0x7C00); /* rounds to >= 65520: inf */
    if (a < 0x38800000u) {
        /* result is subnormal (or zero): scale by 2^24 and round to an integer, RNE */
        if (a < 0x33000000u) return sign; /* below half the smallest subnormal */
        uint32_t exp = a >> 23, man = (a & 0x7FFFFF) | 0x800000;
        uint32_t shift = 126 - exp; /* 14..24 */
        uint32_t q = man >> shift, rem = man & ((1u << shift) - 1), half = 1u << (shift - 1);
        if (rem > half || (rem == half && (q & 1))) q++;
        return (uint16_t)(sign | q);
    }
    uint32_t r = a + 0xFFF + ((a >> 13) & 1); /* round to nearest even at bit 13 */
    return (uint16_t)(sign | ((r - 0x38000000u) >> 13));
}

static inline float mx_hb_bf16_to_f32(uint16_t h) { return mx_hb_bits_f32((uint32_t)h << 16); }

static inline uint16_t mx_hb_f32_to_bf16(float f) {
    uint32_t u = mx_hb_f32_bits(f);
    if ((u & 0x7FFFFFFFu) > 0x7F800000u) return (uint16_t)((u >> 16) | 0x40);
    return (uint16_t)((u + 0x7FFF + ((u >> 16) & 1)) >> 16);
}

#endif
