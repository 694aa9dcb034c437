/* Devices, contexts and device memory of the CUDA backend. */
#include <stdio.h>
#include <string.h>

#include "cuda_common.cuh"
extern "C" {
#include "../../runtime/file_stream.h" /* C headers without their own extern "C" */
#include "../../runtime/log.h"         /* mx_now */
}

/* cuBLASLt workspace: 32 MiB is what NVIDIA recommends for Hopper (4 MiB is enough before it). */
#define MX_CUDA_WORKSPACE_BYTES ((size_t)32 << 20)
/* Each of the two pinned staging halves of the uploads: large enough that a copy's fixed cost
 * (~10 us) is small against its transfer (8 MiB at ~25 GB/s: ~0.3 ms), small enough to pin. */
#define MX_CUDA_STAGING_BYTES ((size_t)8 << 20)

int mx_cuda_device_count(int *count, mx_status *st) {
    int n = 0, drv = 0, rt = 0;
    cudaError_t e = cudaGetDeviceCount(&n);
    (void)cudaGetLastError(); /* clear it, so that it is not reported by a later launch check */
    *count = 0;
    if (e == cudaSuccess) {
        *count = n;
        return 0;
    }
    (void)cudaDriverGetVersion(&drv); /* 0: no driver (libcuda) installed */
    (void)cudaRuntimeGetVersion(&rt);
    /* No driver or no device at all is not an error (a machine without a GPU); a driver that is
     * there but cannot serve this runtime, or any other failure, is one. */
    if (e == cudaErrorNoDevice || (e == cudaErrorInsufficientDriver && drv == 0)) return 0;
    if (e == cudaErrorInsufficientDriver)
        return mx_fail(st, MX_EUSAGE,
                       "CUDA driver too old for this runtime (driver %d.%d, runtime %d.%d): install an NVIDIA driver "
                       "that supports CUDA %d.%d (for 13.0: 580 or later)",
                       drv / 1000, drv % 1000 / 10, rt / 1000, rt % 1000 / 10, rt / 1000, rt % 1000 / 10);
    return mx_fail(st, MX_EINTERNAL, "CUDA cannot list the devices (driver %d.%d, runtime %d.%d): %s: %s", drv / 1000,
                   drv % 1000 / 10, rt / 1000, rt % 1000 / 10, cudaGetErrorName(e), cudaGetErrorString(e));
}

/* Two pinned halves of MX_CUDA_STAGING_BYTES each and their events. */
static int staging_create(mx_cuda_ctx *c, mx_status *st) {
    for (int i = 0; i < 2; i++) {
        if (mx_cuda_ok(cudaMallocHost((void **)&c->staging[i], MX_CUDA_STAGING_BYTES), "cuda pinned staging buffer", st) ||
            mx_cuda_ok(cudaEventCreateWithFlags(&c->staging_done[i], cudaEventDisableTiming), "cuda staging event", st))
            return -1;
    }
    c->staging_bytes = MX_CUDA_STAGING_BYTES;
    return 0;
}

static void staging_destroy(mx_cuda_ctx *c) {
    for (int i = 0; i < 2; i++) {
        if (c->staging_done[i]) cudaEventDestroy(c->staging_done[i]);
        if (c->staging[i]) cudaFreeHost(c->staging[i]);
    }
}

int mx_cuda_ctx_create(mx_cuda_ctx **out, int device, size_t scratch_bytes, mx_status *st) {
    *out = NULL;
    mx_cuda_ctx *c = (mx_cuda_ctx *)calloc(1, sizeof *c);
    if (!c) return mx_fail(st, MX_ENOMEM, "cuda context: out of host memory");
    if (mx_cuda_ok(cudaSetDevice(device), "cuda context: select device", st) ||
        mx_cuda_ok(cudaStreamCreateWithFlags(&c->stream, cudaStreamNonBlocking), "cuda context: stream", st))
        goto fail;
    if (cublasLtCreate(&c->lt) != CUBLAS_STATUS_SUCCESS) {
        c->lt = NULL;
        mx_fail(st, MX_EINTERNAL, "cuda context: cublasLtCreate failed");
        goto fail;
    }
    c->workspace_bytes = MX_CUDA_WORKSPACE_BYTES;
    if (mx_cuda_alloc(&c->workspace, c->workspace_bytes, "cuBLASLt workspace", st)) goto fail;
    c->scratch_cap = scratch_bytes;
    if (scratch_bytes && mx_cuda_alloc((void **)&c->scratch, scratch_bytes, "cuda scratch", st)) goto fail;
    if (staging_create(c, st) || mx_cuda_attention_open(st)) goto fail;
    mx_cuda_cudnn_open(c);
    mx_cuda_flash_open(c);
    *out = c;
    return 0;
fail:
    mx_cuda_ctx_destroy(c);
    return -1;
}

