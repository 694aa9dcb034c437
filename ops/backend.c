/* The CPU backends and the backend factory.
 *
 * cpu: activations in host memory, the cpuid-chosen kernel table.
 * cpu-strict: the same kernels, but every allocation is its own anonymous mapping that is
 * PROT_NONE except while one of the backend's kernels (or an upload/download) runs, so any
 * read or write of an activation from outside the op layer ends in SIGSEGV. Made for tests:
 * each op pays two mprotect calls per live allocation. It is a device context, as CUDA is:
 * weights are device copies (mx_dev_weight, mapped read-only, outside the per-op mprotect), and
 * an op handed a weight that is not one (a host pointer, bound through a host binder) is refused
 * without running, its message kept and reported by the next download, as a CUDA kernel fault is.
 * A whole weight file is put on it as on CUDA (mx_dev_weight_file: streamed by runtime/file_stream.h
 * into one read-only mapping, weights bound as places in it), so tests without a GPU run that path. */
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "ops.h"
#include "record.h"

#ifdef MX_WITH_CUDA
int mx_cuda_backend_create(mx_backend **out, mx_status *st); /* ops/cuda/cuda_backend.cu */
#endif

/* ---- cpu ---- */

/* Released host blocks of HOST_REUSE_MIN bytes or more are kept for the next request of nearly
 * their size: a texture job asks for the same arenas, step caches and decode buffers request
 * after request, and fresh memory costs a fault and a zeroed page per page (the kernel's page
 * clearing was ~7 % of a --fast job's CPU time on the VMs measured). A large request that no
 * kept block fits first hands every kept block back, so a kept block only adds to what the
 * process holds until the next large request (or the backend's end). */
#define HOST_REUSE_MIN ((size_t)8 << 20)
#define HOST_BLOCKS 32

typedef struct {
    void *p;
    size_t n;
} host_block;

typedef struct {
    pthread_mutex_t mu;
    host_block live[HOST_BLOCKS], kept[HOST_BLOCKS]; /* large blocks in use; released ones kept */
    int nlive, nkept;
} host_state;

/* A kept block of n to n + n/4 bytes (the smallest), taken out of the list; else the list is
 * emptied and {NULL, 0} returned. Called locked. */
static host_block take_kept(host_state *h, size_t n) {
    int best = -1;
    for (int i = 0; i < h->nkept; i++)
        if (h->kept[i].n >= n && h->kept[i].n - n <= n / 4 && (best < 0 || h->kept[i].n < h->kept[best].n)) best = i;
    if (best >= 0) {
        host_block b = h->kept[best];
        h->kept[best] = h->kept[--h->nkept];
        return b;
    }
    for (int i = 0; i < h->nkept; i++) free(h->kept[i].p);
    h->nkept = 0;
    return (host_block){NULL, 0};
}

static void *host_alloc(mx_backend *be, size_t bytes, mx_status *st) {
    host_state *h = be->impl;
    size_t n = (bytes + MX_ARENA_ALIGN - 1) / MX_ARENA_ALIGN * MX_ARENA_ALIGN;
    host_block b = {NULL, n ? n : MX_ARENA_ALIGN};
    if (n < bytes) b.n = 0; /* overflow */
    if (b.n >= HOST_REUSE_MIN) {
        pthread_mutex_lock(&h->mu);
        host_block k = take_kept(h, b.n);
        pthread_mutex_unlock(&h->mu);
        if (k.p) b = k;
    }
    if (!b.p && b.n) b.p = mx_host_block(b.n);
    if (!b.p) {
        mx_fail(st, MX_ENOMEM, "out of memory (%zu bytes)", bytes);
        return NULL;
    }
    if (b.n >= HOST_REUSE_MIN) {
        pthread_mutex_lock(&h->mu);
        if (h->nlive < HOST_BLOCKS) h->live[h->nlive++] = b; /* else it is freed on release */
        pthread_mutex_unlock(&h->mu);
    }
    return b.p;
}

static void host_release(mx_backend *be, void *p) {
    host_state *h = be->impl;
    pthread_mutex_lock(&h->mu);
    for (int i = 0; i < h->nlive; i++)
        if (h->live[i].p == p) {
            host_block b = h->live[i];
            h->live[i] = h->live[--h->nlive];
            if (h->nkept < HOST_BLOCKS) {
                h->kept[h->nkept++] = b;
                p = NULL;
            }
            break;
        }
    pthread_mutex_unlock(&h->mu);
    free(p);
}

