/* Scalar references of GELU (erf), quick-GELU (CLIP), SiLU, GEGLU and tanh, computed in double. */
#include <math.h>

#include "kernels.h"

typedef float (*unary_fn)(float);

/* x/2 · (1 + erf(x/√2)) written with erfc, which keeps the tiny values of negative x exact */
static float gelu_one(float v) { return (float)(0.5 * v * erfc(-(double)v * 0.70710678118654752440)); }
static float quick_gelu_one(float v) { return (float)((double)v / (1.0 + exp(-1.702 * (double)v))); }
static float silu_one(float v) { return (float)((double)v / (1.0 + exp(-(double)v))); }

typedef struct {
    float *x;
    size_t n;
    unary_fn fn;
} unary_args;

static void unary_chunk(void *arg, int task, int thread) {
    (void)thread;
    const unary_args *a = arg;
    size_t i0 = (size_t)task * MX_EW_CHUNK, i1 = i0 + MX_EW_CHUNK < a->n ? i0 + MX_EW_CHUNK : a->n;
    for (size_t i = i0; i < i1; i++) a->x[i] = a->fn(a->x[i]);
}

static void unary_run(const mx_ctx *c, float *x, size_t n, unary_fn fn) {
    unary_args a = {x, n, fn};
    mx_par_for(c, (int)((n + MX_EW_CHUNK - 1) / MX_EW_CHUNK), unary_chunk, &a);
}

void mx_gelu_ref(const mx_ctx *c, float *x, size_t n) { unary_run(c, x, n, gelu_one); }
void mx_quick_gelu_ref(const mx_ctx *c, float *x, size_t n) { unary_run(c, x, n, quick_gelu_one); }
void mx_silu_ref(const mx_ctx *c, float *x, size_t n) { unary_run(c, x, n, silu_one); }

typedef struct {
    float *y;
    const float *x;
    int N;
} geglu_args;

static void geglu_row(void *arg, int m, int thread) {
    (void)thread;
    const geglu_args *a = arg;
    const float *h = a->x + (size_t)m * 2 * a->N, *g = h + a->N;
    float *yr = a->y + (size_t)m * a->N;
    for (int i = 0; i < a->N; i++) yr[i] = (float)((double)h[i] * gelu_one(g[i]));
}

void mx_geglu_ref(const mx_ctx *c, float *y, const float *x, int M, int N) {
    geglu_args a = {y, x, N};
    mx_par_for(c, M, geglu_row, &a);
}

static float tanh_one(float v) { return (float)tanh((double)v); }

void mx_tanh_ref(const mx_ctx *c, float *x, size_t n) { unary_run(c, x, n, tanh_one); }
