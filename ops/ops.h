/* The op interface of matex. The ops are listed once in op_list.h (name, semantics, parameters);
 * this header turns the list into the kernel table (struct mx_kernels) and the mx_* wrappers.
 * Every op has a scalar reference in ops/cpu (<family>_ref.c, the test oracle); the faster CPU
 * levels (ops/cpu/dispatch.c) and the CUDA backend (ops/cuda) each have a table of their own,
 * chosen once: by cpuid for the CPU, by the backend otherwise. Networks call the mx_* wrappers
 * and nothing else touches activations. *
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
 *   Scratch the SIMD kernels take per call: linear/conv2d, the GEMM engine (ops/cpu/gemm.c),
 *   (A + B)·w + max(M, N) floats (AMX: + 16·M), where w = the words of a panel row: min(K, KC)
 *   for fp32 panels, half that for bf16 ones (a k-pair per word), KC the K block (gemm.h: 640 on
 *   the SIMD levels, 2048 on AMX); A = M rows (threads·96 when M has 32 or more blocks of 96; 0
 *   for conv weights the context keeps packed);
 *   B = min(N, 4096) columns, or 384 KiB per thread where each thread packs its own columns
 *   (conv: M = Cout, N = Ho·Wo, K = Cin·kh·kw). conv2d adds the band of input rows it reads
 *   (≤ 8 MiB, twice on AMX's fp32 layers) and, when the output takes several blocks of rows, the
 *   weights' panels of all of K (≈ M·K floats) unless the context keeps them packed (wpack).
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
#include "../runtime/file_stream.h"
#include "../runtime/half.h"
#include "../runtime/tensor.h"
#include "../runtime/threadpool.h"
#include "op_list.h"
#include "profile.h"

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
    mx_profile *prof;        /* NULL, or where each op's time is added (profile.h) */
    struct mx_wpack *wpack;  /* NULL, or the weights packed once (mx_ctx_pack_weights) */
} mx_ctx;

typedef enum { MX_BIN_ADD = 0, MX_BIN_SUB = 1, MX_BIN_MUL = 2 } mx_binop;

/* The dispatch table: one field per op of op_list.h, each with exactly the semantics of the
 * wrapper of the same name. A backend's table is full: mx_kernels_check at context creation. */
#define MX_KERNEL_FIELD_(name, guard, params, args, cost) void (*name)(const mx_ctx *c, MX_SPLICE params);
struct mx_kernels {
    mx_isa isa;
    MX_OPS(MX_KERNEL_FIELD_)
};

/* The table for an ISA level (clamped to what this CPU supports). */
const mx_kernels *mx_kernels_for(mx_isa isa);
/* c computing in fp32: a copy whose table is mx_kernels_fp32_of c's when c's computes in bf16
 * (avx512bf16 -> avx512), c's own otherwise (CUDA keeps its table). Same pool, scratch,
 * backend. For the layers the precision policy keeps in fp32 (pipeline/nn/precision.h). */
mx_ctx mx_ctx_fp32(const mx_ctx *c);
/* The table of the layers a bf16 level keeps in fp32: its fp32 level's (avx512bf16 -> avx512),
 * but for amx the avx512 table with linear and conv2d as three bf16 products on the tiles
 * (ops/cpu/gemm.h: split kernels), near fp32 accuracy at the tiles' speed. */
const mx_kernels *mx_kernels_fp32_of(const mx_kernels *k);
/* The scalar reference table (the test oracle). */
const mx_kernels *mx_kernels_scalar(void);
/* The table of a level as compiled in, whether or not this CPU runs it (NULL: not compiled in,
 * e.g. x86 levels on another architecture). For tests; contexts use mx_kernels_for. */
const mx_kernels *mx_kernels_compiled(mx_isa isa);
/* The best fp32 table for this CPU (mx_cpu_isa_for(MX_PREC_FP32)): what a context without a
 * table gets. */
const mx_kernels *mx_kernels_best(void);

/* ---- wrappers: the op semantics (op_list.h) ---- */

/* 1 when every dim of both shapes (ndim of each) is positive: the guard of mx_binary. */
int mx_shapes_nonempty(const int64_t *ashape, const int64_t *bshape, int ndim);

