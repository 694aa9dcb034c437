/* The CUDA backend (runtime/backend.h): device memory, host copies, and the kernel table that
 * runs every op of ops.h with the kernels of this folder. Kernel table entries return nothing,
 * so the first error of any op is kept and reported by the next copy to the host (ops queue
 * work on one stream; a download waits for it). One device (0) per process. */
#include <string.h>

#include "cuda_common.cuh"

#define CUDA_SCRATCH_BYTES ((size_t)64 << 20)

typedef struct cuda_backend {
    mx_backend be;
    mx_kernels k;
    mx_cuda_ctx *cc;
    mx_status err; /* the first failure of a queued op */
    int failed;
} cuda_backend;

static cuda_backend *of(const mx_ctx *c) { return (cuda_backend *)c->be->impl; }

/* Runs one mx_cuda_* call (which sees b_ and st_) unless an earlier op failed; keeps its error. */
#define CUDA_OP(c, call)                                                                                   \
    do {                                                                                                   \
        cuda_backend *b_ = of(c);                                                                          \
        mx_status *st_ = &b_->err;                                                                         \
        if (!b_->failed && (call) != 0) b_->failed = 1;                                                    \
    } while (0)

static void k_linear(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    CUDA_OP(c, mx_cuda_linear(b_->cc, y, x, w, bias, M, N, K, st_));
}
static void k_conv2d(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w, mx_wptr bias,
                     int Cout, int kh, int kw, int stride, int pad) {
    CUDA_OP(c, mx_cuda_conv2d(b_->cc, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad, st_));
}
static void k_group_norm(const mx_ctx *c, float *y, const float *x, int B, int C, int HW, int groups, mx_wptr gamma,
                         mx_wptr beta, float eps, int fuse_silu) {
    CUDA_OP(c, mx_cuda_group_norm(b_->cc, y, x, B, C, HW, groups, gamma, beta, eps, fuse_silu, st_));
}
static void k_layer_norm(const mx_ctx *c, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                         float eps) {
    CUDA_OP(c, mx_cuda_layer_norm(b_->cc, y, x, M, C, gamma, beta, eps, st_));
}
static void k_softmax(const mx_ctx *c, float *x, int M, int N) { CUDA_OP(c, mx_cuda_softmax(b_->cc, x, M, N, st_)); }
static void k_attention(const mx_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                        int Tq, int Tk, int D, int qs, int kvs, int os, int causal, float scale) {
    CUDA_OP(c, mx_cuda_attention(b_->cc, out, q, k, v, B, H, Tq, Tk, D, qs, kvs, os, causal, scale, st_));
}
static void k_gelu(const mx_ctx *c, float *x, size_t n) { CUDA_OP(c, mx_cuda_gelu(b_->cc, x, n, st_)); }
static void k_quick_gelu(const mx_ctx *c, float *x, size_t n) { CUDA_OP(c, mx_cuda_quick_gelu(b_->cc, x, n, st_)); }
static void k_silu(const mx_ctx *c, float *x, size_t n) { CUDA_OP(c, mx_cuda_silu(b_->cc, x, n, st_)); }
static void k_geglu(const mx_ctx *c, float *y, const float *x, int M, int N) {
    CUDA_OP(c, mx_cuda_geglu(b_->cc, y, x, M, N, st_));
}
static void k_binary(const mx_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b,
                     const int64_t *bshape, int ndim) {
    CUDA_OP(c, mx_cuda_binary(b_->cc, op, y, a, ashape, b, bshape, ndim, st_));
}
static void k_scale(const mx_ctx *c, float *y, const float *x, float s, size_t n) {
    CUDA_OP(c, mx_cuda_scale(b_->cc, y, x, s, n, st_));
}
static void k_upsample(const mx_ctx *c, float *y, const float *x, int BC, int H, int W) {
    CUDA_OP(c, mx_cuda_upsample_nearest2x(b_->cc, y, x, BC, H, W, st_));
}
static void k_concat(const mx_ctx *c, float *y, const float *a, int Ca, const float *b, int Cb, int B, int HW) {
    CUDA_OP(c, mx_cuda_concat_channels(b_->cc, y, a, Ca, b, Cb, B, HW, st_));
}
static void k_chw_hwc(const mx_ctx *c, float *y, const float *x, int B, int C, int HW) {
    CUDA_OP(c, mx_cuda_transpose_chw_hwc(b_->cc, y, x, B, C, HW, st_));
}
static void k_hwc_chw(const mx_ctx *c, float *y, const float *x, int B, int C, int HW) {
    CUDA_OP(c, mx_cuda_transpose_hwc_chw(b_->cc, y, x, B, C, HW, st_));
}
static void k_resize(const mx_ctx *c, float *y, const float *x, int BC, int H, int W, int Ho, int Wo, int ac) {
    CUDA_OP(c, mx_cuda_resize_bilinear(b_->cc, y, x, BC, H, W, Ho, Wo, ac, st_));
}
static void k_pad2d(const mx_ctx *c, float *y, const float *x, int BC, int H, int W, int t, int b, int l, int r) {
    CUDA_OP(c, mx_cuda_pad2d(b_->cc, y, x, BC, H, W, t, b, l, r, st_));
}
static void k_copy(const mx_ctx *c, float *y, const float *x, size_t n) { CUDA_OP(c, mx_cuda_copy(b_->cc, y, x, n, st_)); }
static void k_fill(const mx_ctx *c, float *y, float v, size_t n) { CUDA_OP(c, mx_cuda_fill(b_->cc, y, v, n, st_)); }
static void k_axpy(const mx_ctx *c, float *y, const float *x, float s, size_t n) {
    CUDA_OP(c, mx_cuda_axpy(b_->cc, y, x, s, n, st_));
}
static void k_lincomb(const mx_ctx *c, float *y, int k, const float *coef, const float *const *x, size_t n) {
    CUDA_OP(c, mx_cuda_lincomb(b_->cc, y, k, coef, x, n, st_));
}
static void k_clamp(const mx_ctx *c, float *y, const float *x, float lo, float hi, size_t n) {
    CUDA_OP(c, mx_cuda_clamp(b_->cc, y, x, lo, hi, n, st_));
}
static void k_affine(const mx_ctx *c, float *y, const float *x, float a, float b, size_t n) {
    CUDA_OP(c, mx_cuda_affine(b_->cc, y, x, a, b, n, st_));
}
static void k_timestep(const mx_ctx *c, float *y, const float *t, int B, int dim, int flip, float shift, float period) {
    CUDA_OP(c, mx_cuda_timestep_embedding(b_->cc, y, t, B, dim, flip, shift, period, st_));
}
static void k_embed(const mx_ctx *c, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tok, mx_wptr pos) {
    CUDA_OP(c, mx_cuda_embed_tokens(b_->cc, y, ids, B, T, C, tok, pos, st_));
}
static void k_tanh(const mx_ctx *c, float *x, size_t n) { CUDA_OP(c, mx_cuda_tanh(b_->cc, x, n, st_)); }
static void k_copy_rect(const mx_ctx *c, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx,
                        int sy0, int sx0, int BC, int h, int w) {
    CUDA_OP(c, mx_cuda_copy_rect(b_->cc, y, Hy, Wy, y0, x0, x, Hx, Wx, sy0, sx0, BC, h, w, st_));
}
static void k_f16_to_f32(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    CUDA_OP(c, mx_cuda_f16_to_f32(b_->cc, y, x, n, st_));
}
static void k_f32_to_f16(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    CUDA_OP(c, mx_cuda_f32_to_f16(b_->cc, y, x, n, st_));
}
static void k_bf16_to_f32(const mx_ctx *c, float *y, const uint16_t *x, size_t n) {
    CUDA_OP(c, mx_cuda_bf16_to_f32(b_->cc, y, x, n, st_));
}
static void k_f32_to_bf16(const mx_ctx *c, uint16_t *y, const float *x, size_t n) {
    CUDA_OP(c, mx_cuda_f32_to_bf16(b_->cc, y, x, n, st_));
}

