/* Activations: GELU (erf), quick-GELU (CLIP), SiLU, GEGLU (diffusers), and tanh (TAESD's latent
 * clamp) in double as the CPU reference, rounded once to float. */
#include "cuda_common.cuh"

#define EW_THREADS 256

__device__ __forceinline__ float gelu_f(float v) { return 0.5f * v * (1.0f + erff(v * 0.70710678118654752f)); }

__global__ void gelu_kernel(float *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) x[i] = gelu_f(x[i]);
}
__global__ void quick_gelu_kernel(float *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) x[i] = x[i] / (1.0f + expf(-1.702f * x[i]));
}
__global__ void silu_kernel(float *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) x[i] = x[i] / (1.0f + expf(-x[i]));
}
/* x[M, 2N] = [h | g] -> y[M, N] = h * gelu(g). */
__global__ void geglu_kernel(float *y, const float *x, int N, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t row = i / (size_t)N, col = i % (size_t)N;
        const float *xr = x + row * 2 * (size_t)N;
        y[i] = xr[col] * gelu_f(xr[N + col]);
    }
}
__global__ void tanh_kernel(float *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) x[i] = (float)tanh((double)x[i]);
}

int mx_cuda_gelu(mx_cuda_ctx *c, float *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    gelu_kernel<<<mx_cuda_blocks(n, EW_THREADS), EW_THREADS, 0, c->stream>>>(x, n);
    return mx_cuda_launched("cuda gelu", st);
}

int mx_cuda_quick_gelu(mx_cuda_ctx *c, float *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    quick_gelu_kernel<<<mx_cuda_blocks(n, EW_THREADS), EW_THREADS, 0, c->stream>>>(x, n);
    return mx_cuda_launched("cuda quick_gelu", st);
}

int mx_cuda_silu(mx_cuda_ctx *c, float *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    silu_kernel<<<mx_cuda_blocks(n, EW_THREADS), EW_THREADS, 0, c->stream>>>(x, n);
    return mx_cuda_launched("cuda silu", st);
}

int mx_cuda_geglu(mx_cuda_ctx *c, float *y, const float *x, int M, int N, mx_status *st) {
    const long long dims[2] = {M, N};
    if (mx_cuda_check_dims("cuda geglu", st, 2, dims)) return -1;
    size_t n = (size_t)M * N;
    geglu_kernel<<<mx_cuda_blocks(n, EW_THREADS), EW_THREADS, 0, c->stream>>>(y, x, N, n);
    return mx_cuda_launched("cuda geglu", st);
}

int mx_cuda_tanh(mx_cuda_ctx *c, float *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    tanh_kernel<<<mx_cuda_blocks(n, EW_THREADS), EW_THREADS, 0, c->stream>>>(x, n);
    return mx_cuda_launched("cuda tanh", st);
}
