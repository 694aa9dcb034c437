/* Internal to ops/: the kernel functions behind the dispatch table (ops/cpu/dispatch.c),
 * the scratch-memory helper and the parallel-for helper they share.
 * Naming: mx_<op>_ref (scalar reference, the test oracle), mx_<op>_avx2, mx_<op>_avx512,
 * mx_<op>_avx512bf16 (bf16 arithmetic, fp32 accumulation), mx_<op>_amx (the same on AMX tiles),
 * mx_<op>_neon and mx_<op>_neonbf16 (aarch64: Advanced SIMD, FEAT_BF16).
 *
 * Files: <family>_ref.c are the references (linear, conv, norm, attention, activation, binary,
 * layout, convert). gemm.c is the blocked GEMM engine behind linear and conv2d; gemm_<isa>.c
 * holds its micro-kernels (the AVX-512 one written once in gemm_micro_avx512.inc for fp32 and bf16). The other SIMD kernels are written once as templates
 * (attention_simd.inc, norm_simd.inc, activation_simd.inc, vmath_simd.inc for exp/erfc) over a
 * small vector vocabulary (simd_avx2.h, simd_avx512.h, simd_neon.h) and instantiated by attention_<isa>.c
 * and elementwise_<isa>.c; convert_<isa>.c are the fp16/bf16 conversions. */
#ifndef MX_OPS_CPU_KERNELS_H
#define MX_OPS_CPU_KERNELS_H

#include <stddef.h>
#include <stdint.h>

#include "../ops.h"

/* Runs fn over ntasks tasks on c->pool (serially when c or its pool is NULL). */
static inline void mx_par_for(const mx_ctx *c, int ntasks, mx_task_fn fn, void *arg) {
    mx_pool_for(c ? c->pool : NULL, ntasks, fn, arg);
}
static inline int mx_par_threads(const mx_ctx *c) { return mx_pool_threads(c ? c->pool : NULL); }

/* Temporary memory for one kernel call: from c->scratch when it has room, else from the heap
 * (so a small scratch arena costs speed, never correctness). Release in reverse order. */
typedef struct mx_scratch {
    void *p;
    size_t mark;
    int heap;
} mx_scratch;
void *mx_scratch_take(const mx_ctx *c, size_t bytes, mx_scratch *s);
void mx_scratch_release(const mx_ctx *c, mx_scratch *s);

#define MX_KERNEL_DECLS(sfx)                                                                                 \
    void mx_linear_##sfx(const mx_ctx *, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N,    \
                         int K);                                                                             \
    void mx_conv2d_##sfx(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,  \
                         mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);                       \
    void mx_group_norm_##sfx(const mx_ctx *, float *y, const float *x, int B, int C, int HW, int groups,     \
                             mx_wptr gamma, mx_wptr beta, float eps, int fuse_silu);                         \
    void mx_layer_norm_##sfx(const mx_ctx *, float *y, const float *x, int M, int C, mx_wptr gamma,          \
                             mx_wptr beta, float eps);                                                       \
    void mx_softmax_##sfx(const mx_ctx *, float *x, int M, int N);                                           \
    void mx_attention_##sfx(const mx_ctx *, float *out, const float *q, const float *k, const float *v,      \
                            int B, int H, int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, \
                            int causal, float scale);                                                        \
    void mx_gelu_##sfx(const mx_ctx *, float *x, size_t n);                                                  \
    void mx_quick_gelu_##sfx(const mx_ctx *, float *x, size_t n);                                            \
    void mx_silu_##sfx(const mx_ctx *, float *x, size_t n);                                                  \
    void mx_geglu_##sfx(const mx_ctx *, float *y, const float *x, int M, int N);                             \
    void mx_binary_##sfx(const mx_ctx *, mx_binop op, float *y, const float *a, const int64_t *ashape,       \
                         const float *b, const int64_t *bshape, int ndim);                                   \
    void mx_scale_##sfx(const mx_ctx *, float *y, const float *x, float s, size_t n);                        \
    void mx_f16_to_f32_##sfx(const mx_ctx *, float *y, const uint16_t *x, size_t n);                                         \
    void mx_f32_to_f16_##sfx(const mx_ctx *, uint16_t *y, const float *x, size_t n);                                         \
    void mx_bf16_to_f32_##sfx(const mx_ctx *, float *y, const uint16_t *x, size_t n);                                        \
    void mx_f32_to_bf16_##sfx(const mx_ctx *, uint16_t *y, const float *x, size_t n);