static void host_destroy(mx_backend *be) {
    host_state *h = be->impl;
    for (int i = 0; i < h->nkept; i++) free(h->kept[i].p);
    pthread_mutex_destroy(&h->mu);
    free(h);
    free(be);
}

static int host_copy(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    (void)be;
    (void)st;
    if (bytes) memcpy(dst, src, bytes);
    return 0;
}

/* ---- cpu-strict ---- */

typedef struct strict_map {
    void *p;
    size_t bytes;
    int weight; /* a weight's copy: read-only, never opened by enter */
    const void *file_map; /* a whole weight file's copy: the host mapping it was read from; else NULL */
} strict_map;

typedef struct strict_state {
    strict_map *maps;
    size_t n, cap;
    int depth;                    /* nesting of enter/leave: the memory is open while depth > 0 */
    const mx_kernels *inner[2];   /* the CPU kernels of the chosen level and of its fp32 level */
    mx_kernels checked[2];        /* the same with the weight check before every weight op */
    mx_kernels traced[2];         /* the checked tables, each call traced inside a recorded region */
    mx_status fault;              /* the first refused op (code 0: none), sticky */
    int region;                   /* inside a recorded region (ops/record.h): no alloc, release, copy */
    mx_status region_fault;       /* the first call the region refused (code 0: none) */
    struct strict_trace *trace;   /* the open region's op trace (strict_recorded), or NULL */
    size_t trace_pos;             /* ops the open region has queued so far */
} strict_state;

/* 1 (and the region's fault kept) when `call` is made inside a recorded region: CUDA cannot
 * capture an allocation, a free or a host copy into a graph (each waits or changes memory the
 * graph's replays would still use), so cpu-strict refuses them where the GPU would fail. */
static int strict_in_region(strict_state *s, const char *call) {
    if (!s->region) return 0;
    if (!s->region_fault.code)
        mx_fail(&s->region_fault, MX_EINTERNAL,
                "cpu-strict: %s inside a recorded region (ops/record.h): a CUDA graph cannot capture it; do it "
                "before the region",
                call);
    return 1;
}

/* The refusal of strict_in_region in st (when there is one). */
static int strict_refused(strict_state *s, mx_status *st) {
    if (st) *st = s->region_fault;
    return -1;
}

static void strict_protect(strict_state *s, int prot) {
    for (size_t i = 0; i < s->n; i++)
        if (!s->maps[i].weight && mprotect(s->maps[i].p, s->maps[i].bytes, prot) != 0)
            abort(); /* cannot keep the guarantee */
}

static void strict_enter(mx_backend *be) {
    strict_state *s = be->impl;
    if (s->depth++ == 0) strict_protect(s, PROT_READ | PROT_WRITE);
}

static void strict_leave(mx_backend *be) {
    strict_state *s = be->impl;
    if (--s->depth == 0) strict_protect(s, PROT_NONE);
}

static void *strict_map_new(mx_backend *be, size_t bytes, int prot, int weight, mx_status *st) {
    strict_state *s = be->impl;
    if (s->n == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 64;
        strict_map *m = realloc(s->maps, cap * sizeof *m);
        if (!m) {
            mx_fail(st, MX_ENOMEM, "cpu-strict: out of memory");
            return NULL;
        }
        s->maps = m;
        s->cap = cap;
    }
    size_t n = bytes ? bytes : 1;
    void *p = mmap(NULL, n, prot, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) {
        mx_fail(st, MX_ENOMEM, "cpu-strict: cannot map %zu bytes", bytes);
        return NULL;
    }
    s->maps[s->n++] = (strict_map){.p = p, .bytes = n, .weight = weight};
    return p;
}

static void *strict_alloc(mx_backend *be, size_t bytes, mx_status *st) {
    strict_state *s = be->impl;
    if (strict_in_region(s, "a device allocation (mx_dev_alloc, an arena)")) return strict_refused(s, st), NULL;
    return strict_map_new(be, bytes, s->depth > 0 ? PROT_READ | PROT_WRITE : PROT_NONE, 0, st);
}

