/* Element-wise vector ops of the denoising loop and the scheduler step (axpy, linear
 * combination, clamp, affine): plain loops the compiler vectorises, in fixed chunks so the
 * split never depends on the thread count. Shared by every ISA level. */
#include "kernels.h"

typedef struct {
    float *y;
    const float *x[MX_LINCOMB_MAX];
    float coef[MX_LINCOMB_MAX];
    int k;
    size_t n;
} lincomb_args;

static void lincomb_chunk(void *arg, int task, int thread) {
    (void)thread;
    const lincomb_args *a = arg;
    size_t lo = (size_t)task * MX_EW_CHUNK, hi = lo + MX_EW_CHUNK < a->n ? lo + MX_EW_CHUNK : a->n;
    for (size_t i = lo; i < hi; i++) {
        float s = a->coef[0] * a->x[0][i];
        for (int j = 1; j < a->k; j++) s = s + a->coef[j] * a->x[j][i];
        a->y[i] = s;
    }
}

static int chunks(size_t n) { return (int)((n + MX_EW_CHUNK - 1) / MX_EW_CHUNK); }

void mx_lincomb_ref(const mx_ctx *c, float *y, int k, const float *coef, const float *const *x, size_t n) {
    lincomb_args a = {.y = y, .k = k, .n = n};
    for (int j = 0; j < k; j++) {
        a.x[j] = x[j];
        a.coef[j] = coef[j];
    }
    mx_par_for(c, chunks(n), lincomb_chunk, &a);
}

typedef struct {
    float *y;
    const float *x;
    float p, q;
    size_t n;
} ew_args;

static void axpy_chunk(void *arg, int task, int thread) {
    (void)thread;
    const ew_args *a = arg;
    size_t lo = (size_t)task * MX_EW_CHUNK, hi = lo + MX_EW_CHUNK < a->n ? lo + MX_EW_CHUNK : a->n;
    for (size_t i = lo; i < hi; i++) a->y[i] = a->y[i] + a->p * a->x[i];
}

static void clamp_chunk(void *arg, int task, int thread) {
    (void)thread;
    const ew_args *a = arg;
    size_t lo = (size_t)task * MX_EW_CHUNK, hi = lo + MX_EW_CHUNK < a->n ? lo + MX_EW_CHUNK : a->n;
    for (size_t i = lo; i < hi; i++) {
        float v = a->x[i];
        a->y[i] = v < a->p ? a->p : (v > a->q ? a->q : v);
    }
}

static void affine_chunk(void *arg, int task, int thread) {
    (void)thread;
    const ew_args *a = arg;
    size_t lo = (size_t)task * MX_EW_CHUNK, hi = lo + MX_EW_CHUNK < a->n ? lo + MX_EW_CHUNK : a->n;
    for (size_t i = lo; i < hi; i++) a->y[i] = a->p * a->x[i] + a->q;
}

void mx_axpy_ref(const mx_ctx *c, float *y, const float *x, float s, size_t n) {
    ew_args a = {y, x, s, 0.0f, n};
    mx_par_for(c, chunks(n), axpy_chunk, &a);
}

void mx_clamp_ref(const mx_ctx *c, float *y, const float *x, float lo, float hi, size_t n) {
    ew_args a = {y, x, lo, hi, n};
    mx_par_for(c, chunks(n), clamp_chunk, &a);
}

void mx_affine_ref(const mx_ctx *c, float *y, const float *x, float s, float b, size_t n) {
    ew_args a = {y, x, s, b, n};
    mx_par_for(c, chunks(n), affine_chunk, &a);
}