void mx_cuda_ctx_destroy(mx_cuda_ctx *c) {
    if (!c) return;
    if (c->stream) cudaStreamSynchronize(c->stream);
    staging_destroy(c);
    mx_cuda_cudnn_close(c);
    mx_cuda_gemm_plans_free(c);
    mx_cuda_free(c->scratch);
    mx_cuda_free(c->workspace);
    if (c->lt) cublasLtDestroy(c->lt);
    if (c->stream) cudaStreamDestroy(c->stream);
    free(c);
}

int mx_cuda_sync(mx_cuda_ctx *c, mx_status *st) {
    if (mx_cuda_not_capturing(c, "cuda sync: a wait for the device", st)) return -1;
    return mx_cuda_ok(cudaStreamSynchronize(c->stream), "cuda sync: a queued kernel or copy failed", st);
}

int mx_cuda_alloc(void **dptr, size_t bytes, const char *what, mx_status *st) {
    *dptr = NULL;
    cudaError_t e = cudaMalloc(dptr, bytes ? bytes : 1);
    if (e != cudaSuccess) {
        *dptr = NULL;
        return mx_fail(st, e == cudaErrorMemoryAllocation ? MX_ENOMEM : MX_EINTERNAL,
                       "%s: cannot allocate %zu bytes of device memory: %s", what, bytes, cudaGetErrorString(e));
    }
    return 0;
}

void mx_cuda_free(void *dptr) {
    if (dptr) cudaFree(dptr);
}

static int copy_sync(mx_cuda_ctx *c, void *dst, const void *src, size_t bytes, cudaMemcpyKind kind,
                     const char *what, mx_status *st) {
    if (mx_cuda_not_capturing(c, what, st)) return -1;
    if (mx_cuda_ok(cudaMemcpyAsync(dst, src, bytes, kind, c->stream), what, st)) return -1;
    return mx_cuda_ok(cudaStreamSynchronize(c->stream), what, st);
}

int mx_cuda_upload(mx_cuda_ctx *c, void *dst, const void *src, size_t bytes, const char *what, mx_status *st) {
    return copy_sync(c, dst, src, bytes, cudaMemcpyHostToDevice, what, st);
}

/* Pieces of at most one staging half: wait until the copy that last read the half is done, fill it
 * on the host, queue its copy and record its event. The host memory is read before this returns;
 * the device copy completes in stream order, before any op queued after it. */
int mx_cuda_upload_staged(mx_cuda_ctx *c, void *dst, const void *src, size_t bytes, const char *what,
                          mx_status *st) {
    if (mx_cuda_not_capturing(c, what, st)) return -1;
    if (!c->staging_bytes) return mx_cuda_upload(c, dst, src, bytes, what, st);
    for (size_t off = 0; off < bytes;) {
        int h = c->staging_next;
        size_t n = bytes - off < c->staging_bytes ? bytes - off : c->staging_bytes;
        double t0 = mx_now();
        if (mx_cuda_ok(cudaEventSynchronize(c->staging_done[h]), what, st)) return -1;
        double t1 = mx_now();
        memcpy(c->staging[h], (const unsigned char *)src + off, n);
        c->upload_wait_s += t1 - t0;
        c->upload_copy_s += mx_now() - t1;
        c->upload_bytes += n;
        if (mx_cuda_ok(cudaMemcpyAsync((unsigned char *)dst + off, c->staging[h], n, cudaMemcpyHostToDevice, c->stream),
                       what, st) ||
            mx_cuda_ok(cudaEventRecord(c->staging_done[h], c->stream), what, st))
            return -1;
        c->staging_next = 1 - h;
        off += n;
    }
    return 0;
}

/* Weight files are streamed (runtime/file_stream.h) through a ring of pinned chunks: 4 MiB copies
 * cost their ~10 us of fixed cost against ~80-160 us of transfer (25-50 GB/s), and FILE_IN_FLIGHT
 * of them queued keep the copy engine busy while the host waits for the oldest. The ring is one
 * pinned allocation (one call: pinning costs per call as well as per page), made for one file and
 * freed after it: (readers + FILE_IN_FLIGHT) chunks, 20-64 MiB. */
