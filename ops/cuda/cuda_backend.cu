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
#include <unistd.h>

#include "cuda_common.cuh"
extern "C" {
#include "../../runtime/file_stream.h" /* C headers without their own extern "C" */
#include "../../runtime/log.h"         /* mx_now */
#include "../record.h"                 /* mx_record */
}

#define CUDA_SCRATCH_BYTES ((size_t)64 << 20)
/* Host threads reading a weight file (MATEX_CUDA_LOAD_THREADS overrides): enough that the reads
 * (pread from the page cache, ~3-6 GB/s a thread) outrun a host-to-device link of 25-50 GB/s. */
#define CUDA_LOAD_READERS 8

/* A weight file's bytes on the device (mx_dev_weight_file): the mapping they were read from and
 * the one allocation holding their copy, at the same offsets. */
typedef struct weight_image {
    const unsigned char *map;
    size_t len;
    unsigned char *dev;
} weight_image;

typedef struct cuda_backend {
    mx_backend be;
    mx_kernels k;
    mx_cuda_ctx *cc;
    mx_status err; /* the first failure of a queued op */
    int failed;
    int sync_each_op;    /* MATEX_CUDA_SYNC=1: wait after every op (slow; names the op that faults) */
    int graphs;          /* MATEX_CUDA_GRAPH=1 (and not SYNC): recorded regions replayed as CUDA graphs */
    const char *last_op; /* the op queued last (an op_list.h name) */
    double alloc_s;      /* time in device allocations (weights, arenas) and their count */
    unsigned long long allocs;
    weight_image *images; /* the weight files on the device */
    int nimages, images_cap;
    int load_readers;
    mx_stream_stats file; /* of the weight files streamed, summed */
    int files;
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
    if (mx_cuda_not_capturing(b->cc, "cuda device memory: an allocation", st)) return NULL;
    double t0 = mx_now();
    int rc = mx_cuda_alloc(&p, bytes, "cuda device memory", st);
    b->alloc_s += mx_now() - t0;
    b->allocs++;
    return rc ? NULL : p;
}

/* The image holding device bytes [p, p + 1), or NULL. */
static const weight_image *image_of_device(const cuda_backend *b, const void *p) {
    const unsigned char *q = (const unsigned char *)p;
    for (int i = 0; i < b->nimages; i++)
        if (q >= b->images[i].dev && q < b->images[i].dev + b->images[i].len) return &b->images[i];
    return NULL;
}

/* The image whose mapping holds host bytes [src, src + bytes), or NULL. */
static const weight_image *image_of_host(const cuda_backend *b, const void *src, size_t bytes) {
    const unsigned char *q = (const unsigned char *)src;
    for (int i = 0; i < b->nimages; i++) {
        const weight_image *im = &b->images[i];
        if (q >= im->map && q < im->map + im->len && bytes <= (size_t)(im->map + im->len - q)) return im;
    }
    return NULL;
}

