/* Shared by the .cu files of the CUDA backend (not part of the C interface): the context
 * layout, error checks that fill an mx_status, the device scratch buffer, launch sizes and
 * the weight loader that widens fp16/bf16 to fp32. */
#ifndef MX_CUDA_COMMON_CUH
#define MX_CUDA_COMMON_CUH

#include <math.h>
#include <stdlib.h>

#include <cublasLt.h>
#include <cuda_bf16.h>
#include <cuda_fp16.h>
#include <cuda_runtime.h>

#include "cuda_backend.h"

struct mx_cuda_ctx {
    cudaStream_t stream;
    cublasLtHandle_t lt;
    void *workspace; /* cuBLASLt workspace */
    size_t workspace_bytes;
    unsigned char *scratch; /* device bump buffer for temporaries of one op */
    size_t scratch_cap;
    size_t scratch_used;
    /* Host-to-device copies go through two pinned staging halves, used in turn: the host fills
     * one while the copy engine reads the other (mx_cuda_upload_staged). */
    unsigned char *staging[2];
    cudaEvent_t staging_done[2]; /* recorded after the copy out of each half */
    size_t staging_bytes;        /* of each half; 0: no staging, plain copies */
    int staging_next;
    unsigned long long half_products; /* GEMMs run on fp16/bf16 inputs (mx_cuda_half_products) */
    unsigned long long cudnn_convs;   /* conv2d calls run by cuDNN (mx_cuda_ctx_cudnn_convs) */
    /* Where staged uploads spend their time (mx_cuda_backend_upload_stats): host copies into the
     * staging halves, waits for a half the copy engine still reads, and the bytes. */
    double upload_copy_s, upload_wait_s;
    unsigned long long upload_bytes;
    unsigned long long flash_calls;   /* attention calls run by the fused kernel (mx_cuda_ctx_flash_calls) */
    int flash_attn; /* MATEX_CUDA_FLASH=1: half-precision attention through cuda_flash.cu */
    int attn_fp32; /* the last linear had fp32 weights: attention (fed by it) in fp32 */
    struct mx_cuda_gemm_plans *gemm_plans; /* cuBLASLt plans by shape (cuda_gemm.cu), made on first use */
    struct mx_cuda_cudnn *cudnn; /* conv2d through cuDNN (cuda_cudnn.cu); NULL: im2col + cuBLASLt */
    int capturing; /* the stream is being captured as a CUDA graph (cuda_graph.cu) */
};

/* 0 when e is cudaSuccess, else -1 with "what: CUDA error name: text". */
static inline int mx_cuda_ok(cudaError_t e, const char *what, mx_status *st) {
    if (e == cudaSuccess) return 0;
    return mx_fail(st, MX_EINTERNAL, "%s: CUDA error %s: %s", what, cudaGetErrorName(e), cudaGetErrorString(e));
}

/* 0, or -1 naming `what` while the context's stream is captured as a CUDA graph: host copies,
 * waits, allocations and new plans or buffers cannot be part of a graph that is replayed without
 * its host code (cuda_graph.cu, docs/cuda-notes.md §11); the capture then fails and the work runs
 * op by op. */
static inline int mx_cuda_not_capturing(const mx_cuda_ctx *c, const char *what, mx_status *st) {
    if (!c->capturing) return 0;
    return mx_fail(st, MX_EINTERNAL, "%s while a CUDA graph is captured (a replay would not redo it)", what);
}

/* Call right after a kernel launch: reports a bad launch configuration at once. */
static inline int mx_cuda_launched(const char *what, mx_status *st) {
    return mx_cuda_ok(cudaGetLastError(), what, st);
}

/* Temporary device memory of one op, 256-byte aligned; the op resets scratch_used before returning.
 * The next op may reuse those bytes at once: all kernels of a context run in the order of its one
 * stream, so they cannot overwrite memory that an earlier queued kernel still reads. */
static inline void *mx_cuda_scratch(mx_cuda_ctx *c, size_t bytes, const char *what, mx_status *st) {
    size_t start = (c->scratch_used + 255) & ~(size_t)255;
    if (start > c->scratch_cap || bytes > c->scratch_cap - start) {
        mx_fail(st, MX_ENOMEM, "%s: needs %zu bytes of CUDA scratch, %zu of %zu left", what, bytes,
                c->scratch_cap - (start < c->scratch_cap ? start : c->scratch_cap), c->scratch_cap);
        return NULL;
    }
    c->scratch_used = start + bytes;
    return c->scratch + start;
}

