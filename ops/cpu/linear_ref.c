/* Scalar reference of mx_linear: y = x · w^T + bias, accumulated in double (the test oracle). */
#include "kernels.h"

typedef struct {
    float *y;
    const float *x;
    mx_wptr w, bias;
    int M, N, K;
} linear_args;

/* One task = one output row. */
static void linear_row(void *arg, int m, int thread) {
    (void)thread;
    const linear_args *a = arg;
    const float *xr = a->x + (size_t)m * a->K;
    float *yr = a->y + (size_t)m * a->N;
    for (int n = 0; n < a->N; n++) {
        double acc = 0;
        size_t wrow = (size_t)n * a->K;
        for (int k = 0; k < a->K; k++) acc += (double)xr[k] * mx_w_get(a->w, wrow + k);
        if (a->bias.data) acc += mx_w_get(a->bias, n);
        yr[n] = (float)acc;
    }
}

void mx_linear_ref(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    linear_args a = {y, x, w, bias, M, N, K};
    mx_par_for(c, M, linear_row, &a);
}
