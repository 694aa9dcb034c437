/* Scalar references of the element-wise arithmetic: broadcasting binary ops and scaling. */
#include "kernels.h"

typedef struct {
    mx_binop op;
    float *y;
    const float *a, *b;
    int ndim;
    int64_t oshape[MX_MAX_DIMS], astride[MX_MAX_DIMS], bstride[MX_MAX_DIMS];
    size_t n;
} binary_args;

static float apply_binop(mx_binop op, float a, float b) {
    switch (op) {
    case MX_BIN_ADD: return a + b;
    case MX_BIN_SUB: return a - b;
    case MX_BIN_MUL: return a * b;
    }
    return 0;
}

/* Strides (in elements) of a tensor of `shape`, with 0 on broadcast (size-1) dims. */
static void broadcast_strides(const int64_t *shape, int ndim, int64_t *stride) {
    int64_t s = 1;
    for (int d = ndim - 1; d >= 0; d--) {
        stride[d] = shape[d] == 1 ? 0 : s;
        s *= shape[d];
    }
}

static void binary_chunk(void *arg, int task, int thread) {
    (void)thread;
    const binary_args *a = arg;
    size_t i0 = (size_t)task * MX_EW_CHUNK, i1 = i0 + MX_EW_CHUNK < a->n ? i0 + MX_EW_CHUNK : a->n;
    for (size_t i = i0; i < i1; i++) {
        size_t rem = i;
        int64_t ai = 0, bi = 0;
        for (int d = a->ndim - 1; d >= 0; d--) {
            int64_t idx = (int64_t)(rem % (size_t)a->oshape[d]);
            rem /= (size_t)a->oshape[d];
            ai += idx * a->astride[d];
            bi += idx * a->bstride[d];
        }
        a->y[i] = apply_binop(a->op, a->a[ai], a->b[bi]);
    }
}

void mx_binary_ref(const mx_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b,
                   const int64_t *bshape, int ndim) {
    binary_args args = {.op = op, .y = y, .a = a, .b = b, .ndim = ndim, .n = 1};
    for (int d = 0; d < ndim; d++) {
        args.oshape[d] = ashape[d] > bshape[d] ? ashape[d] : bshape[d];
        args.n *= (size_t)args.oshape[d];
    }
    if (args.n == 0) return;
    broadcast_strides(ashape, ndim, args.astride);
    broadcast_strides(bshape, ndim, args.bstride);
    mx_par_for(c, (int)((args.n + MX_EW_CHUNK - 1) / MX_EW_CHUNK), binary_chunk, &args);
}

typedef struct {
    float *y;
    const float *x;
    float s;
    size_t n;
} scale_args;

static void scale_chunk(void *arg, int task, int thread) {
    (void)thread;
    const scale_args *a = arg;
    size_t i0 = (size_t)task * MX_EW_CHUNK, i1 = i0 + MX_EW_CHUNK < a->n ? i0 + MX_EW_CHUNK : a->n;
    for (size_t i = i0; i < i1; i++) a->y[i] = a->s * a->x[i];
}

void mx_scale_ref(const mx_ctx *c, float *y, const float *x, float s, size_t n) {
    scale_args a = {y, x, s, n};
    mx_par_for(c, (int)((n + MX_EW_CHUNK - 1) / MX_EW_CHUNK), scale_chunk, &a);
}
