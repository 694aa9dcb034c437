/* Devices, contexts and device memory of the CUDA backend. */
#include "cuda_common.cuh"

/* cuBLASLt workspace: 32 MiB is what NVIDIA recommends for Hopper (4 MiB is enough before it). */
#define MX_CUDA_WORKSPACE_BYTES ((size_t)32 << 20)

int mx_cuda_device_count(int *count, mx_status *st) {
    (void)st;
    int n = 0;
    /* No driver, no device or a driver too old all mean "no usable device", not an error. */
    if (cudaGetDeviceCount(&n) != cudaSuccess) {
        (void)cudaGetLastError(); /* clear it, so that it is not reported by a later launch check */
        n = 0;
    }
    *count = n;
    return 0;
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
    *out = c;
    return 0;
fail:
    mx_cuda_ctx_destroy(c);
    return -1;
}

void mx_cuda_ctx_destroy(mx_cuda_ctx *c) {
    if (!c) return;
    if (c->stream) cudaStreamSynchronize(c->stream);
    mx_cuda_free(c->scratch);
    mx_cuda_free(c->workspace);
    if (c->lt) cublasLtDestroy(c->lt);
    if (c->stream) cudaStreamDestroy(c->stream);
    free(c);
}

int mx_cuda_sync(mx_cuda_ctx *c, mx_status *st) {
    return mx_cuda_ok(cudaStreamSynchronize(c->stream), "cuda sync (an earlier queued op failed)", st);
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
    if (mx_cuda_ok(cudaMemcpyAsync(dst, src, bytes, kind, c->stream), what, st)) return -1;
    return mx_cuda_ok(cudaStreamSynchronize(c->stream), what, st);
}

int mx_cuda_upload(mx_cuda_ctx *c, void *dst, const void *src, size_t bytes, const char *what, mx_status *st) {
    return copy_sync(c, dst, src, bytes, cudaMemcpyHostToDevice, what, st);
}

int mx_cuda_download(mx_cuda_ctx *c, void *dst, const void *src, size_t bytes, const char *what,
                     mx_status *st) {
    return copy_sync(c, dst, src, bytes, cudaMemcpyDeviceToHost, what, st);
}

int mx_cuda_memset_zero(mx_cuda_ctx *c, void *dptr, size_t bytes, const char *what, mx_status *st) {
    return mx_cuda_ok(cudaMemsetAsync(dptr, 0, bytes, c->stream), what, st);
}
