/* Group norm (+ fused SiLU) and layer norm: one thread block per normalised group or row, two passes over the data (mean, then the squared deviations) as in the CPU reference, so
 * that large means do not cost precision. */
#include "cuda_common.cuh"

#define NORM_THREADS 512

__device__ __forceinline__ float silu_f(float v) { return v / (1.0f + expf(-v)); }

/* Block (b, g) normalises x[b, g*cpg .. (g+1)*cpg, HW], which is contiguous in NCHW. */
__global__ void group_norm_kernel(float *y, const float *x, int C, long long HW, int groups, const void *gamma,
                                  int gamma_dt, const void *beta, int beta_dt, float eps, int fuse_silu) {
    __shared__ float shm[32];
    int b = blockIdx.x / groups, g = blockIdx.x % groups, cpg = C / groups;
    long long n = (long long)cpg * HW, base = ((long long)b * C + (long long)g * cpg) * HW;
    const float *xg = x + base;
    float s = 0.0f;
    for (long long i = threadIdx.x; i < n; i += blockDim.x) s += xg[i];
    float mean = mx_cuda_block_sum(s, shm) / (float)n;
    float q = 0.0f;
    for (long long i = threadIdx.x; i < n; i += blockDim.x) {
        float d = xg[i] - mean;
        q += d * d;
    }
    float rstd = 1.0f / sqrtf(mx_cuda_block_sum(q, shm) / (float)n + eps);
    for (long long i = threadIdx.x; i < n; i += blockDim.x) {
        int ch = g * cpg + (int)(i / HW);
        float v = (xg[i] - mean) * rstd;
        if (gamma) v *= mx_cuda_wload(gamma, gamma_dt, ch);
        if (beta) v += mx_cuda_wload(beta, beta_dt, ch);
        y[base + i] = fuse_silu ? silu_f(v) : v;
    }
}

int mx_cuda_group_norm(mx_cuda_ctx *c, float *y, const float *x, int B, int C, int HW, int groups, mx_wptr gamma,
                       mx_wptr beta, float eps, int fuse_silu, mx_status *st) {
    const long long dims[4] = {B, C, HW, groups};
    if (mx_cuda_check_dims("cuda group_norm", st, 4, dims)) return -1;
    if (C % groups) return mx_fail(st, MX_EINPUT, "cuda group_norm: %d channels not divisible by %d groups", C, groups);
    if ((gamma.data && mx_cuda_check_wdtype(gamma, "cuda group_norm gamma", st)) ||
        (beta.data && mx_cuda_check_wdtype(beta, "cuda group_norm beta", st)))
        return -1;
    if ((long long)B * groups > 0x7fffffffLL) return mx_fail(st, MX_EINPUT, "cuda group_norm: too many groups");
    group_norm_kernel<<<B * groups, NORM_THREADS, 0, c->stream>>>(y, x, C, HW, groups, gamma.data, (int)gamma.dtype,
                                                                   beta.data, (int)beta.dtype, eps, fuse_silu);
    return mx_cuda_launched("cuda group_norm", st);
}

__global__ void layer_norm_kernel(float *y, const float *x, int C, const void *gamma, int gamma_dt, const void *beta,
                                  int beta_dt, float eps) {
    __shared__ float shm[32];
    const float *xr = x + (long long)blockIdx.x * C;
    float *yr = y + (long long)blockIdx.x * C;
    float s = 0.0f;
    for (int i = threadIdx.x; i < C; i += blockDim.x) s += xr[i];
    float mean = mx_cuda_block_sum(s, shm) / (float)C;
    float q = 0.0f;
    for (int i = threadIdx.x; i < C; i += blockDim.x) {
        float d = xr[i] - mean;
        q += d * d;
    }
    float rstd = 1.0f / sqrtf(mx_cuda_block_sum(q, shm) / (float)C + eps);
    /* y may equal x: every thread reads its own elements before writing them, after both sums. */
    for (int i = threadIdx.x; i < C; i += blockDim.x) {
        float v = (xr[i] - mean) * rstd;
        if (gamma) v *= mx_cuda_wload(gamma, gamma_dt, i);
        if (beta) v += mx_cuda_wload(beta, beta_dt, i);
        yr[i] = v;
    }
}

int mx_cuda_layer_norm(mx_cuda_ctx *c, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                       float eps, mx_status *st) {
    const long long dims[2] = {M, C};
    if (mx_cuda_check_dims("cuda layer_norm", st, 2, dims)) return -1;
    if ((gamma.data && mx_cuda_check_wdtype(gamma, "cuda layer_norm gamma", st)) ||
        (beta.data && mx_cuda_check_wdtype(beta, "cuda layer_norm beta", st)))
        return -1;
    layer_norm_kernel<<<M, 256, 0, c->stream>>>(y, x, C, gamma.data, (int)gamma.dtype, beta.data, (int)beta.dtype,
                                                eps);
    return mx_cuda_launched("cuda layer_norm", st);
}
