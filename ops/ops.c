/* The op wrappers (ops.h, generated from op_list.h), the table check, weight access, scratch
 * memory, the edges and the dry run. The ready-made context, which needs the backends, is
 * ops/ctx.c (backend.c uses this file's tables, so this file never calls back into it). */
#include "ops.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cpu/kernels.h"

float mx_w_get(mx_wptr w, size_t i) {
    switch (w.dtype) {
    case MX_F16: return mx_half_to_float(((const uint16_t *)w.data)[i]);
    case MX_BF16: return mx_bf16_to_float(((const uint16_t *)w.data)[i]);
    default: return ((const float *)w.data)[i];
    }
}

void *mx_scratch_take(const mx_ctx *c, size_t bytes, mx_scratch *s) {
    memset(s, 0, sizeof *s);
    if (c && c->scratch && !c->scratch->measuring) {
        s->mark = mx_arena_mark(c->scratch);
        s->p = mx_arena_alloc(c->scratch, bytes, NULL);
        if (s->p) return s->p;
    }
    s->heap = 1;
    s->p = aligned_alloc(MX_ARENA_ALIGN, (bytes + MX_ARENA_ALIGN - 1) / MX_ARENA_ALIGN * MX_ARENA_ALIGN);
    return s->p;
}

void mx_scratch_release(const mx_ctx *c, mx_scratch *s) {
    if (s->heap)
        free(s->p);
    else if (s->p)
        mx_arena_reset(c->scratch, s->mark);
    s->p = NULL;
}

/* The kernels of one op call, or NULL in a dry run. The backend's enter/leave bracket the
 * kernel (cpu-strict opens its memory only for that long). */
static const mx_kernels *op_begin(const mx_ctx *c) {
    if (!c) return mx_kernels_best();
    if (c->measuring) return NULL;
    if (c->be && c->be->enter) c->be->enter(c->be);
    return c->k ? c->k : mx_kernels_best();
}

static void op_end(const mx_ctx *c) {
    if (c && c->be && c->be->leave) c->be->leave(c->be);
}

/* Op id's call through the kernel table, timed (process CPU time) and costed when c carries a
 * profile. */
#define RUN_OP(c, id, call, cost)                                                                            \
    do {                                                                                                     \
        const mx_kernels *k_ = op_begin(c);                                                                  \
        if (k_) {                                                                                            \
            double t0_ = c && c->prof ? mx_profile_clock(CLOCK_PROCESS_CPUTIME_ID) : 0;                       \
            double w0_ = c && c->prof ? mx_profile_clock(CLOCK_MONOTONIC) : 0;                                \
            k_->call;                                                                                        \
            if (c && c->prof)                                                                                \
                profile_op(c->prof, id, mx_profile_clock(CLOCK_PROCESS_CPUTIME_ID) - t0_,                     \
                           mx_profile_clock(CLOCK_MONOTONIC) - w0_, cost);                                    \
            op_end(c);                                                                                       \
        }                                                                                                    \
    } while (0)

static void profile_op(mx_profile *p, int id, double secs, double wall, mx_op_cost cost) {
    p->op_secs[id] += secs;
    p->op_wall[id] += wall;
    p->op_calls[id]++;
    p->op_flops[id] += cost.flops;
    p->op_bytes[id] += cost.bytes;
    if (p->peak_flops > 0 && p->bandwidth > 0) p->op_floor[id] += fmax(cost.flops / p->peak_flops, cost.bytes / p->bandwidth);
}

/* ---- the costs of op_list.h ---- */

static mx_op_cost mx_cost(double flops, double bytes) { return (mx_op_cost){flops, bytes}; }

/* n outputs at one FLOP each, `arrays` arrays of n floats read or written. */
static mx_op_cost mx_cost_elementwise(double n, int arrays) { return mx_cost(n, 4.0 * n * arrays); }

static double weight_bytes(mx_wptr w, double n) { return n * (double)mx_dtype_size(w.dtype); }

double mx_linear_flops(int M, int N, int K) { return 2.0 * M * N * (double)K; }

double mx_attention_flops(int B, int H, int Tq, int Tk, int D) { return 4.0 * B * H * Tq * (double)Tk * D; }

static mx_op_cost mx_cost_linear(mx_wptr w, int M, int N, int K) {
    return mx_cost(mx_linear_flops(M, N, K), 4.0 * M * ((double)K + N) + weight_bytes(w, (double)N * K));
}