MX_KERNEL_DECLS(ref)
MX_KERNEL_DECLS(avx2)
MX_KERNEL_DECLS(avx512)
MX_KERNEL_DECLS(neon)

/* The AVX512_BF16 level: bf16 products with fp32 sums for the matrix products; everything else
 * is the AVX-512 fp32 kernels. */
void mx_linear_avx512bf16(const mx_ctx *, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
void mx_conv2d_avx512bf16(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                          mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
void mx_attention_avx512bf16(const mx_ctx *, float *out, const float *q, const float *k, const float *v, int B,
                             int H, int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal,
                             float scale);

/* The AMX level: linear and conv2d on AMX-BF16 tiles (gemm_amx.c); everything else is the
 * AVX512_BF16 level's. */
void mx_linear_amx(const mx_ctx *, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
void mx_conv2d_amx(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w, mx_wptr bias,
                   int Cout, int kh, int kw, int stride, int pad);

/* The aarch64 FEAT_BF16 level: linear, conv2d and attention with BFDOT (bf16 products, fp32
 * sums); everything else is the NEON fp32 kernels. */
void mx_linear_neonbf16(const mx_ctx *, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
void mx_conv2d_neonbf16(const mx_ctx *, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                        mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
void mx_attention_neonbf16(const mx_ctx *, float *out, const float *q, const float *k, const float *v, int B, int H,
                           int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal,
                           float scale);

/* Layout ops have only a reference: they are memory-bound copies the compiler vectorises. */
void mx_upsample_nearest2x_ref(const mx_ctx *, float *y, const float *x, int BC, int H, int W);
void mx_concat_channels_ref(const mx_ctx *, float *y, const float *a, int Ca, const float *b, int Cb, int B,
                            int HW);
void mx_transpose_chw_hwc_ref(const mx_ctx *, float *y, const float *x, int B, int C, int HW);
void mx_transpose_hwc_chw_ref(const mx_ctx *, float *y, const float *x, int B, int C, int HW);
void mx_resize_bilinear_ref(const mx_ctx *, float *y, const float *x, int BC, int H, int W, int Ho, int Wo,
                            int align_corners);
void mx_copy_rect_ref(const mx_ctx *, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx,
                      int sy0, int sx0, int BC, int h, int w);

/* tanh has only a reference (TAESD's latent clamp: memory-bound, small). */
void mx_tanh_ref(const mx_ctx *, float *x, size_t n);

/* The seam ops (pad, copy, fill, vector combinations, embeddings): memory-bound or tiny,
 * one reference for every level. */
void mx_pad2d_ref(const mx_ctx *, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
                  int right);
void mx_copy_ref(const mx_ctx *, float *y, const float *x, size_t n);
void mx_fill_ref(const mx_ctx *, float *y, float v, size_t n);
void mx_axpy_ref(const mx_ctx *, float *y, const float *x, float s, size_t n);
void mx_lincomb_ref(const mx_ctx *, float *y, int k, const float *coef, const float *const *x, size_t n);
void mx_clamp_ref(const mx_ctx *, float *y, const float *x, float lo, float hi, size_t n);
void mx_affine_ref(const mx_ctx *, float *y, const float *x, float a, float b, size_t n);
void mx_timestep_embedding_ref(const mx_ctx *, float *y, const float *t, int B, int dim, int flip_sin_to_cos,
                               float downscale_freq_shift, float max_period);
void mx_embed_tokens_ref(const mx_ctx *, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                         mx_wptr positions);

/* Elements per task of the element-wise kernels: fixed, so the split never depends on threads. */
#define MX_EW_CHUNK 16384

#endif