/* Places inside a weight file's copy belong to the copy (freed with it). */
static void cuda_release(mx_backend *be, void *p) {
    if (!image_of_device((const cuda_backend *)be->impl, p)) mx_cuda_free(p);
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

/* A weight inside a weight file on the device is its place there; any other is copied. */
static void *cuda_weight(mx_backend *be, const void *src, size_t bytes, mx_status *st) {
    const weight_image *im = image_of_host((const cuda_backend *)be->impl, src, bytes);
    if (im) return im->dev + ((const unsigned char *)src - im->map);
    void *p = cuda_alloc(be, bytes, st);
    if (p && cuda_to_device(be, p, src, bytes, st)) {
        mx_cuda_free(p);
        return NULL;
    }
    return p;
}

static void add_stream_stats(mx_stream_stats *sum, const mx_stream_stats *s) {
    sum->wall_s += s->wall_s;
    sum->read_s += s->read_s;
    sum->fill_wait_s += s->fill_wait_s;
    sum->copy_wait_s += s->copy_wait_s;
    sum->seen_s += s->seen_s;
    sum->bytes += s->bytes;
    sum->readers = s->readers;
}

/* The whole file in one device allocation, streamed by the backend's readers (mx_dev_weight_file). */
static int cuda_weight_file(mx_backend *be, int fd, const void *map, size_t len, const char *path,
                            const mx_stream_observer *obs, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    if (image_of_host(b, map, len)) return 0;
    if (report_failure(b, st)) return -1;
    if (b->nimages == b->images_cap) {
        int cap = b->images_cap ? 2 * b->images_cap : 4;
        weight_image *im = (weight_image *)realloc(b->images, (size_t)cap * sizeof *im);
        if (!im) return mx_fail(st, MX_ENOMEM, "%s: out of host memory", path);
        b->images = im;
        b->images_cap = cap;
    }
    unsigned char *dev = (unsigned char *)cuda_alloc(be, len, st);
    if (!dev) return mx_fail_prefix(st, "%s: the weight file on the device", path);
    mx_stream_stats s;
    if (mx_cuda_upload_file(b->cc, dev, fd, path, len, b->load_readers, obs, &s, st)) {
        mx_cuda_free(dev);
        return -1;
    }
    add_stream_stats(&b->file, &s);
    b->files++;
    b->images[b->nimages++] = (weight_image){(const unsigned char *)map, len, dev};
    return 1;
}

static void cuda_weight_file_drop(mx_backend *be, const void *map) {
    cuda_backend *b = (cuda_backend *)be->impl;
    for (int i = 0; i < b->nimages; i++)
        if (b->images[i].map == map) {
            mx_cuda_free(b->images[i].dev);
            b->images[i] = b->images[--b->nimages];
            return;
        }
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

/* What queue(arg) queues, captured into *g (cuda_graph.cu); an op that failed while captured makes
 * the capture fail with its error, and leaves the backend usable (nothing of it was queued). */
static int capture(cuda_backend *b, int (*queue)(void *arg, mx_status *st), void *arg, cudaGraph_t *g, mx_status *st) {
    int rc = mx_cuda_graph_capture(b->cc, queue, arg, g, st);
    if (b->failed) {
        *st = b->err;
        b->failed = 0;
        if (*g) cudaGraphDestroy(*g);
        *g = NULL;
        rc = -1;
    }
    return rc;
}

int mx_cuda_backend_capture_count(mx_backend *be, int (*queue)(void *arg, mx_status *st), void *arg,
                                  size_t *launches, mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    cudaGraph_t g = NULL;
    *launches = 0;
    if (report_failure(b, st) || wait_queued(b, st) || capture(b, queue, arg, &g, st)) return -1;
    int rc = mx_cuda_ok(cudaGraphGetNodes(g, NULL, launches), "cuda capture: graph nodes", st);
    cudaGraphDestroy(g);
    return rc;
}

/* The replayable form of a region's second call: captured, instantiated (its node count said once),
 * or NULL with the reason in why. */
static cudaGraphExec_t region_graph(cuda_backend *b, int (*fn)(void *user, mx_status *st), void *user,
                                    mx_status *why) {
    cudaGraph_t g = NULL;
    cudaGraphExec_t exec = NULL;
    size_t nodes = 0;
    if (capture(b, fn, user, &g, why)) return NULL;
    int rc = mx_cuda_graph_instantiate(g, &exec, &nodes, why);
    cudaGraphDestroy(g);
    if (rc) return NULL;
    mx_info("cuda: a recorded region (e.g. a denoising step's networks) captured as one CUDA graph of %zu nodes "
            "(kernels, copies, memsets), replayed from now on",
            nodes);
    return exec;
}

/* A recorded region's later calls (ops/record.h) under MATEX_CUDA_GRAPH=1: the second is captured
 * and launched, later ones launch the same graph. A region that cannot be captured (one line says
 * why) runs op by op from then on: never a half-captured stream, never a wrong replay. */
static int cuda_recorded(mx_backend *be, mx_record *rec, int (*fn)(void *user, mx_status *st), void *user,
                         mx_status *st) {
    cuda_backend *b = (cuda_backend *)be->impl;
    if (!b->graphs || rec->direct || b->failed) return fn(user, st); /* an earlier op's error: reported as ever */
    if (!rec->graph) {
        mx_status why = {};
        rec->graph = region_graph(b, fn, user, &why);
        if (!rec->graph) {
            mx_info("cuda: CUDA graph not used, the region runs op by op: %s", why.msg);
            rec->direct = 1;
            return fn(user, st);
        }
    }
    b->last_op = "a CUDA graph's replay";
    return mx_cuda_graph_launch(b->cc, (cudaGraphExec_t)rec->graph, st);
}

static void cuda_record_drop(mx_backend *be, mx_record *rec) {
    (void)be;
    mx_cuda_graph_free((cudaGraphExec_t)rec->graph);
    rec->graph = NULL;
}

void mx_cuda_backend_upload_stats(mx_backend *be, mx_cuda_upload_stats *out) {
    const cuda_backend *b = (const cuda_backend *)be->impl;
    out->copy_s = b->cc->upload_copy_s;
    out->wait_s = b->cc->upload_wait_s;
    out->bytes = b->cc->upload_bytes;
    out->alloc_s = b->alloc_s;
    out->allocs = b->allocs;
    out->files = b->files;
    out->file_bytes = b->file.bytes;
    out->file_s = b->file.wall_s;
    out->file_read_s = b->file.read_s;
    out->file_fill_wait_s = b->file.fill_wait_s;
    out->file_copy_wait_s = b->file.copy_wait_s;
    out->file_seen_s = b->file.seen_s;
    out->file_readers = b->file.readers;
}

static void cuda_destroy(mx_backend *be) {
    cuda_backend *b = (cuda_backend *)be->impl;
    for (int i = 0; i < b->nimages; i++) mx_cuda_free(b->images[i].dev);
    free(b->images);
    mx_cuda_ctx_destroy(b->cc);
    free(b);
}

/* MATEX_CUDA_LOAD_THREADS, else CUDA_LOAD_READERS, at most the CPUs online. */
static int load_readers(void) {
    const char *env = getenv("MATEX_CUDA_LOAD_THREADS");
    int n = env ? atoi(env) : 0;
    if (n >= 1) return n;
    long cpus = sysconf(_SC_NPROCESSORS_ONLN);
    return cpus >= 1 && cpus < CUDA_LOAD_READERS ? (int)cpus : CUDA_LOAD_READERS;
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
    const char *graph = getenv("MATEX_CUDA_GRAPH");
    b->graphs = graph && strcmp(graph, "1") == 0 && !b->sync_each_op;
    if (graph && strcmp(graph, "1") == 0 && b->sync_each_op)
        mx_info("cuda: MATEX_CUDA_GRAPH=1 ignored under MATEX_CUDA_SYNC=1 (a graph cannot wait after each op)");
    b->load_readers = load_readers();
    b->be.kind = MX_BACKEND_CUDA;
    b->be.k = &b->k;
    b->be.host_visible = 0;
    b->be.alloc = cuda_alloc;
    b->be.release = cuda_release;
    b->be.to_device = cuda_to_device;
    b->be.to_host = cuda_to_host;
    b->be.weight = cuda_weight;
    b->be.weight_file = cuda_weight_file;
    b->be.weight_file_drop = cuda_weight_file_drop;
    b->be.recorded = cuda_recorded;
    b->be.record_drop = cuda_record_drop;
    b->be.destroy = cuda_destroy;
    b->be.impl = b;
    *out = &b->be;
    return 0;
}