#define MX_WRAPPER_DECL_(name, guard, params, args, cost) void mx_##name(const mx_ctx *c, MX_SPLICE params);
MX_OPS(MX_WRAPPER_DECL_)
/* The FLOPs of one call of linear, attention, conv2d (output Ho×Wo) and conv2d_up2x (input H×W,
 * its phase form): one formula each for the profile's costs and the networks' counts. */
double mx_linear_flops(int M, int N, int K);
double mx_attention_flops(int B, int H, int Tq, int Tk, int D);
double mx_conv2d_flops(int B, int Cin, int Ho, int Wo, int Cout, int kh, int kw);
double mx_conv2d_up2x_flops(int B, int Cin, int H, int W, int Cout);
/* Same-shape shortcut of mx_binary: y = a + b over n floats. */
void mx_add(const mx_ctx *c, float *y, const float *a, const float *b, size_t n);
/* Scalar conversions, usable anywhere: runtime/half.h (included above). */

/* The name of the first op of op_list.h that table k lacks, or NULL when k is full. */
const char *mx_kernels_missing(const mx_kernels *k);
/* 0 when k is full, else -1 with "op X is not available on backend Y" in st. */
int mx_kernels_check(const mx_kernels *k, const char *backend, mx_status *st);

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
/* A weight's device copy: `bytes` of fp32/fp16/bf16 data as stored, which ops only read (what
 * mx_binder_device binds on a device context; cpu-strict refuses any other weight pointer).
 * NULL with a message when out of memory. Free with mx_dev_free. */
void *mx_dev_weight(const mx_ctx *c, const void *src, size_t bytes, mx_status *st);
/* A whole weight file (open as fd, mapped at map, len bytes) onto c's device in one pass where
 * the backend can (CUDA: one allocation, read by several threads while the chunks read are
 * copied), each chunk shown to obs (runtime/file_stream.h; NULL: none) in file order; 1 then, and
 * mx_dev_weight gives places in that copy for bytes inside the mapping. 0 and nothing done where
 * it cannot (the CPU backends, c NULL) or when the file is there already: weights are then copied
 * one by one, and obs saw nothing. mx_dev_weight_file_drop frees that copy, after every weight
 * bound from it is released. */
int mx_dev_weight_file(const mx_ctx *c, int fd, const void *map, size_t len, const char *path,
                       const mx_stream_observer *obs, mx_status *st);
void mx_dev_weight_file_drop(const mx_ctx *c, const void *map);

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

/* ---- the ready-made context (ops/ctx.c) ---- */

/* A ready-to-use context: best kernels, a pool of nthreads (<=0: all CPUs) and a scratch
 * arena of scratch_bytes. Free with mx_ctx_destroy. */
int mx_ctx_create(mx_ctx *c, int nthreads, mx_isa isa, size_t scratch_bytes, mx_status *st);
/* The same on a backend of the given kind (cpu-strict and cuda own the activations; the
 * context owns the backend). A kind this binary lacks fails with one clear line. */
int mx_ctx_create_on(mx_ctx *c, mx_backend_kind kind, int nthreads, mx_isa isa, size_t scratch_bytes,
                     mx_status *st);
void mx_ctx_destroy(mx_ctx *c);
/* Keeps the weights of linear and conv2d packed once, in the panels of the GEMM engine, for every
 * later call on c (ops/cpu/wpack.h) instead of repacking them per call; same results. The panels
 * may take at most extra_bytes more than the weights they replace (fp32 panels of fp16 weights
 * take twice the weight). sources_mapped: the weights are a read-only file mapping whose pages
 * may be given back once packed. The weights must stay unchanged at their addresses while c
 * lives. On a backend without the CPU's GEMM engine (cpu-strict, cuda) it does nothing. */
int mx_ctx_pack_weights(mx_ctx *c, size_t extra_bytes, int sources_mapped, mx_status *st);

/* Makes a backend (ops/backend.c): kernels for `isa` on the CPU kinds. */
int mx_backend_create(mx_backend **out, mx_backend_kind kind, mx_isa isa, mx_status *st);
void mx_backend_destroy(mx_backend *be);

#endif
