/* The op wrappers (ops.h), weight access, scalar conversions, the timestep embedding and
 * the ready-made context. */
#include "ops.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cpu/kernels.h"

float mx_w_get(mx_wptr w, size_t i) {
    switch (w.dtype) {
    case MX_F16: return mx_half_to_float(((const uint16_t *)w.data)[i]);
    case MX_BF16: return mx_bf16_to_float(((const uint16_t *)w.data)[i]);
    default: return ((const float *)w.data)[i];
    }
}

void *mx_scratch_take(const mx_ctx *c, size_t bytes, mx_scratch *s) {
    memset(s, 0, sizeof *s);
    if (c && c->scratch && !c->scratch->measuring) {
        s->mark = mx_arena_mark(c->scratch);
        s->p = mx_arena_alloc(c->scratch, bytes, NULL);
        if (s->p) return s->p;
    }
    s->heap = 1;
    s->p = aligned_alloc(MX_ARENA_ALIGN, (bytes + MX_ARENA_ALIGN - 1) / MX_ARENA_ALIGN * MX_ARENA_ALIGN);
    return s->p;
}

void mx_scratch_release(const mx_ctx *c, mx_scratch *s) {
    if (s->heap)
        free(s->p);
    else if (s->p)
        mx_arena_reset(c->scratch, s->mark);
    s->p = NULL;
}

/* The kernels of one op call, or NULL in a dry run. The backend's enter/leave bracket the
 * kernel (cpu-strict opens its memory only for that long). */
static const mx_kernels *op_begin(const mx_ctx *c) {
    if (!c) return mx_kernels_best();
    if (c->measuring) return NULL;
    if (c->be && c->be->enter) c->be->enter(c->be);
    return c->k ? c->k : mx_kernels_best();
}

static void op_end(const mx_ctx *c) {
    if (c && c->be && c->be->leave) c->be->leave(c->be);
}

#define RUN_OP(c, call)                                                                                      \
    do {                                                                                                     \
        const mx_kernels *k_ = op_begin(c);                                                                  \
        if (k_) {                                                                                            \
            k_->call;                                                                                        \
            op_end(c);                                                                                       \
        }                                                                                                    \
    } while (0)

void mx_linear(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    if (M > 0 && N > 0) RUN_OP(c, linear(c, y, x, w, bias, M, N, K));
}

void mx_conv2d(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
               mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    if (B > 0 && Cout > 0) RUN_OP(c, conv2d(c, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad));
}

void mx_group_norm(const mx_ctx *c, float *y, const float *x, int B, int C, int HW, int groups, mx_wptr gamma,
                   mx_wptr beta, float eps, int fuse_silu) {
    if (B > 0 && C > 0 && HW > 0) RUN_OP(c, group_norm(c, y, x, B, C, HW, groups, gamma, beta, eps, fuse_silu));
}

void mx_layer_norm(const mx_ctx *c, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                   float eps) {
    if (M > 0 && C > 0) RUN_OP(c, layer_norm(c, y, x, M, C, gamma, beta, eps));
}

void mx_softmax(const mx_ctx *c, float *x, int M, int N) {
    if (M > 0 && N > 0) RUN_OP(c, softmax(c, x, M, N));
}

void mx_attention(const mx_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                  int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal, float scale) {
    if (B > 0 && H > 0 && Tq > 0 && Tk > 0 && D > 0)
        RUN_OP(c, attention(c, out, q, k, v, B, H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal, scale));
}

void mx_gelu(const mx_ctx *c, float *x, size_t n) { RUN_OP(c, gelu(c, x, n)); }
void mx_quick_gelu(const mx_ctx *c, float *x, size_t n) { RUN_OP(c, quick_gelu(c, x, n)); }
void mx_silu(const mx_ctx *c, float *x, size_t n) { RUN_OP(c, silu(c, x, n)); }
void mx_tanh(const mx_ctx *c, float *x, size_t n) { RUN_OP(c, tanh(c, x, n)); }

void mx_geglu(const mx_ctx *c, float *y, const float *x, int M, int N) {
    if (M > 0 && N > 0) RUN_OP(c, geglu(c, y, x, M, N));
}

void mx_binary(const mx_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b,
               const int64_t *bshape, int ndim) {
    RUN_OP(c, binary(c, op, y, a, ashape, b, bshape, ndim));
}

void mx_add(const mx_ctx *c, float *y, const float *a, const float *b, size_t n) {
    int64_t shape[1] = {(int64_t)n};
    mx_binary(c, MX_BIN_ADD, y, a, shape, b, shape, 1);
}

