/* The seam ops on the GPU (ops.h: pad2d, copy, fill, axpy, lincomb, clamp, affine, timestep and
 * token embeddings). Products and sums are rounded one by one (__fmul_rn/__fadd_rn) so that no
 * multiply-add is fused: the same float32 expression as the CPU reference. */
#include "cuda_common.cuh"

#define SEAM_THREADS 256

__global__ void pad2d_kernel(float *y, const float *x, int H, int W, int top, int left, int Hp, int Wp, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t r = i / (size_t)Wp, p = r / (size_t)Hp;
        int sw = (int)(i % (size_t)Wp) - left, sh = (int)(r % (size_t)Hp) - top;
        y[i] = sh >= 0 && sh < H && sw >= 0 && sw < W ? x[(p * H + sh) * (size_t)W + sw] : 0.0f;
    }
}

__global__ void fill_kernel(float *y, float v, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = v;
}

__global__ void axpy_kernel(float *y, const float *x, float s, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = __fadd_rn(y[i], __fmul_rn(s, x[i]));
}

typedef struct lincomb_terms {
    const float *x[MX_LINCOMB_MAX];
    float coef[MX_LINCOMB_MAX];
    int k;
} lincomb_terms;

__global__ void lincomb_kernel(float *y, lincomb_terms t, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        float s = __fmul_rn(t.coef[0], t.x[0][i]);
        for (int j = 1; j < t.k; j++) s = __fadd_rn(s, __fmul_rn(t.coef[j], t.x[j][i]));
        y[i] = s;
    }
}

__global__ void clamp_kernel(float *y, const float *x, float lo, float hi, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        float v = x[i];
        y[i] = v < lo ? lo : (v > hi ? hi : v);
    }
}

__global__ void affine_kernel(float *y, const float *x, float a, float b, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = __fadd_rn(__fmul_rn(a, x[i]), b);
}

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
        y[i] = __fadd_rn(mx_cuda_wload(tok, tok_dt, (size_t)ids[row] * C + col),
                         mx_cuda_wload(pos, pos_dt, (size_t)t * C + col));
    }
}

#define LAUNCH(kernel, n, ...) kernel<<<mx_cuda_blocks(n, SEAM_THREADS), SEAM_THREADS, 0, c->stream>>>(__VA_ARGS__)

int mx_cuda_pad2d(mx_cuda_ctx *c, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
                  int right, mx_status *st) {
    const long long dims[3] = {BC, H + top + bottom, W + left + right};
    if (top < 0 || bottom < 0 || left < 0 || right < 0)
        return mx_fail(st, MX_EINPUT, "cuda pad2d: negative padding");
    if (mx_cuda_check_dims("cuda pad2d", st, 3, dims)) return -1;
    size_t n = (size_t)dims[0] * dims[1] * dims[2];
    LAUNCH(pad2d_kernel, n, y, x, H, W, top, left, (int)dims[1], (int)dims[2], n);
    return mx_cuda_launched("cuda pad2d", st);
}

int mx_cuda_copy(mx_cuda_ctx *c, float *y, const float *x, size_t n, mx_status *st) {
    return mx_cuda_ok(cudaMemcpyAsync(y, x, n * sizeof(float), cudaMemcpyDeviceToDevice, c->stream), "cuda copy", st);
}

int mx_cuda_fill(mx_cuda_ctx *c, float *y, float v, size_t n, mx_status *st) {
    if (n == 0) return 0;
    LAUNCH(fill_kernel, n, y, v, n);
    return mx_cuda_launched("cuda fill", st);
}

int mx_cuda_axpy(mx_cuda_ctx *c, float *y, const float *x, float s, size_t n, mx_status *st) {
    if (n == 0) return 0;
    LAUNCH(axpy_kernel, n, y, x, s, n);
    return mx_cuda_launched("cuda axpy", st);
}

int mx_cuda_lincomb(mx_cuda_ctx *c, float *y, int k, const float *coef, const float *const *x, size_t n,
                    mx_status *st) {
    if (k < 1 || k > MX_LINCOMB_MAX) return mx_fail(st, MX_EINPUT, "cuda lincomb: %d terms (1..%d)", k, MX_LINCOMB_MAX);
    if (n == 0) return 0;
    lincomb_terms t;
    memset(&t, 0, sizeof t);
    t.k = k;
    for (int j = 0; j < k; j++) {
        t.x[j] = x[j];
        t.coef[j] = coef[j];
    }
    LAUNCH(lincomb_kernel, n, y, t, n);
    return mx_cuda_launched("cuda lincomb", st);
}

int mx_cuda_clamp(mx_cuda_ctx *c, float *y, const float *x, float lo, float hi, size_t n, mx_status *st) {
    if (n == 0) return 0;
    LAUNCH(clamp_kernel, n, y, x, lo, hi, n);
    return mx_cuda_launched("cuda clamp", st);
}

int mx_cuda_affine(mx_cuda_ctx *c, float *y, const float *x, float a, float b, size_t n, mx_status *st) {
    if (n == 0) return 0;
    LAUNCH(affine_kernel, n, y, x, a, b, n);
    return mx_cuda_launched("cuda affine", st);
}

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
