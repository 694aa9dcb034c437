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

/* The table entry of each op of ops/op_list.h: its mx_cuda_<op> on the backend's context. */
#define CUDA_ENTRY_(name, guard, params, args)                                                             \
    static void k_##name(const mx_ctx *c, MX_SPLICE params) { CUDA_OP(c, mx_cuda_##name(b_->cc, MX_SPLICE args, st_)); }
MX_OPS(CUDA_ENTRY_)

void mx_cuda_fill_kernels(mx_kernels *k) {
    memset(k, 0, sizeof *k);
    k->isa = MX_ISA_SCALAR; /* not a CPU table */
#define CUDA_FILL_(name, guard, params, args) k->name = k_##name;
    MX_OPS(CUDA_FILL_)
#undef CUDA_FILL_
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
    mx_cuda_fill_kernels(&b->k);
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
