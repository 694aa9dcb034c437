/* The one fp16 / bf16 <-> fp32 scalar conversion of matex (weight readers and writers, the
 * golden rule, the scalar reference kernels). Narrowing rounds to nearest even, as torch's
 * .half() / .bfloat16() do; overflow goes to infinity; NaN stays NaN, made quiet, its payload
 * kept where it fits. The SIMD kernels (ops/cpu/convert_*.c) agree bit for bit (tested). */
#ifndef MX_HALF_H
#define MX_HALF_H

#include <stdint.h>
#include <string.h>

static inline uint32_t mx_f32_bits(float f) {
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}

static inline float mx_bits_f32(uint32_t u) {
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

static inline float mx_half_to_float(uint16_t h) {
    uint32_t sign = (uint32_t)(h & 0x8000) << 16, e = (h >> 10) & 0x1f, m = h & 0x3ff;
    if (e == 0) {
        float v = (float)m * (1.0f / 16777216.0f); /* subnormal: m · 2^-24, exact */
        return mx_bits_f32(mx_f32_bits(v) | sign);
    }
    if (e == 31) return mx_bits_f32(sign | 0x7f800000u | (m ? 0x400000u | (m << 13) : 0)); /* NaN comes out quiet */
    return mx_bits_f32(sign | ((e + 112) << 23) | (m << 13));
}

static inline uint16_t mx_float_to_half(float f) {
    uint32_t x = mx_f32_bits(f), sign = (x >> 16) & 0x8000;
    x &= 0x7fffffffu;
    if (x > 0x7f800000u) return (uint16_t)(sign | 0x7e00 | ((x >> 13) & 0x3ff)); /* NaN stays NaN */
    if (x >= 0x477ff000u) return (uint16_t)(sign | 0x7c00);                     /* >= 65520 rounds to infinity */
    if (x < 0x38800000u) {
        /* half subnormal: adding 0.5 puts the 2^-24 grid in the low mantissa bits; the FPU rounds */
        float t = mx_bits_f32(x) + 0.5f;
        return (uint16_t)(sign | (mx_f32_bits(t) - 0x3f000000u));
    }
    uint32_t odd = (x >> 13) & 1;
    x += 0xc8000fffu + odd; /* rebias exponent (127 -> 15) and round to nearest even */
    return (uint16_t)(sign | (x >> 13));
}

static inline float mx_bf16_to_float(uint16_t h) { return mx_bits_f32((uint32_t)h << 16); }

static inline uint16_t mx_float_to_bf16(float f) {
    uint32_t x = mx_f32_bits(f);
    if ((x & 0x7fffffffu) > 0x7f800000u) return (uint16_t)((x >> 16) | 0x40); /* quiet NaN */
    return (uint16_t)((x + 0x7fffu + ((x >> 16) & 1)) >> 16);
}

#endif
