/* The CUDA backend (runtime/backend.h): device memory, host copies, and the kernel table that
 * runs every op of ops.h with the kernels of this folder. Kernel table entries return nothing,
 * so the first error of any op is kept and reported by the next copy to the host (ops queue
 * work on one stream; a download waits for it), with the name of the op that raised it, or,
 * for a fault found only when the stream is waited for, the name of the last op queued.
 * MATEX_CUDA_SYNC=1 waits after every op, so such a fault names its own op. One device (0) per
 * process. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cuda_common.cuh"
extern "C" {
#include "../../runtime/log.h" /* mx_now; a C header without its own extern "C" */
}

#define CUDA_SCRATCH_BYTES ((size_t)64 << 20)

typedef struct cuda_backend {
    mx_backend be;
    mx_kernels k;
    mx_cuda_ctx *cc;
    mx_status err; /* the first failure of a queued op */
    int failed;
    int sync_each_op;    /* MATEX_CUDA_SYNC=1: wait after every op (slow; names the op that faults) */
    const char *last_op; /* the op queued last (an op_list.h name) */
    double alloc_s;      /* time in device allocations (weights, arenas) and their count */
    unsigned long long allocs;
} cuda_backend;

static cuda_backend *of(const mx_ctx *c) { return (cuda_backend *)c->be->impl; }

/* Runs one op unless an earlier op failed; keeps its error, prefixed with the op's name. */
static void run_op(cuda_backend *b, const char *op, int rc) {
    b->last_op = op;
    if (rc == 0 && b->sync_each_op) rc = mx_cuda_sync(b->cc, &b->err);
    if (rc != 0) {
        b->failed = 1;
        mx_fail_prefix(&b->err, "op %s", op);
    }
}

/* The table entry of each op of ops/op_list.h: its mx_cuda_<op> on the backend's context (be_: the
 * ops' parameters use the short names). */
#define CUDA_ENTRY_(name, guard, params, args, cost)                                                         \
    static void k_##name(const mx_ctx *c, MX_SPLICE params) {                                              \
        cuda_backend *be_ = of(c);                                                                         \
        if (!be_->failed) run_op(be_, #name, mx_cuda_##name(be_->cc, MX_SPLICE args, &be_->err));          \
    }
MX_OPS(CUDA_ENTRY_)

void mx_cuda_fill_kernels(mx_kernels *k) {
    memset(k, 0, sizeof *k);
    k->isa = MX_ISA_SCALAR; /* not a CPU table */
#define CUDA_FILL_(name, guard, params, args, cost) k->name = k_##name;
    MX_OPS(CUDA_FILL_)
#undef CUDA_FILL_
}

/* ---- memory and copies ---- */

static void *cuda_alloc(mx_backend *be, size_t bytes, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    void *p = NULL;
    double t0 = mx_now();
    int rc = mx_cuda_alloc(&p, bytes, "cuda device memory", st);
    b->alloc_s += mx_now() - t0;
    b->allocs++;
    return rc ? NULL : p;
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

/* Uploads (weights, network inputs) are queued through the pinned staging buffer: the next
 * upload's host copy overlaps this one's transfer. */
static int cuda_to_device(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    if (report_failure(b, st)) return -1;
    return mx_cuda_upload_staged(b->cc, dst, src, bytes, "cuda upload", st);
}

/* A fault found while waiting belongs to some queued op: name the last one, and how to find the
 * one that raised it. */
static int wait_queued(cuda_backend *b, mx_status *st) {
    if (!mx_cuda_sync(b->cc, st)) return 0;
    if (b->last_op)
        mx_fail_prefix(st, "after op %s (the last queued; MATEX_CUDA_SYNC=1 names the op that failed)", b->last_op);
    return -1;
}

static int cuda_to_host(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    if (report_failure(b, st) || wait_queued(b, st)) return -1;
    return mx_cuda_download(b->cc, dst, src, bytes, "cuda download", st);
}

unsigned long long mx_cuda_ctx_half_products(const mx_cuda_ctx *c) { return c->half_products; }

unsigned long long mx_cuda_ctx_cudnn_convs(const mx_cuda_ctx *c) { return c->cudnn_convs; }

unsigned long long mx_cuda_ctx_flash_calls(const mx_cuda_ctx *c) { return c->flash_calls; }

unsigned long long mx_cuda_half_products(mx_backend *be, int reset) {
    mx_cuda_ctx *c = ((cuda_backend *)be->impl)->cc;
    unsigned long long n = c->half_products;
    if (reset) c->half_products = 0;
    return n;
}

int mx_cuda_backend_capture_count(mx_backend *be, int (*queue)(void *arg, mx_status *st), void *arg,
                                  size_t *launches, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    *launches = 0;
    if (report_failure(b, st) || wait_queued(b, st)) return -1;
    if (mx_cuda_ok(cudaStreamBeginCapture(b->cc->stream, cudaStreamCaptureModeRelaxed), "cuda capture: begin", st))
        return -1;
    int rc = queue(arg, st);
    cudaGraph_t g = NULL;
    cudaError_t e = cudaStreamEndCapture(b->cc->stream, &g);
    if (b->failed) { /* an op failed while captured: its error, and the backend usable again */
        *st = b->err;
        b->failed = 0;
        rc = -1;
    }
    if (rc == 0 && mx_cuda_ok(e, "cuda capture: the work queued cannot be one graph", st)) rc = -1;
    if (rc == 0 && mx_cuda_ok(cudaGraphGetNodes(g, NULL, launches), "cuda capture: graph nodes", st)) rc = -1;
    if (g) cudaGraphDestroy(g);
    (void)cudaGetLastError(); /* a capture error is not a later op's */
    return rc;
}

void mx_cuda_backend_upload_stats(mx_backend *be, mx_cuda_upload_stats *out) {
    const cuda_backend *b = (const cuda_backend *)be->impl;
    out->copy_s = b->cc->upload_copy_s;
    out->wait_s = b->cc->upload_wait_s;
    out->bytes = b->cc->upload_bytes;
    out->alloc_s = b->alloc_s;
    out->allocs = b->allocs;
}

static void cuda_destroy(mx_backend *be) {
    cuda_backend *b = (cuda_backend *)be->impl;
    mx_cuda_ctx_destroy(b->cc);
    free(b);
}

int mx_cuda_backend_create(mx_backend **out, mx_status *st) {
    *out = NULL;
    int n = 0;
    if (mx_cuda_device_count(&n, st)) return mx_fail_prefix(st, "--device cuda");
    if (n < 1) return mx_fail(st, MX_EUSAGE, "--device cuda: no CUDA device found (no NVIDIA GPU)");
    cuda_backend *b = (cuda_backend *)calloc(1, sizeof *b);
    if (!b) return mx_fail(st, MX_ENOMEM, "cuda backend: out of memory");
    if (mx_cuda_ctx_create(&b->cc, 0, CUDA_SCRATCH_BYTES, st)) {
        free(b);
        return mx_fail_prefix(st, "cuda backend");
    }
    mx_cuda_fill_kernels(&b->k);
    const char *sync = getenv("MATEX_CUDA_SYNC");
    b->sync_each_op = sync && strcmp(sync, "1") == 0;
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