/* The copy of a weight file whose host mapping holds [src, src + bytes), or NULL. */
static const strict_map *strict_file_of(const strict_state *s, const void *src, size_t bytes) {
    uintptr_t a = (uintptr_t)src;
    for (size_t i = 0; i < s->n; i++) {
        uintptr_t m = (uintptr_t)s->maps[i].file_map;
        if (m && a >= m && a - m <= s->maps[i].bytes && bytes <= s->maps[i].bytes - (a - m)) return &s->maps[i];
    }
    return NULL;
}

static void *strict_weight(mx_backend *be, const void *src, size_t bytes, mx_status *st) {
    if (strict_in_region(be->impl, "a weight upload (mx_dev_weight)")) return strict_refused(be->impl, st), NULL;
    const strict_map *f = strict_file_of(be->impl, src, bytes);
    if (f) return (unsigned char *)f->p + ((uintptr_t)src - (uintptr_t)f->file_map);
    void *p = strict_map_new(be, bytes, PROT_READ | PROT_WRITE, 1, st);
    if (!p) return NULL;
    if (bytes) memcpy(p, src, bytes);
    if (mprotect(p, bytes ? bytes : 1, PROT_READ) != 0) abort();
    return p;
}

static void strict_release(mx_backend *be, void *p) {
    strict_state *s = be->impl;
    strict_in_region(s, "a device free (mx_dev_free, an arena's end)"); /* kept for the region; freed all the same */
    for (size_t i = 0; i < s->n; i++)
        if (s->maps[i].p == p) {
            munmap(p, s->maps[i].bytes);
            s->maps[i] = s->maps[--s->n];
            return;
        }
}

/* The device side of the file stream: copies at once (so waits have nothing to wait for). */
static int strict_stream_copy(void *arg, int slot, const void *buf, size_t n, uint64_t off, mx_status *st) {
    (void)slot, (void)st;
    memcpy((unsigned char *)arg + off, buf, n);
    return 0;
}

static int strict_stream_wait(void *arg, int slot, mx_status *st) {
    (void)arg, (void)slot, (void)st;
    return 0;
}

enum { STRICT_STREAM_BUFS = 3, STRICT_STREAM_CHUNK = 1 << 20 };

static int strict_weight_file(mx_backend *be, int fd, const void *map, size_t len, const char *path,
                              const mx_stream_observer *obs, mx_status *st) {
    strict_state *s = be->impl;
    if (strict_in_region(s, "a weight file upload (mx_dev_weight_file)")) return strict_refused(s, st);
    if (strict_file_of(s, map, len)) return 0;
    unsigned char *p = strict_map_new(be, len, PROT_READ | PROT_WRITE, 1, st);
    unsigned char *ring = malloc((size_t)STRICT_STREAM_BUFS * STRICT_STREAM_CHUNK);
    if (!p || !ring) {
        free(ring);
        if (p) strict_release(be, p);
        return p ? mx_fail(st, MX_ENOMEM, "cpu-strict: out of memory") : -1;
    }
    unsigned char *bufs[STRICT_STREAM_BUFS];
    for (int i = 0; i < STRICT_STREAM_BUFS; i++) bufs[i] = ring + (size_t)i * STRICT_STREAM_CHUNK;
    mx_stream_ring r = {bufs, STRICT_STREAM_BUFS, STRICT_STREAM_CHUNK, 2, 1};
    mx_stream_sink sink = {p, strict_stream_copy, strict_stream_wait};
    int rc = mx_file_stream(fd, path, len, &r, &sink, obs, NULL, st);
    free(ring);
    if (rc) {
        strict_release(be, p);
        return -1;
    }
    if (mprotect(p, len ? len : 1, PROT_READ) != 0) abort();
    for (size_t i = 0; i < s->n; i++)
        if (s->maps[i].p == p) s->maps[i].file_map = map;
    return 1;
}

static void strict_weight_file_drop(mx_backend *be, const void *map) {
    strict_state *s = be->impl;
    strict_in_region(s, "a weight file's release (mx_dev_weight_file_drop)");
    for (size_t i = 0; i < s->n; i++)
        if (s->maps[i].file_map == map) {
            strict_release(be, s->maps[i].p);
            return;
        }
}

static int strict_copy(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    strict_enter(be);
    host_copy(be, dst, src, bytes, st);
    strict_leave(be);
    return 0;
}