/* v rounded (nearest even) to T. */
template <typename T> __device__ __forceinline__ T mx_cuda_store(float v);
template <> __device__ __forceinline__ float mx_cuda_store<float>(float v) { return v; }
template <> __device__ __forceinline__ __half mx_cuda_store<__half>(float v) { return __float2half_rn(v); }
template <> __device__ __forceinline__ __nv_bfloat16 mx_cuda_store<__nv_bfloat16>(float v) {
    return __float2bfloat16_rn(v);
}

/* Blocks for an elementwise grid-stride loop over n items. */
static inline unsigned mx_cuda_blocks(size_t n, unsigned threads) {
    size_t b = (n + threads - 1) / threads;
    if (b > 65535u * 8u) b = 65535u * 8u;
    return b ? (unsigned)b : 1u;
}

/* Grid-stride loop over n items (grids from mx_cuda_blocks). */
#define MX_CUDA_GRID_STRIDE(i, n) \
    for (size_t i = blockIdx.x * (size_t)blockDim.x + threadIdx.x; i < (n); i += (size_t)gridDim.x * blockDim.x)

/* Element i of a weight in device memory, widened to fp32. */
__device__ __forceinline__ float mx_cuda_wload(const void *p, int dtype, size_t i) {
    if (dtype == MX_F16) return __half2float(((const __half *)p)[i]);
    if (dtype == MX_BF16) return __bfloat162float(((const __nv_bfloat16 *)p)[i]);
    return ((const float *)p)[i];
}

/* Sums of a block: every thread passes its value, every thread gets the total. shm holds 32 floats;
 * blockDim.x must be a multiple of 32. The order of additions is fixed by the launch shape. */
__device__ __forceinline__ float mx_cuda_warp_sum(float v) {
    for (int o = 16; o > 0; o >>= 1) v += __shfl_xor_sync(0xffffffffu, v, o);
    return v;
}
__device__ __forceinline__ float mx_cuda_warp_max(float v) {
    for (int o = 16; o > 0; o >>= 1) v = fmaxf(v, __shfl_xor_sync(0xffffffffu, v, o));
    return v;
}
__device__ __forceinline__ float mx_cuda_block_sum(float v, float *shm) {
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, nwarps = blockDim.x >> 5;
    v = mx_cuda_warp_sum(v);
    __syncthreads(); /* shm may still be read from a previous call */
    if (lane == 0) shm[warp] = v;
    __syncthreads();
    v = lane < nwarps ? shm[lane] : 0.0f;
    return mx_cuda_warp_sum(v);
}
__device__ __forceinline__ float mx_cuda_block_max(float v, float *shm) {
    int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, nwarps = blockDim.x >> 5;
    v = mx_cuda_warp_max(v);
    __syncthreads();
    if (lane == 0) shm[warp] = v;
    __syncthreads();
    v = lane < nwarps ? shm[lane] : -INFINITY;
    return mx_cuda_warp_max(v);
}

/* A weight's dtype must be one of fp32/fp16/bf16. */
static inline int mx_cuda_check_wdtype(mx_wptr w, const char *what, mx_status *st) {
    if (w.dtype == MX_F32 || w.dtype == MX_F16 || w.dtype == MX_BF16) return 0;
    return mx_fail(st, MX_EINPUT, "%s: weight dtype %d is not fp32, fp16 or bf16", what, (int)w.dtype);
}

/* 1 when some size is 0: an empty shape, no work (the ops' guards in op_list.h). */
static inline int mx_cuda_empty(int ndim, const long long *dims) {
    for (int i = 0; i < ndim; i++)
        if (dims[i] == 0) return 1;
    return 0;
}

/* Sizes must be positive and their product (the element count) must fit an index. */
static inline int mx_cuda_check_dims(const char *what, mx_status *st, int ndim, const long long *dims) {
    long long n = 1;
    for (int i = 0; i < ndim; i++) {
        if (dims[i] <= 0) return mx_fail(st, MX_EINPUT, "%s: size %d is %lld (must be positive)", what, i, dims[i]);
        if (n > (1LL << 62) / dims[i]) return mx_fail(st, MX_EINPUT, "%s: element count overflows", what);
        n *= dims[i];
    }
    return 0;
}

/* ---- helpers shared by the GEMM-based ops (cuda_gemm.cu) ---- */

