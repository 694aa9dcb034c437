/* Scalar reference of mx_attention. Per query: one pass for the row maximum, a second pass that
 * accumulates exp(s - max)·v straight into the output row; no Tq×Tk matrix, no temporaries. */
#include <math.h>

#include "kernels.h"

typedef struct {
    float *out;
    const float *q, *k, *v;
    int H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal;
    float scale;
} attention_args;

static double dot_ref(const float *a, const float *b, int n) {
    double s = 0;
    for (int i = 0; i < n; i++) s += (double)a[i] * b[i];
    return s;
}

static void attention_query(const attention_args *a, int b, int h, int i) {
    const float *qi = a->q + ((size_t)b * a->Tq + i) * a->q_stride + (size_t)h * a->D;
    float *oi = a->out + ((size_t)b * a->Tq + i) * a->out_stride + (size_t)h * a->D;
    const float *kb = a->k + (size_t)b * a->Tk * a->kv_stride + (size_t)h * a->D;
    const float *vb = a->v + (size_t)b * a->Tk * a->kv_stride + (size_t)h * a->D;
    int nk = a->causal && i + 1 < a->Tk ? i + 1 : a->Tk;
    double mx = -INFINITY;
    for (int j = 0; j < nk; j++) {
        double s = dot_ref(qi, kb + (size_t)j * a->kv_stride, a->D) * a->scale;
        mx = s > mx ? s : mx;
    }
    double acc[64], sum = 0;
    /* accumulate D values in chunks of 64 so the accumulator stays on the stack for any D */
    for (int d0 = 0; d0 < a->D; d0 += 64) {
        int nd = a->D - d0 < 64 ? a->D - d0 : 64;
        for (int d = 0; d < nd; d++) acc[d] = 0;
        sum = 0;
        for (int j = 0; j < nk; j++) {
            double p = exp(dot_ref(qi, kb + (size_t)j * a->kv_stride, a->D) * a->scale - mx);
            sum += p;
            const float *vj = vb + (size_t)j * a->kv_stride + d0;
            for (int d = 0; d < nd; d++) acc[d] += p * vj[d];
        }
        for (int d = 0; d < nd; d++) oi[d0 + d] = (float)(acc[d] / sum);
    }
}

/* One task = one (batch item, head, block of 16 queries). */
static void attention_task(void *arg, int task, int thread) {
    (void)thread;
    const attention_args *a = arg;
    int qblocks = (a->Tq + 15) / 16;
    int bh = task / qblocks, i0 = (task % qblocks) * 16;
    int i1 = i0 + 16 < a->Tq ? i0 + 16 : a->Tq;
    for (int i = i0; i < i1; i++) attention_query(a, bh / a->H, bh % a->H, i);
}

void mx_attention_ref(const mx_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                      int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal,
                      float scale) {
    attention_args a = {out, q, k, v, H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal, scale};
    mx_par_for(c, B * H * ((Tq + 15) / 16), attention_task, &a);
}