void mx_mul(const mx_ctx *c, float *y, const float *a, const float *b, size_t n) {
    int64_t shape[1] = {(int64_t)n};
    mx_binary(c, MX_BIN_MUL, y, a, shape, b, shape, 1);
}

void mx_scale(const mx_ctx *c, float *y, const float *x, float s, size_t n) { RUN_OP(c, scale(c, y, x, s, n)); }

void mx_upsample_nearest2x(const mx_ctx *c, float *y, const float *x, int BC, int H, int W) {
    RUN_OP(c, upsample_nearest2x(c, y, x, BC, H, W));
}

void mx_concat_channels(const mx_ctx *c, float *y, const float *a, int Ca, const float *b, int Cb, int B,
                        int HW) {
    RUN_OP(c, concat_channels(c, y, a, Ca, b, Cb, B, HW));
}

void mx_transpose_chw_hwc(const mx_ctx *c, float *y, const float *x, int B, int C, int HW) {
    RUN_OP(c, transpose_chw_hwc(c, y, x, B, C, HW));
}

void mx_transpose_hwc_chw(const mx_ctx *c, float *y, const float *x, int B, int C, int HW) {
    RUN_OP(c, transpose_hwc_chw(c, y, x, B, C, HW));
}

void mx_copy_rect(const mx_ctx *c, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx, int sy0,
                  int sx0, int BC, int h, int w) {
    if (BC > 0 && h > 0 && w > 0) RUN_OP(c, copy_rect(c, y, Hy, Wy, y0, x0, x, Hx, Wx, sy0, sx0, BC, h, w));
}

void mx_resize_bilinear(const mx_ctx *c, float *y, const float *x, int BC, int H, int W, int Ho, int Wo,
                        int align_corners) {
    RUN_OP(c, resize_bilinear(c, y, x, BC, H, W, Ho, Wo, align_corners));
}

void mx_pad2d(const mx_ctx *c, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
              int right) {
    if (BC > 0 && H > 0 && W > 0) RUN_OP(c, pad2d(c, y, x, BC, H, W, top, bottom, left, right));
}

void mx_copy(const mx_ctx *c, float *y, const float *x, size_t n) {
    if (n) RUN_OP(c, copy(c, y, x, n));
}

void mx_fill(const mx_ctx *c, float *y, float v, size_t n) {
    if (n) RUN_OP(c, fill(c, y, v, n));
}

void mx_axpy(const mx_ctx *c, float *y, const float *x, float s, size_t n) {
    if (n) RUN_OP(c, axpy(c, y, x, s, n));
}

void mx_lincomb(const mx_ctx *c, float *y, int k, const float *coef, const float *const *x, size_t n) {
    if (n && k >= 1 && k <= MX_LINCOMB_MAX) RUN_OP(c, lincomb(c, y, k, coef, x, n));
}

void mx_clamp(const mx_ctx *c, float *y, const float *x, float lo, float hi, size_t n) {
    if (n) RUN_OP(c, clamp(c, y, x, lo, hi, n));
}

void mx_affine(const mx_ctx *c, float *y, const float *x, float a, float b, size_t n) {
    if (n) RUN_OP(c, affine(c, y, x, a, b, n));
}

void mx_embed_tokens(const mx_ctx *c, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                     mx_wptr positions) {
    if (B > 0 && T > 0 && C > 0) RUN_OP(c, embed_tokens(c, y, ids, B, T, C, tokens, positions));
}

void mx_timestep_embedding(const mx_ctx *c, float *y, const float *t, int B, int dim, int flip_sin_to_cos,
                           float downscale_freq_shift, float max_period) {
    if (B > 0 && dim > 0)
        RUN_OP(c, timestep_embedding(c, y, t, B, dim, flip_sin_to_cos, downscale_freq_shift, max_period));
}

void mx_f16_to_f32(const mx_ctx *c, float *y, const uint16_t *x, size_t n) { RUN_OP(c, f16_to_f32(c, y, x, n)); }
void mx_f32_to_f16(const mx_ctx *c, uint16_t *y, const float *x, size_t n) { RUN_OP(c, f32_to_f16(c, y, x, n)); }
void mx_bf16_to_f32(const mx_ctx *c, float *y, const uint16_t *x, size_t n) { RUN_OP(c, bf16_to_f32(c, y, x, n)); }
void mx_f32_to_bf16(const mx_ctx *c, uint16_t *y, const float *x, size_t n) { RUN_OP(c, f32_to_bf16(c, y, x, n)); }

/* ---- the edges ---- */