/* Column-major D[m x n] (fp32, leading dimension ldd) = op(A) · op(B), A and B of type ab
 * (fp32: fp32 math; fp16/bf16: tensor cores, fp32 accumulation). op(A) is m x k: A is stored
 * k x m when transa, else m x k; op(B) is k x n likewise. */
int mx_cuda_gemm(mx_cuda_ctx *c, mx_dtype ab, int transa, int transb, int m, int n, int k, const void *A,
                 long long lda, const void *B, long long ldb, float *D, long long ldd, const char *what,
                 mx_status *st);
/* The same over `batch` products, item i at A + i·sa, B + i·sb, D + i·sd (elements): one
 * strided-batched cuBLASLt call. */
int mx_cuda_gemm_batched(mx_cuda_ctx *c, mx_dtype ab, int transa, int transb, int m, int n, int k, const void *A,
                         long long lda, long long sa, const void *B, long long ldb, long long sb, float *D,
                         long long ldd, long long sd, int batch, const char *what, mx_status *st);
/* Destroys the cached GEMM plans (at context destruction). */
typedef struct mx_cuda_gemm_plans mx_cuda_gemm_plans;
void mx_cuda_gemm_plans_free(mx_cuda_ctx *c);
/* ---- conv2d through cuDNN (cuda_cudnn.cu) ---- */

typedef struct mx_cuda_cudnn mx_cuda_cudnn;
/* Sets c->cudnn: cuDNN when MATEX_CUDNN=1, the build has cuDNN's headers and libcudnn.so.9 loads
 * (cudnnGetVersion: major 9), else NULL; one line saying which, only when MATEX_CUDNN=1 was asked. */
void mx_cuda_cudnn_open(mx_cuda_ctx *c);
void mx_cuda_cudnn_close(mx_cuda_ctx *c);
/* conv2d of mx_cuda_conv2d (checked arguments, Ho x Wo output) through cuDNN: 0, -1 on error, or 1
 * when cuDNN does not take it (off, not fp16 weights, no deterministic engine for this shape):
 * then nothing was queued. */
int mx_cuda_cudnn_conv2d(mx_cuda_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                         mx_wptr bias, int Cout, int kh, int kw, int stride, int pad, int Ho, int Wo, mx_status *st);

/* ---- CUDA graphs (cuda_graph.cu) ---- */

/* What queue(arg) queues on c's stream, captured (not run) into *graph (thread-local mode: an
 * allocation, a free or a wait inside fails the capture). 0, or -1 naming why it cannot be one graph
 * (then *graph is NULL, the stream is no longer capturing and nothing was queued). */
int mx_cuda_graph_capture(mx_cuda_ctx *c, int (*queue)(void *arg, mx_status *st), void *arg, cudaGraph_t *graph,
                          mx_status *st);
/* graph made launchable into *exec (free with mx_cuda_graph_free), its node count into *nodes. */
int mx_cuda_graph_instantiate(cudaGraph_t graph, cudaGraphExec_t *exec, size_t *nodes, mx_status *st);
/* Queues one replay of exec on c's stream. */
int mx_cuda_graph_launch(mx_cuda_ctx *c, cudaGraphExec_t exec, mx_status *st);
void mx_cuda_graph_free(cudaGraphExec_t exec);

/* ---- attention (cuda_attention.cu) ---- */

/* Lets the fp32 attention kernels take the shared memory of their largest head sizes, at most what
 * the device grants a block (once per context: never while a graph is captured). */
int mx_cuda_attention_open(mx_status *st);

/* ---- attention without materialised scores (cuda_flash.cu) ---- */

/* Sets c->flash_attn from MATEX_CUDA_FLASH (only "1" switches it on). */
void mx_cuda_flash_open(mx_cuda_ctx *c);
/* mx_cuda_attention's half-precision path (checked arguments) in the fused kernel: 0, -1 on error,
 * or 1 when it does not take it (off, head size above 160, scratch too small): nothing queued. */
int mx_cuda_flash_attention(mx_cuda_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                            int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal,
                            float scale, mx_status *st);

/* dst[i] = src[i] rounded (nearest even) to dt (MX_F32: a copy). */
int mx_cuda_convert_from_f32(mx_cuda_ctx *c, void *dst, mx_dtype dt, const float *src, size_t n, const char *what,
                             mx_status *st);
/* y[o, ch, i] += bias[ch] for y viewed as [outer, channels, inner]. */
int mx_cuda_add_bias(mx_cuda_ctx *c, float *y, mx_wptr bias, long long outer, int channels, long long inner,
                     const char *what, mx_status *st);

#endif
