/* 2-D convolution (NCHW, zero padding) as GEMM over im2col tiles, on cuBLASLt.
 * For batch item b, with P = Ho*Wo output pixels and Kc = Cin*kh*kw:
 *   y_b[Cout, P] = w[Cout, Kc] · col_b[Kc, P]
 * computed for all items at once (one strided-batched GEMM per tile of pixels, w shared).
 * Row-major y_b is column-major P x Cout, so D = col (stored P x Kc) · w (stored Kc x Cout), no
 * transposes. col is built one tile of pc output pixels at a time in the scratch buffer (never the
 * whole im2col matrix: the memory complaint of ggml's conv), already rounded to the weight's type.
 * A 1x1, stride 1, unpadded conv needs no im2col: col_b is x_b itself. */
#include "cuda_common.cuh"

/* H, W: the input as the conv sees it; x holds it stored (H/up)×(W/up), upsampled up× (nearest) on
 * the fly for conv2d_up2x (up 2), else up 1. */
typedef struct conv_shape {
    int Cin, H, W, kh, kw, stride, pad, Ho, Wo, up;
} conv_shape;

/* col[kk, pl] (row-major, width pc) = x[ci, oy*stride - pad + ky, ox*stride - pad + kx] or 0 for one
 * item x, for kk = (ci, ky, kx) and output pixel p0 + pl = (oy, ox). Grid: x over the tile's pixels,
 * y over kk (< 65536: Cin·kh·kw of SD is at most 11,520): every index is 32-bit, (ci, ky, kx) is
 * computed once per block row. */
template <typename T>
__global__ void im2col_tile_kernel(T *col, const float *x, conv_shape s, unsigned p0, unsigned pc) {
    unsigned kk = blockIdx.y, khw = (unsigned)(s.kh * s.kw);
    unsigned ci = kk / khw, r = kk - ci * khw, ky = r / (unsigned)s.kw, kx = r - ky * (unsigned)s.kw;
    unsigned sw = (unsigned)(s.W / s.up);
    const float *plane = x + (size_t)ci * (s.H / s.up) * sw;
    T *row = col + (size_t)kk * pc;
    for (unsigned pl = blockIdx.x * blockDim.x + threadIdx.x; pl < pc; pl += gridDim.x * blockDim.x) {
        unsigned p = p0 + pl, oy = p / (unsigned)s.Wo, ox = p - oy * (unsigned)s.Wo;
        int iy = (int)(oy * s.stride + ky) - s.pad, ix = (int)(ox * s.stride + kx) - s.pad;
        float v = iy >= 0 && iy < s.H && ix >= 0 && ix < s.W ? plane[(size_t)(iy / s.up) * sw + ix / s.up] : 0.0f;
        row[pl] = mx_cuda_store<T>(v);
    }
}

/* The tile of one item x for output pixels [p0, p0 + pc). */
static int im2col_tile(mx_cuda_ctx *c, void *col, mx_dtype dt, const float *x, const conv_shape *s, long long p0,
                       int pc, mx_status *st) {
    unsigned kc = (unsigned)(s->Cin * s->kh * s->kw), bx = (unsigned)((pc + 255) / 256);
    dim3 grid(bx < 1024 ? bx : 1024, kc);
    if (dt == MX_F16)
        im2col_tile_kernel<__half><<<grid, 256, 0, c->stream>>>((__half *)col, x, *s, (unsigned)p0, (unsigned)pc);
    else if (dt == MX_BF16)
        im2col_tile_kernel<__nv_bfloat16><<<grid, 256, 0, c->stream>>>((__nv_bfloat16 *)col, x, *s, (unsigned)p0,
                                                                      (unsigned)pc);
    else
        im2col_tile_kernel<float><<<grid, 256, 0, c->stream>>>((float *)col, x, *s, (unsigned)p0, (unsigned)pc);
    return mx_cuda_launched("cuda conv2d im2col", st);
}

/* Output pixels per im2col tile of one item: what the free scratch holds, a multiple of 64 (aligned
 * GEMM rows). */
static long long tile_pixels(const mx_cuda_ctx *c, long long kc, size_t esize, long long P) {
    size_t free_bytes = c->scratch_cap > c->scratch_used + 256 ? c->scratch_cap - c->scratch_used - 256 : 0;
    long long pc = (long long)(free_bytes / ((size_t)kc * esize));
    if (pc >= P) return P;
    return pc >= 64 ? pc / 64 * 64 : pc;
}

/* Item by item, tiles sized for one item: item b's GEMMs are the same calls (shape, plan, algorithm)
 * whatever B, so its output is the same bits alone or in a batch. Per tile: im2col, one GEMM. */
