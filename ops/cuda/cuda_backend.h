/* The CUDA backend of the matex ops: device memory and kernels with exactly the semantics of the
 * CPU ops of ops/ops.h (the scalar references in ops/cpu/ ..._ref.c files are the oracle). A C interface,
 * callable from C11; the implementation is in the .cu files of ops/cuda, built by `make cuda` into
 * libmx_cuda.a (link with -lcublasLt -lcudart and a C++ linker).
 *
 * Conventions
 * - Every pointer given to an op is a DEVICE pointer, including the data of an mx_wptr
 *   (fp32, fp16 or bf16 weights uploaded as they are stored in the weight file).
 * - Activations are fp32, contiguous, NCHW / [B, T, C] as on the CPU.
 * - All work of one context is queued on its stream; ops return once the work is queued.
 *   mx_cuda_sync waits and reports any error raised while running.
 * - Every function returns 0, or -1 with a message in st naming the op and the problem
 *   (a bad size, an unsupported shape, a CUDA or cuBLASLt error). Nothing aborts.
 * - Math: fp32 weights -> fp32 math (no TF32). fp16/bf16 weights -> the activation is rounded to
 *   the weight's type and the product runs on tensor cores with fp32 accumulation (docs/DESIGN.md §4).
 */
#ifndef MX_CUDA_BACKEND_H
#define MX_CUDA_BACKEND_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#include "../../runtime/status.h"
#include "../ops.h"

typedef struct mx_cuda_ctx mx_cuda_ctx;

/* ---- devices and contexts ---- */

/* Number of usable CUDA devices; 0 (and success) when there is no driver or no device. */
int mx_cuda_device_count(int *count, mx_status *st);
/* A context on `device`: a stream, a cuBLASLt handle and workspace, and a device scratch
 * buffer of scratch_bytes (temporary memory of the ops: converted activations, im2col tiles). */
int mx_cuda_ctx_create(mx_cuda_ctx **ctx, int device, size_t scratch_bytes, mx_status *st);
void mx_cuda_ctx_destroy(mx_cuda_ctx *ctx);
/* Waits for all queued work; reports the first error raised by it. */
int mx_cuda_sync(mx_cuda_ctx *ctx, mx_status *st);

/* ---- device memory (what names the buffer in error messages) ---- */

int mx_cuda_alloc(void **dptr, size_t bytes, const char *what, mx_status *st);
void mx_cuda_free(void *dptr);
/* Synchronous copies (they wait for the context's stream first). */
int mx_cuda_upload(mx_cuda_ctx *ctx, void *dst, const void *src, size_t bytes, const char *what,
                   mx_status *st);
int mx_cuda_download(mx_cuda_ctx *ctx, void *dst, const void *src, size_t bytes, const char *what,
                     mx_status *st);
int mx_cuda_memset_zero(mx_cuda_ctx *ctx, void *dptr, size_t bytes, const char *what, mx_status *st);

/* ---- ops: same arguments and semantics as the mx_* wrappers of ops/ops.h ---- */

int mx_cuda_linear(mx_cuda_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K,
                   mx_status *st);
int mx_cuda_conv2d(mx_cuda_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                   mx_wptr bias, int Cout, int kh, int kw, int stride, int pad, mx_status *st);
int mx_cuda_group_norm(mx_cuda_ctx *c, float *y, const float *x, int B, int C, int HW, int groups,
                       mx_wptr gamma, mx_wptr beta, float eps, int fuse_silu, mx_status *st);
int mx_cuda_layer_norm(mx_cuda_ctx *c, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                       float eps, mx_status *st);
int mx_cuda_softmax(mx_cuda_ctx *c, float *x, int M, int N, mx_status *st);
/* Fused (flash) attention, fp32 math; D (head size) at most MX_CUDA_ATTN_MAX_D. */
#define MX_CUDA_ATTN_MAX_D 512
int mx_cuda_attention(mx_cuda_ctx *c, float *out, const float *q, const float *k, const float *v, int B,
                      int H, int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal,
                      float scale, mx_status *st);
