/* Scalar references of group norm and layer norm (statistics in double). */
#include <math.h>

#include "kernels.h"

typedef struct {
    float *y;
    const float *x;
    int C, HW, groups, fuse_silu;
    mx_wptr gamma, beta;
    float eps;
} group_norm_args;

static float silu_ref(float v) { return (float)((double)v / (1.0 + exp(-(double)v))); }

/* One task = one (batch item, group): biased variance over C/groups channels × HW. */
static void group_norm_group(void *arg, int task, int thread) {
    (void)thread;
    const group_norm_args *a = arg;
    int cpg = a->C / a->groups;
    int b = task / a->groups, g = task % a->groups;
    size_t off = ((size_t)b * a->C + (size_t)g * cpg) * a->HW, n = (size_t)cpg * a->HW;
    double sum = 0, sq = 0;
    for (size_t i = 0; i < n; i++) sum += a->x[off + i];
    double mean = sum / (double)n;
    for (size_t i = 0; i < n; i++) {
        double d = a->x[off + i] - mean;
        sq += d * d;
    }
    double inv = 1.0 / sqrt(sq / (double)n + a->eps);
    for (int cc = 0; cc < cpg; cc++) {
        int ch = g * cpg + cc;
        double ga = a->gamma.data ? mx_w_get(a->gamma, ch) : 1.0;
        double be = a->beta.data ? mx_w_get(a->beta, ch) : 0.0;
        for (int p = 0; p < a->HW; p++) {
            size_t i = off + (size_t)cc * a->HW + p;
            float v = (float)((a->x[i] - mean) * inv * ga + be);
            a->y[i] = a->fuse_silu ? silu_ref(v) : v;
        }
    }
}

void mx_group_norm_ref(const mx_ctx *c, float *y, const float *x, int B, int C, int HW, int groups,
                       mx_wptr gamma, mx_wptr beta, float eps, int fuse_silu) {
    group_norm_args a = {y, x, C, HW, groups, fuse_silu, gamma, beta, eps};
    mx_par_for(c, B * groups, group_norm_group, &a);
}

typedef struct {
    float *y;
    const float *x;
    int C;
    mx_wptr gamma, beta;
    float eps;
} layer_norm_args;

static void layer_norm_row(void *arg, int m, int thread) {
    (void)thread;
    const layer_norm_args *a = arg;
    const float *xr = a->x + (size_t)m * a->C;
    float *yr = a->y + (size_t)m * a->C;
    double sum = 0, sq = 0;
    for (int i = 0; i < a->C; i++) sum += xr[i];
    double mean = sum / a->C;
    for (int i = 0; i < a->C; i++) sq += (xr[i] - mean) * (xr[i] - mean);
    double inv = 1.0 / sqrt(sq / a->C + a->eps);
    for (int i = 0; i < a->C; i++) {
        double ga = a->gamma.data ? mx_w_get(a->gamma, i) : 1.0;
        double be = a->beta.data ? mx_w_get(a->beta, i) : 0.0;
        yr[i] = (float)((xr[i] - mean) * inv * ga + be);
    }
}

void mx_layer_norm_ref(const mx_ctx *c, float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta,
                       float eps) {
    layer_norm_args a = {y, x, C, gamma, beta, eps};
    mx_par_for(c, M, layer_norm_row, &a);
}