static void fill_table(mx_kernels *k) {
    memset(k, 0, sizeof *k);
    k->isa = MX_ISA_SCALAR; /* not a CPU table */
    k->linear = k_linear;
    k->conv2d = k_conv2d;
    k->group_norm = k_group_norm;
    k->layer_norm = k_layer_norm;
    k->softmax = k_softmax;
    k->attention = k_attention;
    k->gelu = k_gelu;
    k->quick_gelu = k_quick_gelu;
    k->silu = k_silu;
    k->geglu = k_geglu;
    k->binary = k_binary;
    k->scale = k_scale;
    k->upsample_nearest2x = k_upsample;
    k->concat_channels = k_concat;
    k->transpose_chw_hwc = k_chw_hwc;
    k->transpose_hwc_chw = k_hwc_chw;
    k->resize_bilinear = k_resize;
    k->pad2d = k_pad2d;
    k->copy = k_copy;
    k->fill = k_fill;
    k->axpy = k_axpy;
    k->lincomb = k_lincomb;
    k->clamp = k_clamp;
    k->affine = k_affine;
    k->timestep_embedding = k_timestep;
    k->embed_tokens = k_embed;
    k->tanh = k_tanh;
    k->copy_rect = k_copy_rect;
    k->f16_to_f32 = k_f16_to_f32;
    k->f32_to_f16 = k_f32_to_f16;
    k->bf16_to_f32 = k_bf16_to_f32;
    k->f32_to_bf16 = k_f32_to_bf16;
}