#define FILE_CHUNK_BYTES ((size_t)4 << 20)
#define FILE_IN_FLIGHT 4
#define FILE_MAX_READERS 12
#define FILE_MAX_BUFS (FILE_MAX_READERS + FILE_IN_FLIGHT)

typedef struct file_ring {
    mx_cuda_ctx *c;
    const char *path;
    unsigned char *dst;
    unsigned char *pinned;
    unsigned char *bufs[FILE_MAX_BUFS];
    cudaEvent_t done[FILE_MAX_BUFS]; /* recorded after the copy out of each buffer */
    int n;
} file_ring;

/* "PATH: copying to the GPU (at byte OFF): CUDA error NAME: TEXT" */
static int ring_fail(const file_ring *r, cudaError_t e, const char *where, mx_status *st) {
    return mx_fail(st, MX_EINTERNAL, "%s: copying to the GPU%s: CUDA error %s: %s", r->path, where, cudaGetErrorName(e),
                   cudaGetErrorString(e));
}

static int ring_copy(void *arg, int slot, const void *buf, size_t n, uint64_t off, mx_status *st) {
    file_ring *r = (file_ring *)arg;
    cudaError_t e = cudaMemcpyAsync(r->dst + off, buf, n, cudaMemcpyHostToDevice, r->c->stream);
    if (e == cudaSuccess) e = cudaEventRecord(r->done[slot], r->c->stream);
    if (e == cudaSuccess) return 0;
    char where[48];
    snprintf(where, sizeof where, " at byte %llu", (unsigned long long)off);
    return ring_fail(r, e, where, st);
}

static int ring_wait(void *arg, int slot, mx_status *st) {
    file_ring *r = (file_ring *)arg;
    cudaError_t e = cudaEventSynchronize(r->done[slot]);
    return e == cudaSuccess ? 0 : ring_fail(r, e, "", st);
}

static void ring_free(file_ring *r) {
    for (int i = 0; i < r->n; i++)
        if (r->done[i]) cudaEventDestroy(r->done[i]);
    if (r->pinned) cudaFreeHost(r->pinned);
}

static int ring_make(file_ring *r, int nbufs, mx_status *st) {
    if (mx_cuda_ok(cudaMallocHost((void **)&r->pinned, (size_t)nbufs * FILE_CHUNK_BYTES), r->path, st))
        return mx_fail_prefix(st, "pinned staging ring of %d MiB", (int)(nbufs * (FILE_CHUNK_BYTES >> 20)));
    for (; r->n < nbufs; r->n++) {
        r->bufs[r->n] = r->pinned + (size_t)r->n * FILE_CHUNK_BYTES;
        if (mx_cuda_ok(cudaEventCreateWithFlags(&r->done[r->n], cudaEventDisableTiming), r->path, st)) return -1;
    }
    return 0;
}

int mx_cuda_upload_file(mx_cuda_ctx *c, void *dst, int fd, const char *path, size_t len, int readers,
                        const mx_stream_observer *obs, mx_stream_stats *stats, mx_status *st) {
    file_ring r;
    memset(&r, 0, sizeof r);
    r.c = c;
    r.path = path;
    r.dst = (unsigned char *)dst;
    readers = readers < 1 ? 1 : readers > FILE_MAX_READERS ? FILE_MAX_READERS : readers;
    int rc = ring_make(&r, readers + FILE_IN_FLIGHT, st);
    if (rc == 0) {
        mx_stream_ring ring = {r.bufs, r.n, FILE_CHUNK_BYTES, readers, FILE_IN_FLIGHT};
        mx_stream_sink sink = {&r, ring_copy, ring_wait};
        rc = mx_file_stream(fd, path, len, &ring, &sink, obs, stats, st);
    }
    ring_free(&r);
    return rc;
}

int mx_cuda_download(mx_cuda_ctx *c, void *dst, const void *src, size_t bytes, const char *what,
                     mx_status *st) {
    return copy_sync(c, dst, src, bytes, cudaMemcpyDeviceToHost, what, st);
}

int mx_cuda_memset_zero(mx_cuda_ctx *c, void *dptr, size_t bytes, const char *what, mx_status *st) {
    return mx_cuda_ok(cudaMemsetAsync(dptr, 0, bytes, c->stream), what, st);
}
