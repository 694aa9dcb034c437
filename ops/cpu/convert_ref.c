/* Scalar references of the fp16/bf16 <-> fp32 array conversions (round to nearest even). */
#include "kernels.h"

void mx_f16_to_f32_ref(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    (void)c;
    for (size_t i = 0; i < n; i++) y[i] = mx_half_to_float(x[i]);
}

void mx_f32_to_f16_ref(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    (void)c;
    for (size_t i = 0; i < n; i++) y[i] = mx_float_to_half(x[i]);
}

void mx_bf16_to_f32_ref(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    (void)c;
    for (size_t i = 0; i < n; i++) y[i] = mx_bf16_to_float(x[i]);
}

void mx_f32_to_bf16_ref(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    (void)c;
    for (size_t i = 0; i < n; i++) y[i] = mx_float_to_bf16(x[i]);
}