/* ---- memory and copies ---- */

static void *cuda_alloc(mx_backend *be, size_t bytes, mx_status *st) {
    void *p = NULL;
    (void)be;
    return mx_cuda_alloc(&p, bytes, "cuda device memory", st) ? NULL : p;
}

static void cuda_release(mx_backend *be, void *p) {
    (void)be;
    mx_cuda_free(p);
}

/* The error a queued op raised, once (the backend is usable again after it is reported). */
static int report_failure(cuda_backend *b, mx_status *st) {
    if (!b->failed) return 0;
    b->failed = 0;
    if (st) *st = b->err;
    return -1;
}

static int cuda_to_device(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    if (report_failure(b, st)) return -1;
    return mx_cuda_upload(b->cc, dst, src, bytes, "cuda upload", st);
}

static int cuda_to_host(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    if (mx_cuda_sync(b->cc, st) || report_failure(b, st)) return -1;
    return mx_cuda_download(b->cc, dst, src, bytes, "cuda download", st);
}

static void cuda_destroy(mx_backend *be) {
    cuda_backend *b = (cuda_backend *)be->impl;
    mx_cuda_ctx_destroy(b->cc);
    free(b);
}

int mx_cuda_backend_create(mx_backend **out, mx_status *st) {
    *out = NULL;
    int n = 0;
    mx_cuda_device_count(&n, st);
    if (n < 1) return mx_fail(st, MX_EUSAGE, "--device cuda: no CUDA device found (no NVIDIA GPU or driver)");
    cuda_backend *b = (cuda_backend *)calloc(1, sizeof *b);
    if (!b) return mx_fail(st, MX_ENOMEM, "cuda backend: out of memory");
    if (mx_cuda_ctx_create(&b->cc, 0, CUDA_SCRATCH_BYTES, st)) {
        free(b);
        return mx_fail_prefix(st, "cuda backend");
    }
    fill_table(&b->k);
    b->be.kind = MX_BACKEND_CUDA;
    b->be.k = &b->k;
    b->be.host_visible = 0;
    b->be.alloc = cuda_alloc;
    b->be.release = cuda_release;
    b->be.to_device = cuda_to_device;
    b->be.to_host = cuda_to_host;
    b->be.destroy = cuda_destroy;
    b->be.impl = b;
    *out = &b->be;
    return 0;
}
