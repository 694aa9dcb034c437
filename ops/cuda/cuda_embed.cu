/* Embeddings computed on the device: diffusers' sinusoidal timestep embedding and CLIP's token +
 * position embedding. Float32 arithmetic rounded step by step as the CPU reference. */
#include "cuda_common.cuh"

#define EMBED_THREADS 256

/* One thread per (item, frequency): as diffusers' get_timestep_embedding in float32. */
__global__ void timestep_kernel(float *y, const float *t, int dim, int half, int flip, float shift, float neg_log,
                                size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        int b = (int)(i / (size_t)half), k = (int)(i % (size_t)half);
        float exponent = __fdiv_rn(__fmul_rn(neg_log, (float)k), __fsub_rn((float)half, shift));
        float arg = __fmul_rn(t[b], expf(exponent));
        float s = sinf(arg), co = cosf(arg);
        float *yb = y + (size_t)b * dim;
        yb[k] = flip ? co : s;
        yb[half + k] = flip ? s : co;
        if (dim % 2 && k == 0) yb[dim - 1] = 0.0f;
    }
}

__global__ void embed_kernel(float *y, const int32_t *ids, int T, int C, const void *tok, int tok_dt, const void *pos,
                             int pos_dt, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t row = i / (size_t)C, col = i % (size_t)C;
        int t = (int)(row % (size_t)T);
        float p = mx_cuda_wload(pos, pos_dt, (size_t)t * C + col);
        y[i] = ids[row] < 0 ? p : __fadd_rn(mx_cuda_wload(tok, tok_dt, (size_t)ids[row] * C + col), p);
    }
}

#define LAUNCH(kernel, n, ...) kernel<<<mx_cuda_blocks(n, EMBED_THREADS), EMBED_THREADS, 0, c->stream>>>(__VA_ARGS__)

int mx_cuda_timestep_embedding(mx_cuda_ctx *c, float *y, const float *t, int B, int dim, int flip_sin_to_cos,
                               float downscale_freq_shift, float max_period, mx_status *st) {
    const long long dims[2] = {B, dim};
    if (mx_cuda_check_dims("cuda timestep embedding", st, 2, dims)) return -1;
    int half = dim / 2;
    if (half == 0) return mx_cuda_memset_zero(c, y, (size_t)B * dim * sizeof(float), "cuda timestep embedding", st);
    size_t n = (size_t)B * half;
    LAUNCH(timestep_kernel, n, y, t, dim, half, flip_sin_to_cos, downscale_freq_shift, (float)-log((double)max_period),
           n);
    return mx_cuda_launched("cuda timestep embedding", st);
}

/* The ids are host integers: copied into scratch first (the copy from pageable memory has
 * finished when cudaMemcpyAsync returns, so the caller may free them at once). */
int mx_cuda_embed_tokens(mx_cuda_ctx *c, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                         mx_wptr positions, mx_status *st) {
    const long long dims[3] = {B, T, C};
    if (mx_cuda_check_dims("cuda embed tokens", st, 3, dims) || mx_cuda_check_wdtype(tokens, "cuda embed tokens", st) ||
        mx_cuda_check_wdtype(positions, "cuda embed tokens", st))
        return -1;
    /* the ids are host integers: a graph would replay the copy from memory that may hold others by then */
    if (mx_cuda_not_capturing(c, "cuda embed tokens: a copy of host ids", st)) return -1;
    size_t mark = c->scratch_used, nids = (size_t)B * T, n = nids * C;
    int32_t *dids = (int32_t *)mx_cuda_scratch(c, nids * sizeof *dids, "cuda embed tokens", st);
    int rc = -1;
    if (dids && !mx_cuda_ok(cudaMemcpyAsync(dids, ids, nids * sizeof *dids, cudaMemcpyHostToDevice, c->stream),
                            "cuda embed tokens: ids", st)) {
        LAUNCH(embed_kernel, n, y, dids, T, C, tokens.data, (int)tokens.dtype, positions.data, (int)positions.dtype, n);
        rc = mx_cuda_launched("cuda embed tokens", st);
    }
    c->scratch_used = mark;
    return rc;
}
