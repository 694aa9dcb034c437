/* The op interface of matex. Every op has a scalar reference (ops/cpu/<op>_ref.c, the test
 * oracle) and SIMD kernels (ops/cpu/<op>_avx2.c, <op>_avx512.c), all behind one table of function
 * pointers chosen once at run time by cpuid; the CUDA backend has a table of its own
 * (ops/cuda). Networks call the mx_* wrappers below and nothing else touches activations.
 *
 * Conventions
 * - Activations are fp32, contiguous, row-major. Images/feature maps are NCHW
 *   (as in PyTorch); token sequences are [B, T, C]. A `float *` activation is a handle into the
 *   memory of the context's backend (runtime/backend.h): only ops dereference it; offsets into
 *   it (p + i) are fine. Host data enters and leaves through mx_upload / mx_download.
 * - The measuring dry run lives here: on a measuring context (mx_ctx_measuring, what
 *   mx_run_ctx gives for a measuring arena) every op returns at once, and mx_act_alloc hands
 *   out placeholder handles while the arena counts the bytes.
 * - Weights are an mx_wptr: fp32, fp16 or bf16 data widened to fp32 as it is read.
 *   A weight with data == NULL (e.g. a missing bias) means "none".
 * - Linear weights are PyTorch's [N, K] (out_features, in_features); conv weights are
 *   [Cout, Cin, kh, kw].
 * - All ops may use ctx->pool for threads and ctx->scratch for temporary memory
 *   (they restore the scratch mark before returning). Results never depend on the thread count.
 *   Scratch the SIMD kernels take per call: linear/conv2d (min(M, 4096) + min(N, 4096) + 44)
 *   · min(K, 320) + max(M, N) floats (conv: M = Cout, N = Ho·Wo, K = Cin·kh·kw; at most ~11 MB);
 *   attention B·H·D·(Tk + 63) + threads·64·(2D + 2) floats; layer norm 2C floats. With less
 *   (or no) scratch they use the heap, so a small arena costs speed, never correctness.
 *   32 MiB covers SD1.5 at 512×512 (UNet with CFG batch 2, VAE mid-block attention).
 * - Output buffers must not alias inputs unless an op says "in place".
 */
#ifndef MX_OPS_H
#define MX_OPS_H

#include <stddef.h>
#include <stdint.h>

#include "../runtime/arena.h"
#include "../runtime/backend.h"
#include "../runtime/half.h"
#include "../runtime/tensor.h"
#include "../runtime/threadpool.h"

typedef struct mx_wptr {
    const void *data;
    mx_dtype dtype; /* MX_F32, MX_F16 or MX_BF16 */
} mx_wptr;

static inline mx_wptr mx_w_f32(const float *p) { mx_wptr w = {p, MX_F32}; return w; }
static inline mx_wptr mx_w_none(void) { mx_wptr w = {NULL, MX_F32}; return w; }
/* Element i of a weight, widened to fp32. */
float mx_w_get(mx_wptr w, size_t i);

typedef struct mx_kernels mx_kernels;

typedef struct mx_ctx {
    mx_pool *pool;           /* NULL: single-threaded */
    const mx_kernels *k;     /* dispatch table (mx_kernels_for, or the backend's) */
    mx_arena *scratch;       /* temporary memory for kernels; must be a real (non-measuring) arena */
    mx_backend *be;          /* where activations live; NULL: host memory, no guard */
    int measuring;           /* 1: dry run, every op returns at once */
} mx_ctx;

typedef enum { MX_BIN_ADD = 0, MX_BIN_SUB = 1, MX_BIN_MUL = 2 } mx_binop;