float *mx_dev_alloc(const mx_ctx *c, size_t n, mx_status *st) {
    if (n > SIZE_MAX / sizeof(float) - MX_ARENA_ALIGN) {
        mx_fail(st, MX_ENOMEM, "device memory: %zu floats overflow", n);
        return NULL;
    }
    size_t bytes = (n * sizeof(float) + MX_ARENA_ALIGN - 1) / MX_ARENA_ALIGN * MX_ARENA_ALIGN;
    if (c && c->be) return c->be->alloc(c->be, bytes ? bytes : MX_ARENA_ALIGN, st);
    float *p = aligned_alloc(MX_ARENA_ALIGN, bytes ? bytes : MX_ARENA_ALIGN);
    if (!p) mx_fail(st, MX_ENOMEM, "out of memory (%zu bytes)", bytes);
    return p;
}

void mx_dev_free(const mx_ctx *c, void *p) {
    if (!p) return;
    if (c && c->be)
        c->be->release(c->be, p);
    else
        free(p);
}

int mx_upload(const mx_ctx *c, float *dst, const float *src, size_t n, mx_status *st) {
    if (c && c->measuring) return 0;
    if (c && c->be) return c->be->to_device(c->be, dst, src, n * sizeof(float), st);
    if (n) memcpy(dst, src, n * sizeof(float));
    return 0;
}

int mx_download(const mx_ctx *c, float *dst, const float *src, size_t n, mx_status *st) {
    if (c && c->measuring) return 0;
    if (c && c->be) return c->be->to_host(c->be, dst, src, n * sizeof(float), st);
    if (n) memcpy(dst, src, n * sizeof(float));
    return 0;
}

float *mx_dev_from_host(const mx_ctx *c, const float *src, size_t n, mx_status *st) {
    float *p = mx_dev_alloc(c, n, st);
    if (p && mx_upload(c, p, src, n, st)) {
        mx_dev_free(c, p);
        return NULL;
    }
    return p;
}

/* ---- the dry run ---- */

static const mx_ctx measuring_ctx = {.measuring = 1};

const mx_ctx *mx_ctx_measuring(void) { return &measuring_ctx; }

const mx_ctx *mx_run_ctx(const mx_ctx *c, const mx_arena *a) { return a->measuring ? &measuring_ctx : c; }

/* What a measuring arena hands out: ops never dereference it (they return at once). */
static _Alignas(MX_ARENA_ALIGN) float placeholder[MX_ARENA_ALIGN / sizeof(float)];

float *mx_act_alloc(mx_arena *a, size_t n, mx_status *st) {
    float *p = mx_arena_floats(a, n, st);
    return a->measuring ? placeholder : p;
}

float *mx_act_placeholder(void) { return placeholder; }

mx_ctx mx_ctx_fp32(const mx_ctx *c) {
    mx_ctx f;
    memset(&f, 0, sizeof f);
    if (!c) return f;
    f = *c;
    if (c->k && mx_isa_precision(c->k->isa) == MX_PREC_BF16) f.k = mx_kernels_for(mx_cpu_isa_for(MX_PREC_FP32));
    return f;
}

int mx_ctx_create(mx_ctx *c, int nthreads, mx_isa isa, size_t scratch_bytes, mx_status *st) {
    return mx_ctx_create_on(c, MX_BACKEND_CPU, nthreads, isa, scratch_bytes, st);
}

int mx_ctx_create_on(mx_ctx *c, mx_backend_kind kind, int nthreads, mx_isa isa, size_t scratch_bytes,
                     mx_status *st) {
    memset(c, 0, sizeof *c);
    if (mx_backend_create(&c->be, kind, isa, st)) return -1;
    c->k = c->be->k;
    c->pool = mx_pool_create(nthreads, st);
    if (!c->pool) {
        mx_ctx_destroy(c); /* the backend is already made */
        return -1;
    }
    c->scratch = malloc(sizeof *c->scratch);
    if (!c->scratch) {
        mx_ctx_destroy(c);
        return mx_fail(st, MX_ENOMEM, "ops context: out of memory");
    }
    if (mx_arena_create(c->scratch, scratch_bytes, st) != 0) {
        free(c->scratch);
        c->scratch = NULL;
        mx_ctx_destroy(c);
        return mx_fail_prefix(st, "ops context scratch");
    }
    return 0;
}

void mx_ctx_destroy(mx_ctx *c) {
    if (c->scratch) {
        mx_arena_destroy(c->scratch);
        free(c->scratch);
    }
    mx_pool_destroy(c->pool);
    mx_backend_destroy(c->be);
    memset(c, 0, sizeof *c);
}