static int strict_to_device(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    if (strict_in_region(be->impl, "a host-to-device copy (mx_upload)")) return strict_refused(be->impl, st);
    return strict_copy(be, dst, src, bytes, st);
}

/* A download reports the first refused op, as CUDA reports a fault at the next wait. */
static int strict_to_host(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    strict_state *s = be->impl;
    if (strict_in_region(s, "a device-to-host copy (mx_download: a wait for the device)")) return strict_refused(s, st);
    if (s->fault.code) {
        if (st) *st = s->fault;
        return -1;
    }
    return strict_copy(be, dst, src, bytes, st);
}

static void strict_destroy(mx_backend *be) {
    strict_state *s = be->impl;
    for (size_t i = 0; i < s->n; i++) munmap(s->maps[i].p, s->maps[i].bytes);
    free(s->maps);
    free(s);
    free(be);
}

/* 1 when w is absent or lies in one weight copy of this backend, where `numel` elements fit;
 * else 0, and the first such refusal is kept: the op, the argument and its shape name the tensor. */
static int strict_weight_ok(const mx_ctx *c, mx_wptr w, size_t numel, const char *op, const char *arg,
                            const char *shape) {
    strict_state *s = c->be->impl;
    if (!w.data) return 1;
    uintptr_t a = (uintptr_t)w.data, end = a + numel * mx_dtype_size(w.dtype);
    for (size_t i = 0; i < s->n; i++) {
        uintptr_t m = (uintptr_t)s->maps[i].p;
        if (s->maps[i].weight && a >= m && end <= m + s->maps[i].bytes) return 1;
    }
    if (!s->fault.code)
        mx_fail(&s->fault, MX_EINTERNAL,
                "cpu-strict: op %s: weight %s %s (%s) at %p is not device memory: on a device context every "
                "weight is bound through mx_binder_device (or copied with mx_dev_weight), never a host binder",
                op, arg, shape, mx_dtype_name(w.dtype), w.data);
    return 0;
}

/* The CPU kernels c's table wraps (the chosen level's, or its fp32 level's under mx_ctx_fp32). */
static const mx_kernels *strict_inner(const mx_ctx *c) {
    strict_state *s = c->be->impl;
    return s->inner[c->k == &s->traced[1]];
}

#define SHAPE_(buf, ...) (snprintf(buf, sizeof buf, __VA_ARGS__), buf)

static void strict_linear(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    char sw[48], sb[48];
    if (strict_weight_ok(c, w, (size_t)N * (size_t)K, "linear", "w", SHAPE_(sw, "[%d, %d]", N, K)) &&
        strict_weight_ok(c, bias, (size_t)N, "linear", "bias", SHAPE_(sb, "[%d]", N)))
        strict_inner(c)->linear(c, y, x, w, bias, M, N, K);
}

static void strict_conv2d(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                          mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    char sw[64], sb[48];
    if (strict_weight_ok(c, w, (size_t)Cout * (size_t)Cin * (size_t)(kh * kw), "conv2d", "w",
                         SHAPE_(sw, "[%d, %d, %d, %d]", Cout, Cin, kh, kw)) &&
        strict_weight_ok(c, bias, (size_t)Cout, "conv2d", "bias", SHAPE_(sb, "[%d]", Cout)))
        strict_inner(c)->conv2d(c, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad);
}

static void strict_conv2d_up2x(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                               mx_wptr bias, int Cout) {
    char sw[64], sb[48];
    if (strict_weight_ok(c, w, (size_t)Cout * (size_t)Cin * 9, "conv2d_up2x", "w",
                         SHAPE_(sw, "[%d, %d, 3, 3]", Cout, Cin)) &&
        strict_weight_ok(c, bias, (size_t)Cout, "conv2d_up2x", "bias", SHAPE_(sb, "[%d]", Cout)))
        strict_inner(c)->conv2d_up2x(c, y, x, B, Cin, H, W, w, bias, Cout);
}

/* gamma and beta of a norm over C channels. */
static int strict_norm_ok(const mx_ctx *c, mx_wptr gamma, mx_wptr beta, int C, const char *op) {
    char sc[48];
    SHAPE_(sc, "[%d]", C);
    return strict_weight_ok(c, gamma, (size_t)C, op, "gamma", sc) && strict_weight_ok(c, beta, (size_t)C, op, "beta", sc);
}

