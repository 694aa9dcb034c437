/* Group norm (+ fused SiLU) and layer norm: two passes over the data (mean, then the squared
 * deviations) as in the CPU reference, so that large means do not cost precision. Layer norm: one
 * thread block per row; group norm: several blocks per group (below). */
#include "cuda_common.cuh"

__device__ __forceinline__ float silu_f(float v) { return v / (1.0f + expf(-v)); }

/* Group norm in three launches, each over (b, g, chunk) blocks: a group of SD's VAE holds up to
 * 1 M values and there are only B·32 groups, so one block per group left most of the GPU idle
 * (1.25 ms per VAE group norm on an H200). A group is cut into `chunks` equal pieces, a number
 * that depends on the group's size only, never on B (an item's sums are the same alone or in a
 * batch); each block writes its piece's partial sum, and the next launch reduces a group's
 * partials in a fixed order, so results are deterministic. Pass 1: partial sums; pass 2: partial
 * sums of squared deviations from the mean; pass 3: normalise, affine, SiLU. */
#define GN_THREADS 256
#define GN_MAX_CHUNKS 64 /* <= GN_THREADS: one thread per partial in gn_reduce */

typedef struct gn_shape {
    int C, groups, chunks;
    unsigned HW, n, piece; /* values per channel, per group, per chunk */
} gn_shape;

/* The sum of group bg's chunk partials; every thread gets it. */
__device__ __forceinline__ float gn_reduce(const float *partial, int bg, int chunks, float *shm) {
    float v = threadIdx.x < (unsigned)chunks ? partial[(size_t)bg * chunks + threadIdx.x] : 0.0f;
    return mx_cuda_block_sum(v, shm);
}

/* Pass 1 (sum_part == NULL): the sum of x over each chunk. Pass 2: the sum of (x - mean)². */
__global__ void gn_partial_kernel(float *out_part, const float *sum_part, const float *x, gn_shape s) {
    __shared__ float shm[32];
    int bg = blockIdx.x / s.chunks, chunk = blockIdx.x % s.chunks;
    const float *xg = x + (size_t)bg * s.n;
    unsigned lo = chunk * s.piece, hi = min(lo + s.piece, s.n);
    float mean = sum_part ? gn_reduce(sum_part, bg, s.chunks, shm) / (float)s.n : 0.0f, acc = 0.0f;
    for (unsigned i = lo + threadIdx.x; i < hi; i += blockDim.x) {
        float d = xg[i] - mean;
        acc += sum_part ? d * d : xg[i];
    }
    acc = mx_cuda_block_sum(acc, shm);
    if (threadIdx.x == 0) out_part[blockIdx.x] = acc;
}

__global__ void gn_apply_kernel(float *y, const float *x, const float *sum_part, const float *sq_part, gn_shape s,
                                const void *gamma, int gamma_dt, const void *beta, int beta_dt, float eps,
                                int fuse_silu) {
    __shared__ float shm[32];
    int bg = blockIdx.x / s.chunks, chunk = blockIdx.x % s.chunks, cpg = s.C / s.groups, g = bg % s.groups;
    float mean = gn_reduce(sum_part, bg, s.chunks, shm) / (float)s.n;
    float rstd = 1.0f / sqrtf(gn_reduce(sq_part, bg, s.chunks, shm) / (float)s.n + eps);
    size_t base = (size_t)bg * s.n;
    unsigned lo = chunk * s.piece, hi = min(lo + s.piece, s.n);
    for (unsigned i = lo + threadIdx.x; i < hi; i += blockDim.x) {
        int ch = g * cpg + (int)(i / s.HW);
        float v = (x[base + i] - mean) * rstd;
        if (gamma) v *= mx_cuda_wload(gamma, gamma_dt, ch);
        if (beta) v += mx_cuda_wload(beta, beta_dt, ch);
        y[base + i] = fuse_silu ? silu_f(v) : v;
    }
}

/* Chunks of a group of n values: ~512 blocks per item at 32 groups (a GPU of ~130
 * multiprocessors busy even at batch 1), none under 4096 values; from the group alone. */
static int gn_chunks(int groups, unsigned n) {
    int want = (512 + groups - 1) / groups, most = (int)((n + 4095) / 4096);
    want = want < most ? want : most;
    return want < 1 ? 1 : want > GN_MAX_CHUNKS ? GN_MAX_CHUNKS : want;
}

int mx_cuda_group_norm(mx_cuda_ctx *c, float *y, const float *x, int B, int C, int HW, int groups, mx_wptr gamma,
                       mx_wptr beta, float eps, int fuse_silu, mx_status *st) {
    const long long dims[4] = {B, C, HW, groups};
    if (mx_cuda_check_dims("cuda group_norm", st, 4, dims)) return -1;
    if (C % groups) return mx_fail(st, MX_EINPUT, "cuda group_norm: %d channels not divisible by %d groups", C, groups);
    if ((gamma.data && mx_cuda_check_wdtype(gamma, "cuda group_norm gamma", st)) ||
        (beta.data && mx_cuda_check_wdtype(beta, "cuda group_norm beta", st)))
        return -1;
    long long n = (long long)(C / groups) * HW;
    if (n >= (1LL << 32) || (long long)B * groups * GN_MAX_CHUNKS > 0x7fffffffLL)
        return mx_fail(st, MX_EINPUT, "cuda group_norm: %d x %d x %d values too many", B, C, HW);
    gn_shape s = {C, groups, gn_chunks(groups, (unsigned)n), (unsigned)HW, (unsigned)n, 0};
    s.piece = (unsigned)((n + s.chunks - 1) / s.chunks);
    int blocks = B * groups * s.chunks;
    size_t mark = c->scratch_used;
    float *part = (float *)mx_cuda_scratch(c, 2 * (size_t)blocks * sizeof(float), "cuda group_norm", st);
    if (!part) return -1;
    gn_partial_kernel<<<blocks, GN_THREADS, 0, c->stream>>>(part, NULL, x, s);
    gn_partial_kernel<<<blocks, GN_THREADS, 0, c->stream>>>(part + blocks, part, x, s);
    gn_apply_kernel<<<blocks, GN_THREADS, 0, c->stream>>>(y, x, part, part + blocks, s, gamma.data, (int)gamma.dtype,
                                                          beta.data, (int)beta.dtype, eps, fuse_silu);
    c->scratch_used = mark;
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