static int conv_items(mx_cuda_ctx *c, float *y, const float *x, int B, mx_wptr w, int Cout, const conv_shape *s,
                        mx_status *st) {
    long long P = (long long)s->Ho * s->Wo, kc = (long long)s->Cin * s->kh * s->kw;
    long long in_plane = (long long)s->Cin * (s->H / s->up) * (s->W / s->up), out_plane = (long long)Cout * P;
    size_t esize = mx_dtype_size(w.dtype);
    int direct = s->kh == 1 && s->kw == 1 && s->stride == 1 && s->pad == 0 && s->up == 1;
    for (int b = 0; direct && w.dtype == MX_F32 && b < B; b++) /* x_b is already the [Cin, P] matrix */
        if (mx_cuda_gemm_batched(c, w.dtype, 0, 0, (int)P, Cout, (int)kc, x + b * in_plane, P, 0, w.data, kc, 0,
                                 y + b * out_plane, P, 0, 1, "cuda conv2d", st))
            return -1;
    if (direct && w.dtype == MX_F32) return 0;
    long long pc = tile_pixels(c, kc, esize, P);
    if (pc < 1)
        return mx_fail(st, MX_ENOMEM, "cuda conv2d: scratch too small for one im2col column (%lld bytes)",
                       (long long)(kc * esize));
    size_t mark = c->scratch_used;
    void *col = mx_cuda_scratch(c, (size_t)(kc * pc) * esize, "cuda conv2d im2col tile", st);
    int rc = col ? 0 : -1;
    for (int b = 0; rc == 0 && b < B; b++)
        for (long long p0 = 0; rc == 0 && p0 < P; p0 += pc) {
            int n = (int)(P - p0 < pc ? P - p0 : pc);
            rc = im2col_tile(c, col, w.dtype, x + b * in_plane, s, p0, n, st);
            if (rc == 0)
                rc = mx_cuda_gemm_batched(c, w.dtype, 0, 0, n, Cout, (int)kc, col, n, 0, w.data, kc, 0,
                                          y + b * out_plane + p0, P, 0, 1, "cuda conv2d", st);
        }
    c->scratch_used = mark;
    return rc;
}

int mx_cuda_conv2d(mx_cuda_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                   mx_wptr bias, int Cout, int kh, int kw, int stride, int pad, mx_status *st) {
    const long long dims[7] = {B, Cin, H, W, Cout, kh, kw}, outputs[2] = {B, Cout};
    if (mx_cuda_empty(2, outputs)) return 0;
    if (mx_cuda_check_dims("cuda conv2d", st, 7, dims) || mx_cuda_check_wdtype(w, "cuda conv2d weight", st))
        return -1;
    if (stride < 1 || pad < 0)
        return mx_fail(st, MX_EINPUT, "cuda conv2d: stride %d / pad %d out of range", stride, pad);
    conv_shape s = {Cin, H, W, kh, kw, stride, pad, 0, 0, 1};
    if (H + 2 * pad < kh || W + 2 * pad < kw) return 0; /* no output (op_list.h), as on the CPU */
    s.Ho = (H + 2 * pad - kh) / stride + 1;
    s.Wo = (W + 2 * pad - kw) / stride + 1;
    if ((long long)s.Ho * s.Wo > 0x7fffffffLL || (long long)Cin * kh * kw > 65535)
        return mx_fail(st, MX_EINPUT, "cuda conv2d: %d x %d output pixels or %d x %d x %d taps out of range", s.Ho, s.Wo,
                       Cin, kh, kw);
    /* cuDNN where MATEX_CUDNN=1 and a deterministic engine runs this shape (cuda_cudnn.cu), else im2col */
    int rc = mx_cuda_cudnn_conv2d(c, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad, s.Ho, s.Wo, st);
    if (rc != 1) return rc;
    if (conv_items(c, y, x, B, w, Cout, &s, st)) return -1;
    return mx_cuda_add_bias(c, y, bias, B, Cout, (long long)s.Ho * s.Wo, "cuda conv2d bias", st);
}

/* conv2d_up2x: the 3×3 conv over the upsampled input through im2col, which reads x at (iy/2, ix/2);
 * the upsampled image is never stored (the phase form of the CPU levels is not used here yet). */
int mx_cuda_conv2d_up2x(mx_cuda_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                        mx_wptr bias, int Cout, mx_status *st) {
    const long long dims[5] = {B, Cin, H, W, Cout}, outputs[2] = {B, Cout};
    if (mx_cuda_empty(2, outputs)) return 0;
    if (mx_cuda_check_dims("cuda conv2d_up2x", st, 5, dims) || mx_cuda_check_wdtype(w, "cuda conv2d_up2x weight", st))
        return -1;
    if (4LL * H * W > 0x7fffffffLL || (long long)Cin * 9 > 65535)
        return mx_fail(st, MX_EINPUT, "cuda conv2d_up2x: %d x %d input pixels or %d channels out of range", H, W, Cin);
    conv_shape s = {Cin, 2 * H, 2 * W, 3, 3, 1, 1, 2 * H, 2 * W, 2};
    if (conv_items(c, y, x, B, w, Cout, &s, st)) return -1;
    return mx_cuda_add_bias(c, y, bias, B, Cout, 4LL * H * W, "cuda conv2d_up2x bias", st);
}
