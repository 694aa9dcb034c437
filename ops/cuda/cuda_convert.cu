/* fp16 / bf16 <-> fp32 conversions, round to nearest even (the cuda_fp16/cuda_bf16 _rn intrinsics). */
#include "cuda_common.cuh"


__global__ void f16_to_f32_kernel(float *y, const __half *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = __half2float(x[i]);
}
__global__ void f32_to_f16_kernel(__half *y, const float *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = __float2half_rn(x[i]);
}
__global__ void bf16_to_f32_kernel(float *y, const __nv_bfloat16 *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = __bfloat162float(x[i]);
}
__global__ void f32_to_bf16_kernel(__nv_bfloat16 *y, const float *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = __float2bfloat16_rn(x[i]);
}

int mx_cuda_f16_to_f32(mx_cuda_ctx *c, float *y, const uint16_t *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    f16_to_f32_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, (const __half *)x, n);
    return mx_cuda_launched("cuda f16_to_f32", st);
}

int mx_cuda_f32_to_f16(mx_cuda_ctx *c, uint16_t *y, const float *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    f32_to_f16_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>((__half *)y, x, n);
    return mx_cuda_launched("cuda f32_to_f16", st);
}

int mx_cuda_bf16_to_f32(mx_cuda_ctx *c, float *y, const uint16_t *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    bf16_to_f32_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, (const __nv_bfloat16 *)x, n);
    return mx_cuda_launched("cuda bf16_to_f32", st);
}

int mx_cuda_f32_to_bf16(mx_cuda_ctx *c, uint16_t *y, const float *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    f32_to_bf16_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>((__nv_bfloat16 *)y, x, n);
    return mx_cuda_launched("cuda f32_to_bf16", st);
}
