/* Data movement: nearest 2x upsample, channel concat, [C, HW] <-> [HW, C] transposes, bilinear resize. */
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

/* Source coordinate as PyTorch's upsample_bilinear2d (area_pixel_compute_source_index):
 * align_corners: dst * (in-1)/(out-1); else (dst + 0.5) * in/out - 0.5, clamped at 0. */
__device__ __forceinline__ float bilinear_src(int dst, float scale, int align_corners) {
    if (align_corners) return scale * (float)dst;
    float s = scale * ((float)dst + 0.5f) - 0.5f;
    return s < 0.0f ? 0.0f : s;
}

__global__ void resize_bilinear_kernel(float *y, const float *x, int H, int W, int Ho, int Wo, float sh, float sw,
                                       int align_corners, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t plane = i / ((size_t)Ho * Wo);
        int oy = (int)(i / Wo % Ho), ox = (int)(i % Wo);
        float fy = bilinear_src(oy, sh, align_corners), fx = bilinear_src(ox, sw, align_corners);
        int y0 = min((int)fy, H - 1), x0 = min((int)fx, W - 1);
        int y1 = y0 + (y0 < H - 1), x1 = x0 + (x0 < W - 1);
        float ly = fy - (float)y0, lx = fx - (float)x0;
        const float *p = x + plane * H * W;
        y[i] = (1.0f - ly) * ((1.0f - lx) * p[(size_t)y0 * W + x0] + lx * p[(size_t)y0 * W + x1]) +
               ly * ((1.0f - lx) * p[(size_t)y1 * W + x0] + lx * p[(size_t)y1 * W + x1]);
    }
}

static float bilinear_scale(int in, int out, int align_corners) {
    if (align_corners) return out > 1 ? (float)(in - 1) / (float)(out - 1) : 0.0f;
    return (float)in / (float)out;
}

int mx_cuda_resize_bilinear(mx_cuda_ctx *c, float *y, const float *x, int BC, int H, int W, int Ho, int Wo,
                            int align_corners, mx_status *st) {
    const long long dims[5] = {BC, H, W, Ho, Wo};
    if (mx_cuda_check_dims("cuda resize_bilinear", st, 5, dims)) return -1;
    size_t n = (size_t)BC * Ho * Wo;
    resize_bilinear_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(
        y, x, H, W, Ho, Wo, bilinear_scale(H, Ho, align_corners), bilinear_scale(W, Wo, align_corners),
        align_corners, n);
    return mx_cuda_launched("cuda resize_bilinear", st);
}