static void strict_group_norm(const mx_ctx *c, float *y, const float *x, int B, int C, int HW, int groups,
                              mx_wptr gamma, mx_wptr beta, float eps, int fuse_silu) {
    if (strict_norm_ok(c, gamma, beta, C, "group_norm"))
        strict_inner(c)->group_norm(c, y, x, B, C, HW, groups, gamma, beta, eps, fuse_silu);
}

static void strict_layer_norm(const mx_ctx *c, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                              float eps) {
    if (strict_norm_ok(c, gamma, beta, C, "layer_norm")) strict_inner(c)->layer_norm(c, y, x, M, C, gamma, beta, eps);
}

/* The token table's rows are not known here (the caller checked the ids): its first row is. */
static void strict_embed_tokens(const mx_ctx *c, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                                mx_wptr positions) {
    char st_[48], sp[48];
    if (strict_weight_ok(c, tokens, (size_t)C, "embed_tokens", "tokens", SHAPE_(st_, "[vocabulary, %d]", C)) &&
        strict_weight_ok(c, positions, (size_t)T * (size_t)C, "embed_tokens", "positions", SHAPE_(sp, "[%d, %d]", T, C)))
        strict_inner(c)->embed_tokens(c, y, ids, B, T, C, tokens, positions);
}

#undef SHAPE_

/* The CPU table with the ops that take weights checked first. */
static void strict_table(mx_kernels *t, const mx_kernels *inner) {
    *t = *inner;
    t->linear = strict_linear;
    t->conv2d = strict_conv2d;
    t->conv2d_up2x = strict_conv2d_up2x;
    t->group_norm = strict_group_norm;
    t->layer_norm = strict_layer_norm;
    t->embed_tokens = strict_embed_tokens;
}

/* ---- cpu-strict's recorded regions (ops/record.h) ----
 * A region's second call is what a GPU captures as a graph and replays at every later call without
 * its host code. cpu-strict runs every call, refuses inside it what a graph cannot hold
 * (strict_in_region), and keeps the second call's trace: per op its id and the bytes of its
 * arguments (pointers, sizes, host scalars), hashed. Every later call must queue the same trace:
 * a difference is a value the replay would not have (e.g. a per-step scalar passed to an op instead
 * of read from device memory written before the region). Arrays passed by pointer (binary's
 * shapes, lincomb's terms) count by their address, not their contents. */

typedef struct strict_trace {
    uint64_t *h; /* per op of the second call */
    size_t n, cap;
    int done;    /* 1 once the second call is traced: later calls are compared */
} strict_trace;

static uint64_t trace_bytes(uint64_t h, const void *p, size_t n) {
    const unsigned char *b = p;
    for (size_t i = 0; i < n; i++) h = (h ^ b[i]) * 1099511628211ull; /* FNV-1a */
    return h;
}

/* A weight by its pointer and type (not the bytes of its padded struct). */
static uint64_t trace_wptr(uint64_t h, const void *p, size_t n) {
    const mx_wptr *w = p;
    (void)n;
    h = trace_bytes(h, &w->data, sizeof w->data);
    return trace_bytes(h, &w->dtype, sizeof w->dtype);
}

/* One op of the open region: appended to the trace of its second call, or compared with it. */
static void trace_op(strict_state *s, int op, uint64_t h) {
    strict_trace *t = s->trace;
    size_t i = s->trace_pos++;
    h = trace_bytes(h, &op, sizeof op);
    if (t->done) {
        if ((i >= t->n || t->h[i] != h) && !s->region_fault.code)
            mx_fail(&s->region_fault, MX_EINTERNAL,
                    "cpu-strict: a recorded region (ops/record.h) differs from its captured call at op %zu (%s): "
                    "another op or other arguments, which a CUDA graph's replay would not have; pass what changes "
                    "call by call in device memory written before the region",
                    i + 1, mx_op_name(op));
        return;
    }
    if (t->n == t->cap) {
        size_t cap = t->cap ? 2 * t->cap : 1024;
        uint64_t *g = realloc(t->h, cap * sizeof *g);
        if (!g) {
            if (!s->region_fault.code) mx_fail(&s->region_fault, MX_ENOMEM, "cpu-strict: out of memory (region trace)");
            return;
        }
        t->h = g;
        t->cap = cap;
    }
    t->h[t->n++] = h;
}

