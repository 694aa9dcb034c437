/* Element-wise vector ops of the denoising loop and the scheduler step (axpy, linear
 * combination, clamp, affine). Products and sums are rounded one by one (__fmul_rn/__fadd_rn) so
 * that no multiply-add is fused: the same float32 expression as the CPU reference. */
#include "cuda_common.cuh"

#define VECTOR_THREADS 256

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

#define LAUNCH(kernel, n, ...) kernel<<<mx_cuda_blocks(n, VECTOR_THREADS), VECTOR_THREADS, 0, c->stream>>>(__VA_ARGS__)

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