double mx_conv2d_flops(int B, int Cin, int Ho, int Wo, int Cout, int kh, int kw) {
    return 2.0 * B * Cout * (double)Ho * Wo * Cin * kh * kw;
}

/* The phase form's products: 4 phases × Cout outputs over (H+1)×(W+1) positions, 2×2 taps each. */
double mx_conv2d_up2x_flops(int B, int Cin, int H, int W, int Cout) {
    return 2.0 * B * 4.0 * Cout * (H + 1.0) * (W + 1.0) * Cin * 4.0;
}

static mx_op_cost mx_cost_conv2d(int B, int Cin, int H, int W, mx_wptr w, int Cout, int kh, int kw, int stride,
                                 int pad) {
    int Ho = (H + 2 * pad - kh) / stride + 1, Wo = (W + 2 * pad - kw) / stride + 1;
    return mx_cost(mx_conv2d_flops(B, Cin, Ho, Wo, Cout, kh, kw),
                   4.0 * B * ((double)Cin * H * W + Cout * (double)Ho * Wo) +
                       weight_bytes(w, (double)Cout * Cin * kh * kw));
}

static mx_op_cost mx_cost_conv2d_up2x(int B, int Cin, int H, int W, mx_wptr w, int Cout) {
    double out = 4.0 * H * W;
    return mx_cost(mx_conv2d_up2x_flops(B, Cin, H, W, Cout),
                   4.0 * B * ((double)Cin * H * W + Cout * out) + weight_bytes(w, (double)Cout * Cin * 9));
}

/* q·kᵀ and p·v; q, k, v read and the output written once (the scores never leave the cache). */
static mx_op_cost mx_cost_attention(int B, int H, int Tq, int Tk, int D) {
    return mx_cost(mx_attention_flops(B, H, Tq, Tk, D), 4.0 * B * H * D * (2.0 * Tq + 2.0 * Tk));
}

static double shape_count(const int64_t *shape, int ndim) {
    double n = 1;
    for (int d = 0; d < ndim; d++) n *= (double)shape[d];
    return n;
}

static mx_op_cost mx_cost_binary(const int64_t *ashape, const int64_t *bshape, int ndim) {
    double y = 1;
    for (int d = 0; d < ndim; d++) y *= (double)(ashape[d] > bshape[d] ? ashape[d] : bshape[d]);
    return mx_cost(y, 4.0 * (shape_count(ashape, ndim) + shape_count(bshape, ndim) + y));
}

const char *mx_op_name(int op) {
#define MX_NAME_(name, guard, params, args, cost) #name,
    static const char *const names[MX_OP_COUNT] = {MX_OPS(MX_NAME_)};
#undef MX_NAME_
    return op >= 0 && op < MX_OP_COUNT ? names[op] : "?";
}

int mx_shapes_nonempty(const int64_t *ashape, const int64_t *bshape, int ndim) {
    for (int d = 0; d < ndim; d++)
        if (ashape[d] <= 0 || bshape[d] <= 0) return 0;
    return 1;
}

/* Every wrapper has the same shape (op_list.h): no work unless the guard holds, else the table
 * entry. None needs more checking: the kernels take any sizes the guards let through. */
#define MX_WRAPPER_DEF_(name, guard, params, args, cost)                                                     \
    void mx_##name(const mx_ctx *c, MX_SPLICE params) {                                                      \
        if (guard) RUN_OP(c, MX_OP_ID_##name, name(c, MX_SPLICE args), cost);                                \
    }
MX_OPS(MX_WRAPPER_DEF_)

void mx_add(const mx_ctx *c, float *y, const float *a, const float *b, size_t n) {
    int64_t shape[1] = {(int64_t)n};
    mx_binary(c, MX_BIN_ADD, y, a, shape, b, shape, 1);
}

const char *mx_kernels_missing(const mx_kernels *k) {
#define MX_MISSING_(name, guard, params, args, cost)                                                         \
    if (!k->name) return #name;
    MX_OPS(MX_MISSING_)
#undef MX_MISSING_
    return NULL;
}

int mx_kernels_check(const mx_kernels *k, const char *backend, mx_status *st) {
    const char *missing = mx_kernels_missing(k);
    if (missing) return mx_fail(st, MX_EINTERNAL, "op %s is not available on backend %s", missing, backend);
    return 0;
}