int mx_cuda_gelu(mx_cuda_ctx *c, float *x, size_t n, mx_status *st);
int mx_cuda_quick_gelu(mx_cuda_ctx *c, float *x, size_t n, mx_status *st);
int mx_cuda_silu(mx_cuda_ctx *c, float *x, size_t n, mx_status *st);
int mx_cuda_geglu(mx_cuda_ctx *c, float *y, const float *x, int M, int N, mx_status *st);
int mx_cuda_binary(mx_cuda_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape,
                   const float *b, const int64_t *bshape, int ndim, mx_status *st);
int mx_cuda_scale(mx_cuda_ctx *c, float *y, const float *x, float s, size_t n, mx_status *st);
int mx_cuda_upsample_nearest2x(mx_cuda_ctx *c, float *y, const float *x, int BC, int H, int W, mx_status *st);
int mx_cuda_concat_channels(mx_cuda_ctx *c, float *y, const float *a, int Ca, const float *b, int Cb, int B,
                            int HW, mx_status *st);
int mx_cuda_transpose_chw_hwc(mx_cuda_ctx *c, float *y, const float *x, int B, int C, int HW, mx_status *st);
int mx_cuda_transpose_hwc_chw(mx_cuda_ctx *c, float *y, const float *x, int B, int C, int HW, mx_status *st);
int mx_cuda_resize_bilinear(mx_cuda_ctx *c, float *y, const float *x, int BC, int H, int W, int Ho, int Wo,
                            int align_corners, mx_status *st);
/* Conversions, round to nearest even. */
int mx_cuda_f16_to_f32(mx_cuda_ctx *c, float *y, const uint16_t *x, size_t n, mx_status *st);
int mx_cuda_f32_to_f16(mx_cuda_ctx *c, uint16_t *y, const float *x, size_t n, mx_status *st);
int mx_cuda_bf16_to_f32(mx_cuda_ctx *c, float *y, const uint16_t *x, size_t n, mx_status *st);
int mx_cuda_f32_to_bf16(mx_cuda_ctx *c, uint16_t *y, const float *x, size_t n, mx_status *st);
/* The seam ops (cuda_seam.cu). embed_tokens: ids are HOST integers. */
int mx_cuda_pad2d(mx_cuda_ctx *c, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
                  int right, mx_status *st);
int mx_cuda_copy(mx_cuda_ctx *c, float *y, const float *x, size_t n, mx_status *st);
int mx_cuda_fill(mx_cuda_ctx *c, float *y, float v, size_t n, mx_status *st);
int mx_cuda_axpy(mx_cuda_ctx *c, float *y, const float *x, float s, size_t n, mx_status *st);
int mx_cuda_lincomb(mx_cuda_ctx *c, float *y, int k, const float *coef, const float *const *x, size_t n,
                    mx_status *st);
int mx_cuda_clamp(mx_cuda_ctx *c, float *y, const float *x, float lo, float hi, size_t n, mx_status *st);
int mx_cuda_affine(mx_cuda_ctx *c, float *y, const float *x, float a, float b, size_t n, mx_status *st);
int mx_cuda_timestep_embedding(mx_cuda_ctx *c, float *y, const float *t, int B, int dim, int flip_sin_to_cos,
                               float downscale_freq_shift, float max_period, mx_status *st);
/* TAESD's tanh (in place) and the tiled VAE decode's rectangle copy (cuda_fast.cu). */
int mx_cuda_tanh(mx_cuda_ctx *c, float *x, size_t n, mx_status *st);
int mx_cuda_copy_rect(mx_cuda_ctx *c, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx,
                      int sy0, int sx0, int BC, int h, int w, mx_status *st);
int mx_cuda_embed_tokens(mx_cuda_ctx *c, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                         mx_wptr positions, mx_status *st);

/* The CUDA backend of runtime/backend.h on device 0: every op of ops.h through a kernel table of
 * the functions above (errors are kept and reported by the next copy to the host), device
 * memory, host copies. Fails with one line when there is no usable device. */
int mx_cuda_backend_create(mx_backend **out, mx_status *st);

/* out[i] = mx_rng_normal(seed, stream, first + i) of runtime/rng.h, bit for bit. */
int mx_cuda_rng_fill_normal(mx_cuda_ctx *c, float *out, size_t n, uint64_t seed, uint64_t stream,
                            uint64_t first, mx_status *st);

#ifdef __cplusplus
}
#endif

#endif