/* FOR_EACH_(m, a, b, ...): m(a) m(b) ... for up to 16 arguments. */
#define FE1_(m, x) m(x)
#define FE2_(m, x, ...) m(x) FE1_(m, __VA_ARGS__)
#define FE3_(m, x, ...) m(x) FE2_(m, __VA_ARGS__)
#define FE4_(m, x, ...) m(x) FE3_(m, __VA_ARGS__)
#define FE5_(m, x, ...) m(x) FE4_(m, __VA_ARGS__)
#define FE6_(m, x, ...) m(x) FE5_(m, __VA_ARGS__)
#define FE7_(m, x, ...) m(x) FE6_(m, __VA_ARGS__)
#define FE8_(m, x, ...) m(x) FE7_(m, __VA_ARGS__)
#define FE9_(m, x, ...) m(x) FE8_(m, __VA_ARGS__)
#define FE10_(m, x, ...) m(x) FE9_(m, __VA_ARGS__)
#define FE11_(m, x, ...) m(x) FE10_(m, __VA_ARGS__)
#define FE12_(m, x, ...) m(x) FE11_(m, __VA_ARGS__)
#define FE13_(m, x, ...) m(x) FE12_(m, __VA_ARGS__)
#define FE14_(m, x, ...) m(x) FE13_(m, __VA_ARGS__)
#define FE15_(m, x, ...) m(x) FE14_(m, __VA_ARGS__)
#define FE16_(m, x, ...) m(x) FE15_(m, __VA_ARGS__)
#define FE_PICK_(_1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, N, ...) N
#define FOR_EACH_(m, ...)                                                                                    \
    FE_PICK_(__VA_ARGS__, FE16_, FE15_, FE14_, FE13_, FE12_, FE11_, FE10_, FE9_, FE8_, FE7_, FE6_, FE5_, FE4_, \
             FE3_, FE2_, FE1_, )(m, __VA_ARGS__)
#define TRACE_ARG_(x) h_ = _Generic((x), mx_wptr: trace_wptr, default: trace_bytes)(h_, &(x), sizeof(x));

/* Each op: traced while a region is open, then the checked table of c's level. */
#define STRICT_TRACED_(name, guard, params, args, cost)                                                      \
    static void strict_traced_##name(const mx_ctx *c, MX_SPLICE params) {                                    \
        strict_state *s_ = c->be->impl;                                                                      \
        if (s_->trace) {                                                                                     \
            uint64_t h_ = 14695981039346656037ull;                                                           \
            FOR_EACH_(TRACE_ARG_, MX_SPLICE args)                                                            \
            trace_op(s_, MX_OP_ID_##name, h_);                                                               \
        }                                                                                                    \
        s_->checked[c->k == &s_->traced[1]].name(c, MX_SPLICE args);                                         \
    }
MX_OPS(STRICT_TRACED_)

static void strict_traced_table(mx_kernels *t, mx_isa isa) {
    t->isa = isa;
#define STRICT_TRACED_FILL_(name, guard, params, args, cost) t->name = strict_traced_##name;
    MX_OPS(STRICT_TRACED_FILL_)
#undef STRICT_TRACED_FILL_
}

/* A recorded region's later calls: fn runs as it is, with every alloc, release and host copy
 * refused (strict_in_region) and its op trace kept (second call) or compared (later calls), the
 * trace being what rec holds as its "graph"; the first refusal or difference is the region's error. */
static int strict_recorded(mx_backend *be, mx_record *rec, int (*fn)(void *user, mx_status *st), void *user,
                           mx_status *st) {
    strict_state *s = be->impl;
    strict_trace *t = rec->graph;
    if (!t && !(t = rec->graph = calloc(1, sizeof *t))) return mx_fail(st, MX_ENOMEM, "cpu-strict: out of memory");
    memset(&s->region_fault, 0, sizeof s->region_fault);
    s->trace = t;
    s->trace_pos = 0;
    s->region++;
    int rc = fn(user, st);
    s->region--;
    s->trace = NULL;
    if (t->done && s->trace_pos != t->n && !s->region_fault.code)
        mx_fail(&s->region_fault, MX_EINTERNAL,
                "cpu-strict: a recorded region (ops/record.h) queued %zu ops, its captured call %zu: a CUDA graph's "
                "replay would queue the captured ones",
                s->trace_pos, t->n);
    t->done = 1;
    return s->region_fault.code ? strict_refused(s, st) : rc;
}