/* ---- the edges ---- */

float *mx_dev_alloc(const mx_ctx *c, size_t n, mx_status *st) {
    if (n > SIZE_MAX / sizeof(float) - MX_ARENA_ALIGN) {
        mx_fail(st, MX_ENOMEM, "device memory: %zu floats overflow", n);
        return NULL;
    }
    size_t bytes = (n * sizeof(float) + MX_ARENA_ALIGN - 1) / MX_ARENA_ALIGN * MX_ARENA_ALIGN;
    if (c && c->be) return c->be->alloc(c->be, bytes ? bytes : MX_ARENA_ALIGN, st);
    float *p = aligned_alloc(MX_ARENA_ALIGN, bytes ? bytes : MX_ARENA_ALIGN);
    if (!p) mx_fail(st, MX_ENOMEM, "out of memory (%zu bytes)", bytes);
    return p;
}

void mx_dev_free(const mx_ctx *c, void *p) {
    if (!p) return;
    if (c && c->be)
        c->be->release(c->be, p);
    else
        free(p);
}

int mx_upload(const mx_ctx *c, float *dst, const float *src, size_t n, mx_status *st) {
    if (c && c->measuring) return 0;
    if (c && c->be) return c->be->to_device(c->be, dst, src, n * sizeof(float), st);
    if (n) memcpy(dst, src, n * sizeof(float));
    return 0;
}

int mx_download(const mx_ctx *c, float *dst, const float *src, size_t n, mx_status *st) {
    if (c && c->measuring) return 0;
    if (c && c->be) return c->be->to_host(c->be, dst, src, n * sizeof(float), st);
    if (n) memcpy(dst, src, n * sizeof(float));
    return 0;
}

float *mx_dev_from_host(const mx_ctx *c, const float *src, size_t n, mx_status *st) {
    float *p = mx_dev_alloc(c, n, st);
    if (p && mx_upload(c, p, src, n, st)) {
        mx_dev_free(c, p);
        return NULL;
    }
    return p;
}

void *mx_dev_weight(const mx_ctx *c, const void *src, size_t bytes, mx_status *st) {
    mx_backend *be = c ? c->be : NULL;
    if (be && be->weight) return be->weight(be, src, bytes, st);
    void *p = mx_dev_alloc(c, bytes / sizeof(float) + 1, st);
    if (!p) return NULL;
    if (!be) {
        memcpy(p, src, bytes);
    } else if (be->to_device(be, p, src, bytes, st)) {
        mx_dev_free(c, p);
        return NULL;
    }
    return p;
}

int mx_dev_weight_file(const mx_ctx *c, int fd, const void *map, size_t len, const char *path,
                       const mx_stream_observer *obs, mx_status *st) {
    mx_backend *be = c ? c->be : NULL;
    return be && be->weight_file ? be->weight_file(be, fd, map, len, path, obs, st) : 0;
}

void mx_dev_weight_file_drop(const mx_ctx *c, const void *map) {
    mx_backend *be = c ? c->be : NULL;
    if (be && be->weight_file_drop) be->weight_file_drop(be, map);
}

/* ---- the dry run ---- */

static const mx_ctx measuring_ctx = {.measuring = 1};

const mx_ctx *mx_ctx_measuring(void) { return &measuring_ctx; }

const mx_ctx *mx_run_ctx(const mx_ctx *c, const mx_arena *a) { return a->measuring ? &measuring_ctx : c; }

/* What a measuring arena hands out: ops never dereference it (they return at once). */
static _Alignas(MX_ARENA_ALIGN) float placeholder[MX_ARENA_ALIGN / sizeof(float)];

float *mx_act_alloc(mx_arena *a, size_t n, mx_status *st) {
    float *p = mx_arena_floats(a, n, st);
    return a->measuring ? placeholder : p;
}

float *mx_act_placeholder(void) { return placeholder; }

mx_ctx mx_ctx_fp32(const mx_ctx *c) {
    mx_ctx f;
    memset(&f, 0, sizeof f);
    if (!c) return f;
    f = *c;
    if (c->k && mx_isa_precision(c->k->isa) == MX_PREC_BF16)
        f.k = c->be && c->be->k_fp32 ? c->be->k_fp32 : mx_kernels_fp32_of(c->k);
    return f;
}
