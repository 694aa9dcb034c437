/* The ops of the few-step path and the tiled VAE decode on the GPU (ops.h: tanh, copy_rect). tanh
 * in double as the CPU reference, rounded once to float. */
#include "cuda_common.cuh"

#define FAST_THREADS 256

__global__ void tanh_kernel(float *x, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) x[i] = (float)tanh((double)x[i]);
}

/* One thread per copied element: plane p, row r, column q of the h x w rectangle. */
__global__ void copy_rect_kernel(float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx, int sy0,
                                 int sx0, int h, int w, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t row = i / (size_t)w, p = row / (size_t)h;
        int q = (int)(i % (size_t)w), r = (int)(row % (size_t)h);
        y[(p * Hy + y0 + r) * (size_t)Wy + x0 + q] = x[(p * Hx + sy0 + r) * (size_t)Wx + sx0 + q];
    }
}

int mx_cuda_tanh(mx_cuda_ctx *c, float *x, size_t n, mx_status *st) {
    if (n == 0) return 0;
    tanh_kernel<<<mx_cuda_blocks(n, FAST_THREADS), FAST_THREADS, 0, c->stream>>>(x, n);
    return mx_cuda_launched("cuda tanh", st);
}

int mx_cuda_copy_rect(mx_cuda_ctx *c, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx,
                      int sy0, int sx0, int BC, int h, int w, mx_status *st) {
    const long long dims[3] = {BC, h, w};
    if (mx_cuda_check_dims("cuda copy_rect", st, 3, dims)) return -1;
    size_t n = (size_t)BC * h * w;
    copy_rect_kernel<<<mx_cuda_blocks(n, FAST_THREADS), FAST_THREADS, 0, c->stream>>>(y, Hy, Wy, y0, x0, x, Hx, Wx, sy0,
                                                                                      sx0, h, w, n);
    return mx_cuda_launched("cuda copy_rect", st);
}
