/* Data movement: nearest 2x upsample, rectangle copy, channel concat, [C, HW] <-> [HW, C] transposes,
 * zero padding, copy and fill. */
#include "cuda_common.cuh"

__global__ void upsample_nearest2x_kernel(float *y, const float *x, int H, int W, size_t n) {
    int Wo = 2 * W, Ho = 2 * H;
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t plane = i / ((size_t)Ho * Wo);
        int oy = (int)(i / Wo % Ho), ox = (int)(i % Wo);
        y[i] = x[plane * H * W + (size_t)(oy >> 1) * W + (ox >> 1)];
    }
}

int mx_cuda_upsample_nearest2x(mx_cuda_ctx *c, float *y, const float *x, int BC, int H, int W, mx_status *st) {
    const long long dims[3] = {BC, H, W};
    if (mx_cuda_check_dims("cuda upsample_nearest2x", st, 3, dims)) return -1;
    size_t n = (size_t)BC * 4 * H * W;
    upsample_nearest2x_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, x, H, W, n);
    return mx_cuda_launched("cuda upsample_nearest2x", st);
}

__global__ void concat_channels_kernel(float *y, const float *a, int Ca, const float *b, int Cb, long long HW,
                                       size_t n) {
    int C = Ca + Cb;
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t bi = i / ((size_t)C * HW);
        int ch = (int)(i / HW % C);
        size_t p = i % HW;
        y[i] = ch < Ca ? a[(bi * Ca + ch) * HW + p] : b[(bi * Cb + (ch - Ca)) * HW + p];
    }
}

int mx_cuda_concat_channels(mx_cuda_ctx *c, float *y, const float *a, int Ca, const float *b, int Cb, int B, int HW,
                            mx_status *st) {
    const long long dims[4] = {Ca, Cb, B, HW};
    if (mx_cuda_check_dims("cuda concat_channels", st, 4, dims)) return -1;
    size_t n = (size_t)B * (Ca + Cb) * HW;
    concat_channels_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, a, Ca, b, Cb, HW, n);
    return mx_cuda_launched("cuda concat_channels", st);
}

/* y[b, col, row] = x[b, row, col] for x of [rows, cols] per batch item: 32x32 tiles through shared
 * memory (the +1 column avoids bank conflicts) so that both the reads and the writes are coalesced. */
#define TILE 32
__global__ void transpose_kernel(float *y, const float *x, int rows, int cols) {
    __shared__ float tile[TILE][TILE + 1];
    size_t base = (size_t)blockIdx.z * rows * cols;
    int c0 = blockIdx.x * TILE, r0 = blockIdx.y * TILE;
    for (int dy = threadIdx.y; dy < TILE; dy += blockDim.y) {
        int r = r0 + dy, cl = c0 + threadIdx.x;
        if (r < rows && cl < cols) tile[dy][threadIdx.x] = x[base + (size_t)r * cols + cl];
    }
    __syncthreads();
    for (int dy = threadIdx.y; dy < TILE; dy += blockDim.y) {
        int cl = c0 + dy, r = r0 + threadIdx.x;
        if (r < rows && cl < cols) y[base + (size_t)cl * rows + r] = tile[threadIdx.x][dy];
    }
}

static int transpose(mx_cuda_ctx *c, float *y, const float *x, int B, int rows, int cols, const char *what,
                     mx_status *st) {
    const long long dims[3] = {B, rows, cols};
    if (mx_cuda_check_dims(what, st, 3, dims)) return -1;
    if (B > 65535 || (rows + TILE - 1) / TILE > 65535)
        return mx_fail(st, MX_EINPUT, "%s: %d x %d x %d is beyond the launch grid", what, B, rows, cols);
    dim3 grid((unsigned)((cols + TILE - 1) / TILE), (unsigned)((rows + TILE - 1) / TILE), (unsigned)B);
    transpose_kernel<<<grid, dim3(TILE, 8), 0, c->stream>>>(y, x, rows, cols);
    return mx_cuda_launched(what, st);
}

int mx_cuda_transpose_chw_hwc(mx_cuda_ctx *c, float *y, const float *x, int B, int C, int HW, mx_status *st) {
    return transpose(c, y, x, B, C, HW, "cuda transpose_chw_hwc", st);
}

int mx_cuda_transpose_hwc_chw(mx_cuda_ctx *c, float *y, const float *x, int B, int C, int HW, mx_status *st) {
    return transpose(c, y, x, B, HW, C, "cuda transpose_hwc_chw", st);
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

int mx_cuda_copy_rect(mx_cuda_ctx *c, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx,
                      int sy0, int sx0, int BC, int h, int w, mx_status *st) {
    const long long dims[3] = {BC, h, w};
    if (mx_cuda_check_dims("cuda copy_rect", st, 3, dims)) return -1;
    size_t n = (size_t)BC * h * w;
    copy_rect_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, Hy, Wy, y0, x0, x, Hx, Wx, sy0,
                                                                                      sx0, h, w, n);
    return mx_cuda_launched("cuda copy_rect", st);
}

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

int mx_cuda_pad2d(mx_cuda_ctx *c, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
                  int right, mx_status *st) {
    const long long dims[3] = {BC, H + top + bottom, W + left + right};
    if (top < 0 || bottom < 0 || left < 0 || right < 0)
        return mx_fail(st, MX_EINPUT, "cuda pad2d: negative padding");
    if (mx_cuda_check_dims("cuda pad2d", st, 3, dims)) return -1;
    size_t n = (size_t)dims[0] * dims[1] * dims[2];
    pad2d_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, x, H, W, top, left, (int)dims[1], (int)dims[2], n);
    return mx_cuda_launched("cuda pad2d", st);
}

int mx_cuda_copy(mx_cuda_ctx *c, float *y, const float *x, size_t n, mx_status *st) {
    return mx_cuda_ok(cudaMemcpyAsync(y, x, n * sizeof(float), cudaMemcpyDeviceToDevice, c->stream), "cuda copy", st);
}

int mx_cuda_fill(mx_cuda_ctx *c, float *y, float v, size_t n, mx_status *st) {
    if (n == 0) return 0;
    fill_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, v, n);
    return mx_cuda_launched("cuda fill", st);
}