static void strict_record_drop(mx_backend *be, mx_record *rec) {
    strict_trace *t = rec->graph;
    (void)be;
    if (t) free(t->h);
    free(t);
    rec->graph = NULL;
}

static int strict_setup(mx_backend *be, mx_isa isa, mx_status *st) {
    strict_state *s = calloc(1, sizeof *s);
    if (!s) return mx_fail(st, MX_ENOMEM, "backend: out of memory");
    s->inner[0] = mx_kernels_for(isa);
    s->inner[1] = mx_kernels_fp32_of(s->inner[0]);
    strict_table(&s->checked[0], s->inner[0]);
    strict_table(&s->checked[1], s->inner[1]);
    strict_traced_table(&s->traced[0], s->inner[0]->isa);
    strict_traced_table(&s->traced[1], s->inner[1]->isa);
    be->impl = s;
    be->k = &s->traced[0];
    be->k_fp32 = &s->traced[1];
    be->host_visible = 0;
    be->alloc = strict_alloc;
    be->weight = strict_weight;
    be->weight_file = strict_weight_file;
    be->weight_file_drop = strict_weight_file_drop;
    be->release = strict_release;
    be->to_device = strict_to_device;
    be->to_host = strict_to_host;
    be->recorded = strict_recorded;
    be->record_drop = strict_record_drop;
    be->enter = strict_enter;
    be->leave = strict_leave;
    be->destroy = strict_destroy;
    return 0;
}

/* ---- factory ---- */

static int cpu_backend_create(mx_backend **out, mx_backend_kind kind, mx_isa isa, mx_status *st) {
    mx_backend *be = calloc(1, sizeof *be);
    if (!be) return mx_fail(st, MX_ENOMEM, "backend: out of memory");
    be->kind = kind;
    be->k = mx_kernels_for(isa);
    be->host_visible = 1;
    be->to_device = host_copy;
    be->to_host = host_copy;
    if (kind == MX_BACKEND_CPU_STRICT) {
        if (strict_setup(be, isa, st)) {
            free(be);
            return -1;
        }
        *out = be;
        return 0;
    }
    host_state *h = calloc(1, sizeof *h);
    if (!h || pthread_mutex_init(&h->mu, NULL)) {
        free(h);
        free(be);
        return mx_fail(st, MX_ENOMEM, "backend: out of memory");
    }
    be->impl = h;
    be->alloc = host_alloc;
    be->release = host_release;
    be->destroy = host_destroy;
    *out = be;
    return 0;
}

/* "cuda", or a CPU kind with its level: "cpu-strict (avx512)". */
static void backend_label(const mx_backend *be, char *buf, size_t cap) {
    if (be->kind == MX_BACKEND_CUDA)
        snprintf(buf, cap, "%s", mx_backend_name(be->kind));
    else
        snprintf(buf, cap, "%s (%s)", mx_backend_name(be->kind), mx_isa_name(be->k->isa));
}

/* Every backend's table is checked full here, so a missing kernel is one clear line at context
 * creation, never a NULL call in the middle of a run. */
int mx_backend_create(mx_backend **out, mx_backend_kind kind, mx_isa isa, mx_status *st) {
    *out = NULL;
    if (!mx_backend_compiled(kind))
        return mx_fail(st, MX_EUSAGE, "this matex was built without the %s backend (build it with `make %s`)",
                       mx_backend_name(kind), mx_backend_name(kind));
    int rc;
#ifdef MX_WITH_CUDA
    if (kind == MX_BACKEND_CUDA)
        rc = mx_cuda_backend_create(out, st);
    else
#endif
        rc = cpu_backend_create(out, kind, isa, st);
    if (rc) return rc;
    char name[64];
    backend_label(*out, name, sizeof name);
    if (mx_kernels_check((*out)->k, name, st)) {
        mx_backend_destroy(*out);
        *out = NULL;
        return -1;
    }
    return 0;
}

void mx_backend_destroy(mx_backend *be) {
    if (be) be->destroy(be);
}
