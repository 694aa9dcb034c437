/* Layout ops (upsample, rectangle copy, concat, transposes, pad, copy, fill): plain loops, one
 * plane or batch item per task. They are shared by every ISA level. */
#include <string.h>

#include "kernels.h"

typedef struct {
    float *y;
    const float *x;
    int H, W;
} upsample_args;

static void upsample_plane(void *arg, int p, int thread) {
    (void)thread;
    const upsample_args *a = arg;
    const float *xp = a->x + (size_t)p * a->H * a->W;
    float *yp = a->y + (size_t)p * 4 * a->H * a->W;
    for (int i = 0; i < a->H; i++) {
        float *row = yp + (size_t)2 * i * 2 * a->W;
        for (int j = 0; j < a->W; j++) row[2 * j] = row[2 * j + 1] = xp[(size_t)i * a->W + j];
        memcpy(row + 2 * a->W, row, (size_t)2 * a->W * sizeof *row);
    }
}

void mx_upsample_nearest2x_ref(const mx_ctx *c, float *y, const float *x, int BC, int H, int W) {
    upsample_args a = {y, x, H, W};
    mx_par_for(c, BC, upsample_plane, &a);
}

void mx_copy_rect_ref(const mx_ctx *c, float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx,
                      int sy0, int sx0, int BC, int h, int w) {
    (void)c;
    for (int p = 0; p < BC; p++)
        for (int r = 0; r < h; r++)
            memcpy(y + ((size_t)p * Hy + y0 + r) * Wy + x0, x + ((size_t)p * Hx + sy0 + r) * Wx + sx0,
                   (size_t)w * sizeof *y);
}

void mx_concat_channels_ref(const mx_ctx *c, float *y, const float *a, int Ca, const float *b, int Cb, int B,
                            int HW) {
    (void)c;
    for (int i = 0; i < B; i++) {
        float *yb = y + (size_t)i * (Ca + Cb) * HW;
        memcpy(yb, a + (size_t)i * Ca * HW, (size_t)Ca * HW * sizeof *y);
        memcpy(yb + (size_t)Ca * HW, b + (size_t)i * Cb * HW, (size_t)Cb * HW * sizeof *y);
    }
}

typedef struct {
    float *y;
    const float *x;
    int C, HW, to_hwc;
} transpose_args;

#define TRANSPOSE_TILE 32
#define TRANSPOSE_ROWS_PER_TASK 128

static int transpose_tasks_per_item(const transpose_args *a) {
    int rows = a->to_hwc ? a->C : a->HW;
    return (rows + TRANSPOSE_ROWS_PER_TASK - 1) / TRANSPOSE_ROWS_PER_TASK;
}

/* One task = TRANSPOSE_ROWS_PER_TASK source rows of one batch item, in 32×32 tiles that keep
 * both sides in cache. */
static void transpose_task(void *arg, int task, int thread) {
    (void)thread;
    const transpose_args *a = arg;
    int per = transpose_tasks_per_item(a), b = task / per;
    int rows = a->to_hwc ? a->C : a->HW, cols = a->to_hwc ? a->HW : a->C;
    int rbeg = task % per * TRANSPOSE_ROWS_PER_TASK;
    int rend = rbeg + TRANSPOSE_ROWS_PER_TASK < rows ? rbeg + TRANSPOSE_ROWS_PER_TASK : rows;
    const float *x = a->x + (size_t)b * a->C * a->HW;
    float *y = a->y + (size_t)b * a->C * a->HW;
    for (int r0 = rbeg; r0 < rend; r0 += TRANSPOSE_TILE)
        for (int c0 = 0; c0 < cols; c0 += TRANSPOSE_TILE)
            for (int r = r0; r < rend && r < r0 + TRANSPOSE_TILE; r++)
                for (int cc = c0; cc < cols && cc < c0 + TRANSPOSE_TILE; cc++)
                    y[(size_t)cc * rows + r] = x[(size_t)r * cols + cc];
}

void mx_transpose_chw_hwc_ref(const mx_ctx *c, float *y, const float *x, int B, int C, int HW) {
    transpose_args a = {y, x, C, HW, 1};
    mx_par_for(c, B * transpose_tasks_per_item(&a), transpose_task, &a);
}

void mx_transpose_hwc_chw_ref(const mx_ctx *c, float *y, const float *x, int B, int C, int HW) {
    transpose_args a = {y, x, C, HW, 0};
    mx_par_for(c, B * transpose_tasks_per_item(&a), transpose_task, &a);
}

typedef struct {
    float *y;
    const float *x;
    int H, W, top, bottom, left, right;
} pad_args;

static void pad_plane(void *arg, int p, int thread) {
    (void)thread;
    const pad_args *a = arg;
    int Wp = a->W + a->left + a->right, Hp = a->H + a->top + a->bottom;
    const float *xp = a->x + (size_t)p * a->H * a->W;
    float *yp = a->y + (size_t)p * Hp * Wp;
    memset(yp, 0, (size_t)a->top * Wp * sizeof *yp);
    for (int i = 0; i < a->H; i++) {
        float *row = yp + (size_t)(a->top + i) * Wp;
        memset(row, 0, (size_t)a->left * sizeof *row);
        memcpy(row + a->left, xp + (size_t)i * a->W, (size_t)a->W * sizeof *row);
        memset(row + a->left + a->W, 0, (size_t)a->right * sizeof *row);
    }
    memset(yp + (size_t)(a->top + a->H) * Wp, 0, (size_t)a->bottom * Wp * sizeof *yp);
}

void mx_pad2d_ref(const mx_ctx *c, float *y, const float *x, int BC, int H, int W, int top, int bottom, int left,
                  int right) {
    pad_args a = {y, x, H, W, top, bottom, left, right};
    mx_par_for(c, BC, pad_plane, &a);
}

void mx_copy_ref(const mx_ctx *c, float *y, const float *x, size_t n) {
    (void)c;
    memcpy(y, x, n * sizeof *y);
}

void mx_fill_ref(const mx_ctx *c, float *y, float v, size_t n) {
    (void)c;
    for (size_t i = 0; i < n; i++) y[i] = v;
}
