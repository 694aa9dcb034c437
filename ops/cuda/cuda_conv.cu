/* 2-D convolution (NCHW, zero padding) as GEMM over im2col tiles, on cuBLASLt.
 * For batch item b, with P = Ho*Wo output pixels and Kc = Cin*kh*kw:
 *   y_b[Cout, P] = w[Cout, Kc] · col_b[Kc, P]
 * Row-major y_b is column-major P x Cout, so D = col (stored P x Kc) · w (stored Kc x Cout), no
 * transposes. col is built one tile of pc output pixels at a time in the scratch buffer (never the
 * whole im2col matrix: the memory complaint of ggml's conv), already rounded to the weight's type.
 * A 1x1, stride 1, unpadded conv needs no im2col: col_b is x_b itself. */
#include "cuda_common.cuh"

typedef struct conv_shape {
    int Cin, H, W, kh, kw, stride, pad, Ho, Wo;
} conv_shape;

template <typename T> __device__ __forceinline__ T conv_store(float v);
template <> __device__ __forceinline__ float conv_store<float>(float v) { return v; }
template <> __device__ __forceinline__ __half conv_store<__half>(float v) { return __float2half_rn(v); }
template <> __device__ __forceinline__ __nv_bfloat16 conv_store<__nv_bfloat16>(float v) {
    return __float2bfloat16_rn(v);
}

/* col[kk, pl] (row-major, width pc) = x_b[ci, oy*stride - pad + ky, ox*stride - pad + kx] or 0,
 * for kk = (ci, ky, kx) and output pixel p0 + pl = (oy, ox). */
template <typename T>
__global__ void im2col_tile_kernel(T *col, const float *xb, conv_shape s, long long p0, int pc) {
    long long kc = (long long)s.Cin * s.kh * s.kw;
    long long n = kc * pc;
    for (long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x; i < n;
         i += (long long)gridDim.x * blockDim.x) {
        long long kk = i / pc, p = p0 + i % pc;
        int kx = (int)(kk % s.kw), ky = (int)(kk / s.kw % s.kh), ci = (int)(kk / ((long long)s.kw * s.kh));
        int oy = (int)(p / s.Wo), ox = (int)(p % s.Wo);
        int iy = oy * s.stride - s.pad + ky, ix = ox * s.stride - s.pad + kx;
        float v = 0.0f;
        if (iy >= 0 && iy < s.H && ix >= 0 && ix < s.W) v = xb[((long long)ci * s.H + iy) * s.W + ix];
        col[i] = conv_store<T>(v);
    }
}

static int im2col_tile(mx_cuda_ctx *c, void *col, mx_dtype dt, const float *xb, const conv_shape *s, long long p0,
                       int pc, mx_status *st) {
    size_t n = (size_t)s->Cin * s->kh * s->kw * pc;
    unsigned blocks = mx_cuda_blocks(n, 256);
    if (dt == MX_F16)
        im2col_tile_kernel<__half><<<blocks, 256, 0, c->stream>>>((__half *)col, xb, *s, p0, pc);
    else if (dt == MX_BF16)
        im2col_tile_kernel<__nv_bfloat16><<<blocks, 256, 0, c->stream>>>((__nv_bfloat16 *)col, xb, *s, p0, pc);
    else
        im2col_tile_kernel<float><<<blocks, 256, 0, c->stream>>>((float *)col, xb, *s, p0, pc);
    return mx_cuda_launched("cuda conv2d im2col", st);
}

/* Output pixels per im2col tile: what the free scratch holds, a multiple of 64 (aligned GEMM rows). */
static long long tile_pixels(const mx_cuda_ctx *c, long long kc, size_t esize, long long P) {
    size_t free_bytes = c->scratch_cap > c->scratch_used + 256 ? c->scratch_cap - c->scratch_used - 256 : 0;
    long long pc = (long long)(free_bytes / (kc * esize));
    if (pc >= P) return P;
    return pc >= 64 ? pc / 64 * 64 : pc;
}

static int conv_batch_item(mx_cuda_ctx *c, float *yb, const float *xb, mx_wptr w, int Cout, const conv_shape *s,
                           mx_status *st) {
    long long P = (long long)s->Ho * s->Wo, kc = (long long)s->Cin * s->kh * s->kw;
    size_t esize = mx_dtype_size(w.dtype);
    int direct = s->kh == 1 && s->kw == 1 && s->stride == 1 && s->pad == 0;
    if (direct && w.dtype == MX_F32) /* x_b is already the [Cin, P] matrix */
        return mx_cuda_gemm(c, w.dtype, 0, 0, (int)P, Cout, (int)kc, xb, P, w.data, kc, yb, P, "cuda conv2d", st);
    long long pc = tile_pixels(c, kc, esize, P);
    if (pc < 1)
        return mx_fail(st, MX_ENOMEM, "cuda conv2d: scratch too small for one im2col column (%lld bytes)",
                       (long long)(kc * esize));
    size_t mark = c->scratch_used;
    void *col = mx_cuda_scratch(c, (size_t)(kc * pc) * esize, "cuda conv2d im2col tile", st);
    int rc = col ? 0 : -1;
    for (long long p0 = 0; rc == 0 && p0 < P; p0 += pc) {
        int n = (int)(P - p0 < pc ? P - p0 : pc);
        rc = im2col_tile(c, col, w.dtype, xb, s, p0, n, st);
        if (rc == 0) rc = mx_cuda_gemm(c, w.dtype, 0, 0, n, Cout, (int)kc, col, n, w.data, kc, yb + p0, P,
                                       "cuda conv2d", st);
    }
    c->scratch_used = mark;
    return rc;
}

int mx_cuda_conv2d(mx_cuda_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                   mx_wptr bias, int Cout, int kh, int kw, int stride, int pad, mx_status *st) {
    const long long dims[7] = {B, Cin, H, W, Cout, kh, kw};
    if (mx_cuda_check_dims("cuda conv2d", st, 7, dims) || mx_cuda_check_wdtype(w, "cuda conv2d weight", st))
        return -1;
    if (stride < 1 || pad < 0)
        return mx_fail(st, MX_EINPUT, "cuda conv2d: stride %d / pad %d out of range", stride, pad);
    conv_shape s = {Cin, H, W, kh, kw, stride, pad, 0, 0};
    if (H + 2 * pad < kh || W + 2 * pad < kw)
        return mx_fail(st, MX_EINPUT, "cuda conv2d: kernel %dx%d larger than padded input %dx%d", kh, kw, H + 2 * pad,
                       W + 2 * pad);
    s.Ho = (H + 2 * pad - kh) / stride + 1;
    s.Wo = (W + 2 * pad - kw) / stride + 1;
    long long in_plane = (long long)Cin * H * W, out_plane = (long long)Cout * s.Ho * s.Wo;
    for (int b = 0; b < B; b++)
        if (conv_batch_item(c, y + b * out_plane, x + b * in_plane, w, Cout, &s, st)) return -1;
    return mx_cuda_add_bias(c, y, bias, B, Cout, (long long)s.Ho * s.Wo, "cuda conv2d bias", st);
}
