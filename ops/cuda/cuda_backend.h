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

/* Number of usable CUDA devices: 0 (and success) when the system has no CUDA device; -1 with a
 * message naming the cause for anything else (a driver too old for this runtime, with both
 * versions; a driver that cannot be loaded or initialised): a GPU that CUDA cannot use is an
 * error, never "no device". */
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
/* Asynchronous host-to-device copy through the context's two pinned staging halves (double
 * buffered): src may be reused when it returns; the copy completes in stream order. Errors of the
 * copy itself surface at the next sync. Weights are uploaded this way (one pass, no pageable
 * synchronous copy per tensor). */
int mx_cuda_upload_staged(mx_cuda_ctx *ctx, void *dst, const void *src, size_t bytes, const char *what,
                          mx_status *st);
/* The whole open file fd ([0, len), named path in messages) copied to dst (device memory of len
 * bytes): `readers` host threads read it into a ring of pinned chunks while earlier chunks are
 * copied, each chunk shown to obs (NULL: none) (runtime/file_stream.h); returns when every byte
 * is on the device, or -1 naming the file, the offset and the cause (a file of another length,
 * one cut while read, an I/O error, a failed copy). stats (may be NULL) gets where the time went. */
struct mx_stream_stats;
struct mx_stream_observer;
int mx_cuda_upload_file(mx_cuda_ctx *ctx, void *dst, int fd, const char *path, size_t len, int readers,
                        const struct mx_stream_observer *obs, struct mx_stream_stats *stats, mx_status *st);
int mx_cuda_memset_zero(mx_cuda_ctx *ctx, void *dptr, size_t bytes, const char *what, mx_status *st);

/* ---- ops: one per op of ops/op_list.h, with the same arguments and semantics as its mx_* wrapper
 * plus the status: int mx_cuda_<op>(mx_cuda_ctx *c, <the op's params>, mx_status *st). Files by op
 * family, as the CPU references: cuda_linear.cu, cuda_conv.cu (both on cuda_gemm.cu), cuda_norm.cu,
 * cuda_attention.cu, cuda_activation.cu, cuda_binary.cu, cuda_layout.cu, cuda_vector.cu,
 * cuda_embed.cu. attention: D (head size) at most MX_CUDA_ATTN_MAX_D. embed_tokens: the ids are
 * HOST integers. ---- */

#define MX_CUDA_ATTN_MAX_D 512
#define MX_CUDA_OP_DECL_(name, guard, params, args, cost) int mx_cuda_##name(mx_cuda_ctx *c, MX_SPLICE params, mx_status *st);
MX_OPS(MX_CUDA_OP_DECL_)

/* The CUDA backend of runtime/backend.h on device 0: every op of ops.h through a kernel table of
 * the functions above (errors are kept and reported by the next copy to the host), device
 * memory, host copies. Fails with one line when there is no usable device. */
int mx_cuda_backend_create(mx_backend **out, mx_status *st);
/* The number of matrix products that backend be (a CUDA backend) computed in half precision
 * (fp16/bf16 weights on tensor cores) since the last call with reset=1. The network parity tests
 * apply the half-precision bound exactly where this is non-zero (tests/nn_golden.h). */
unsigned long long mx_cuda_half_products(mx_backend *be, int reset);
/* The same count of one context (never reset): what the op test reads around one op. Attention
 * counts too: it runs on tensor cores in fp16 (cuda_attention.cu) unless the scratch is too small. */
unsigned long long mx_cuda_ctx_half_products(const mx_cuda_ctx *c);
/* The conv2d calls of a context that cuDNN ran (MATEX_CUDNN=1, cuda_cudnn.cu; never reset): the op
 * test checks cuDNN really ran where it was asked for, and never where it was not. */
unsigned long long mx_cuda_ctx_cudnn_convs(const mx_cuda_ctx *c);
/* The attention calls of a context that the fused kernel ran (MATEX_CUDA_FLASH=1, cuda_flash.cu). */
unsigned long long mx_cuda_ctx_flash_calls(const mx_cuda_ctx *c);
/* Where loading weights onto the GPU spends its time, since the backend was created. Weight files
 * (mx_dev_weight_file): their count, bytes, the wall time of their streams, the reader threads'
 * time in pread (summed), the waits for a chunk to be read and for a chunk's copy, the time in
 * the observer (the weight digest), the readers.
 * Other uploads through the pinned staging halves: host copies, waits for a half the copy engine
 * still reads, bytes. Device allocations: time and count. bench_cuda and gpu-check print them
 * (issue 39: the 3.6 GB set took 2.5-3 s with a copy per tensor; the goal is under 1 s). */
typedef struct mx_cuda_upload_stats {
    double copy_s, wait_s, alloc_s;
    unsigned long long bytes, allocs;
    int files, file_readers;
    unsigned long long file_bytes;
    double file_s, file_read_s, file_fill_wait_s, file_copy_wait_s, file_seen_s;
} mx_cuda_upload_stats;
void mx_cuda_backend_upload_stats(mx_backend *be, mx_cuda_upload_stats *out);
/* Captures what queue(arg) queues on the backend's stream into one CUDA graph (relaxed mode), without
 * running it, and gives its node count (kernel launches, copies, memsets): the launches of, e.g.,
 * one guided step. Fails, naming the cause, where the work cannot be captured (a host wait inside
 * it, an allocation): what issue 39's graph replay must remove first. Run queue once before, so
 * that plans and buffers exist. */
int mx_cuda_backend_capture_count(mx_backend *be, int (*queue)(void *arg, mx_status *st), void *arg,
                                  size_t *launches, mx_status *st);
/* That kernel table (needs no device: tests check it is full). */
void mx_cuda_fill_kernels(mx_kernels *k);

/* out[i] = mx_rng_normal(seed, stream, first + i) of runtime/rng.h, bit for bit. */
int mx_cuda_rng_fill_normal(mx_cuda_ctx *c, float *out, size_t n, uint64_t seed, uint64_t stream,
                            uint64_t first, mx_status *st);

#ifdef __cplusplus
}
#endif

#endif