/* The dispatch table. Each entry has exactly the semantics of the wrapper of the same name. */
struct mx_kernels {
    mx_isa isa;
    void (*linear)(const mx_ctx *, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
    void (*conv2d)(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                   mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
    void (*group_norm)(const mx_ctx *, float *y, const float *x, int B, int C, int HW, int groups,
                       mx_wptr gamma, mx_wptr beta, float eps, int fuse_silu);
    void (*layer_norm)(const mx_ctx *, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                       float eps);
    void (*softmax)(const mx_ctx *, float *x, int M, int N);
    void (*attention)(const mx_ctx *, float *out, const float *q, const float *k, const float *v, int B,
                      int H, int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal,
                      float scale);
    void (*gelu)(const mx_ctx *, float *x, size_t n);
    void (*quick_gelu)(const mx_ctx *, float *x, size_t n);
    void (*silu)(const mx_ctx *, float *x, size_t n);
    void (*geglu)(const mx_ctx *, float *y, const float *x, int M, int N);
    void (*binary)(const mx_ctx *, mx_binop op, float *y, const float *a, const int64_t *ashape,
                   const float *b, const int64_t *bshape, int ndim);
    void (*scale)(const mx_ctx *, float *y, const float *x, float s, size_t n);
    void (*upsample_nearest2x)(const mx_ctx *, float *y, const float *x, int BC, int H, int W);
    void (*concat_channels)(const mx_ctx *, float *y, const float *a, int Ca, const float *b, int Cb, int B,
                            int HW);
    void (*transpose_chw_hwc)(const mx_ctx *, float *y, const float *x, int B, int C, int HW);
    void (*transpose_hwc_chw)(const mx_ctx *, float *y, const float *x, int B, int C, int HW);
    void (*resize_bilinear)(const mx_ctx *, float *y, const float *x, int BC, int H, int W, int Ho, int Wo,
                            int align_corners);
    void (*copy_rect)(const mx_ctx *, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx,
                      int sy0, int sx0, int BC, int h, int w);
    void (*pad2d)(const mx_ctx *, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
                  int right);
    void (*copy)(const mx_ctx *, float *y, const float *x, size_t n);
    void (*fill)(const mx_ctx *, float *y, float v, size_t n);
    void (*axpy)(const mx_ctx *, float *y, const float *x, float s, size_t n);
    void (*lincomb)(const mx_ctx *, float *y, int k, const float *coef, const float *const *x, size_t n);
    void (*clamp)(const mx_ctx *, float *y, const float *x, float lo, float hi, size_t n);
    void (*tanh)(const mx_ctx *, float *x, size_t n);
    void (*affine)(const mx_ctx *, float *y, const float *x, float a, float b, size_t n);
    void (*timestep_embedding)(const mx_ctx *, float *y, const float *t, int B, int dim, int flip_sin_to_cos,
                               float downscale_freq_shift, float max_period);
    void (*embed_tokens)(const mx_ctx *, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                         mx_wptr positions);
    void (*f16_to_f32)(const mx_ctx *, float *y, const uint16_t *x, size_t n);
    void (*f32_to_f16)(const mx_ctx *, uint16_t *y, const float *x, size_t n);
    void (*bf16_to_f32)(const mx_ctx *, float *y, const uint16_t *x, size_t n);
    void (*f32_to_bf16)(const mx_ctx *, uint16_t *y, const float *x, size_t n);
};

/* The table for an ISA level (clamped to what this CPU supports). */
const mx_kernels *mx_kernels_for(mx_isa isa);
/* c computing in fp32: a copy whose table is the fp32 level below c's when c's computes in bf16
 * (avx512bf16 -> avx512), c's own otherwise (CUDA keeps its table). Same pool, scratch,
 * backend. For the layers the precision policy keeps in fp32 (pipeline/nn/precision.h). */
mx_ctx mx_ctx_fp32(const mx_ctx *c);
/* The scalar reference table (the test oracle). */
const mx_kernels *mx_kernels_scalar(void);
/* The best fp32 table for this CPU (mx_cpu_isa_for(MX_PREC_FP32)): what a context without a
 * table gets. */
const mx_kernels *mx_kernels_best(void);

/* ---- wrappers: the op semantics ---- */

/* y[M,N] = x[M,K] · w[N,K]^T + bias[N]. */
void mx_linear(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
/* 2-D convolution, NCHW, square kernel (kh x kw, 1x1 or 3x3 in SD; any size is correct),
 * zero padding `pad` on each side; Ho = (H + 2 pad - kh)/stride + 1, same for Wo. */
void mx_conv2d(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
               mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
/* Group norm over (C/groups channels × HW) per batch item and group, biased variance,
 * then per-channel affine; fuse_silu applies SiLU after. y may equal x (in place). */
void mx_group_norm(const mx_ctx *c, float *y, const float *x, int B, int C, int HW, int groups, mx_wptr gamma,
                   mx_wptr beta, float eps, int fuse_silu);
/* Layer norm over the last dimension C of x[M, C]. y may equal x. */
void mx_layer_norm(const mx_ctx *c, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                   float eps);
/* Softmax over each row of x[M, N], in place. */
void mx_softmax(const mx_ctx *c, float *x, int M, int N);
/* Multi-head attention, softmax(q·k^T·scale [+ causal mask]) · v, streaming over keys
 * (never builds the Tq×Tk score matrix).
 * q: [B, Tq, ·] with head h of token t at q + (b*Tq + t)*q_stride + h*D; k, v likewise with kv_stride
 * and Tk tokens; out: [B, Tq, ·] with out_stride. causal: key j is masked for query i when j > i. */
void mx_attention(const mx_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                  int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal, float scale);
/* In place: GELU with erf, quick-GELU x·σ(1.702x) (CLIP), SiLU x·σ(x). */
void mx_gelu(const mx_ctx *c, float *x, size_t n);
void mx_quick_gelu(const mx_ctx *c, float *x, size_t n);
void mx_silu(const mx_ctx *c, float *x, size_t n);
/* In place: tanh (TAESD's latent clamp 3 tanh(x / 3)). */
void mx_tanh(const mx_ctx *c, float *x, size_t n);
/* GEGLU (diffusers): x[M, 2N] = [h | g]; y[M, N] = h * gelu(g). */
void mx_geglu(const mx_ctx *c, float *y, const float *x, int M, int N);
/* y = a op b with numpy broadcasting over ndim (1..5) dims; y has the broadcast shape.
 * y may equal a when a has the output shape. */
void mx_binary(const mx_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b,
               const int64_t *bshape, int ndim);
/* Same-shape shortcuts of mx_binary. */
void mx_add(const mx_ctx *c, float *y, const float *a, const float *b, size_t n);
void mx_mul(const mx_ctx *c, float *y, const float *a, const float *b, size_t n);
/* y = s * x (y may equal x). */
void mx_scale(const mx_ctx *c, float *y, const float *x, float s, size_t n);
/* Nearest-neighbour 2× upsample of BC planes of H×W into 2H×2W. */
void mx_upsample_nearest2x(const mx_ctx *c, float *y, const float *x, int BC, int H, int W);
/* Channel concat of a[B, Ca, HW] and b[B, Cb, HW] into y[B, Ca+Cb, HW]. */
void mx_concat_channels(const mx_ctx *c, float *y, const float *a, int Ca, const float *b, int Cb, int B, int HW);
/* [B, C, HW] <-> [B, HW, C]. */
void mx_transpose_chw_hwc(const mx_ctx *c, float *y, const float *x, int B, int C, int HW);
void mx_transpose_hwc_chw(const mx_ctx *c, float *y, const float *x, int B, int C, int HW);
/* Bilinear resize of BC planes H×W -> Ho×Wo; align_corners as in PyTorch's F.interpolate
 * (0: half-pixel centres, no antialias). */
void mx_resize_bilinear(const mx_ctx *c, float *y, const float *x, int BC, int H, int W, int Ho, int Wo,
                        int align_corners);
/* Rectangle copy over BC planes: y[p, y0 + r, x0 + q] = x[p, sy0 + r, sx0 + q] for r < h, q < w, with
 * y planes Hy×Wy and x planes Hx×Wx (the rectangle must lie inside both). Crops, pastes, tiles. */
void mx_copy_rect(const mx_ctx *c, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx, int sy0,
                  int sx0, int BC, int h, int w);
/* Zero padding of BC planes H×W by (top, bottom, left, right) rows/columns, each >= 0
 * (diffusers' asymmetric Downsample2D pad is (0, 1, 0, 1)). */
void mx_pad2d(const mx_ctx *c, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
              int right);
/* y = x over n floats (no overlap), y[i] = v, y += s·x, y = Σ_j coef[j]·x[j] (k <= 4 terms,
 * summed left to right; y may be one of the x), y = clamp(x, lo, hi), y = a·x + b. */
void mx_copy(const mx_ctx *c, float *y, const float *x, size_t n);
void mx_fill(const mx_ctx *c, float *y, float v, size_t n);
void mx_axpy(const mx_ctx *c, float *y, const float *x, float s, size_t n);
#define MX_LINCOMB_MAX 4
void mx_lincomb(const mx_ctx *c, float *y, int k, const float *coef, const float *const *x, size_t n);
void mx_clamp(const mx_ctx *c, float *y, const float *x, float lo, float hi, size_t n);
void mx_affine(const mx_ctx *c, float *y, const float *x, float a, float b, size_t n);
/* y[b, t, :] = tokens[ids[b·T + t], :] + positions[t, :] (C columns). ids are HOST integers,
 * already checked against the vocabulary by the caller. */
void mx_embed_tokens(const mx_ctx *c, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                     mx_wptr positions);
/* Sinusoidal timestep embedding exactly as diffusers' get_timestep_embedding:
 * half = dim/2, exponent_k = -ln(max_period) * k / (half - downscale_freq_shift),
 * emb = t * exp(exponent); out = [sin | cos] (or [cos | sin] when flip_sin_to_cos); zero pad if dim odd.
 * y: [B, dim]. SD1.5: flip_sin_to_cos=1, downscale_freq_shift=0, max_period=10000. */
void mx_timestep_embedding(const mx_ctx *c, float *y, const float *t, int B, int dim, int flip_sin_to_cos,
                           float downscale_freq_shift, float max_period);
/* Conversions (round to nearest even; NaN stays NaN). */
void mx_f16_to_f32(const mx_ctx *c, float *y, const uint16_t *x, size_t n);
void mx_f32_to_f16(const mx_ctx *c, uint16_t *y, const float *x, size_t n);
void mx_bf16_to_f32(const mx_ctx *c, float *y, const uint16_t *x, size_t n);
void mx_f32_to_bf16(const mx_ctx *c, uint16_t *y, const float *x, size_t n);
/* Scalar conversions, usable anywhere: runtime/half.h (included above). */

/* ---- the edges: backend memory and host copies ---- */

/* n floats of the context's backend memory (host heap without a backend); NULL with a
 * message when out of memory. Free with mx_dev_free. */
float *mx_dev_alloc(const mx_ctx *c, size_t n, mx_status *st);
void mx_dev_free(const mx_ctx *c, void *p);
/* Copies n floats host -> backend (mx_upload) or backend -> host (mx_download, which waits
 * for the queued ops first and reports an error any of them raised). */
int mx_upload(const mx_ctx *c, float *dst, const float *src, size_t n, mx_status *st);
int mx_download(const mx_ctx *c, float *dst, const float *src, size_t n, mx_status *st);
/* Backend memory holding a copy of n host floats (mx_dev_alloc + mx_upload). */
float *mx_dev_from_host(const mx_ctx *c, const float *src, size_t n, mx_status *st);

/* ---- the dry run ---- */

/* The context of a measuring dry run: every op returns at once. */
const mx_ctx *mx_ctx_measuring(void);
/* The context ops of a run in arena a get: mx_ctx_measuring() when a is measuring, else c. */
const mx_ctx *mx_run_ctx(const mx_ctx *c, const mx_arena *a);
/* n activation floats from the arena; in a measuring arena a placeholder handle (never NULL:
 * the arena only counts), so forward code needs no special case. NULL only on failure. */
float *mx_act_alloc(mx_arena *a, size_t n, mx_status *st);
/* A placeholder handle for the outputs of a dry run (ops on a measuring context ignore it). */
float *mx_act_placeholder(void);

/* A ready-to-use context: best kernels, a pool of nthreads (<=0: all CPUs) and a scratch
 * arena of scratch_bytes. Free with mx_ctx_destroy. */
int mx_ctx_create(mx_ctx *c, int nthreads, mx_isa isa, size_t scratch_bytes, mx_status *st);
/* The same on a backend of the given kind (cpu-strict and cuda own the activations; the
 * context owns the backend). A kind this binary lacks fails with one clear line. */
int mx_ctx_create_on(mx_ctx *c, mx_backend_kind kind, int nthreads, mx_isa isa, size_t scratch_bytes,
                     mx_status *st);
void mx_ctx_destroy(mx_ctx *c);

/* Makes a backend (ops/backend.c): kernels for `isa` on the CPU kinds. */
int mx_backend_create(mx_backend **out, mx_backend_kind kind, mx_isa isa, mx_status *st);
void mx_backend_destroy(mx_backend *be);

#endif
