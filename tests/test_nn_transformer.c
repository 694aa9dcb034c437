/* The CLIP encoder layer (pipeline/nn/transformer.h) against a plain-C reference of
 * transformers' CLIPEncoderLayer, with the causal mask (the text encoder) and without it (a vision
 * tower): two layers bound under "vision_model.encoder.layers.{0,1}" by the golden-v1 rule,
 * awkward sizes (T = 7, 3 heads of 8). The two masks must give different results, so a layer
 * that ignored the flag fails one of the comparisons. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/transformer.h"
#include "../weights/golden_rule.h"
#include "nn_golden.h"

enum { B = 2, T = 7, C = 24, HEADS = 3, I = 40, LAYERS = 2, SEED = 5 };

/* The golden-v1 values of parameter `name` of n floats (1-d or 2-d by `rows`). */
static float *param(const char *path, const char *name, int64_t rows, int64_t cols) {
    char full[160];
    snprintf(full, sizeof full, "%s.%s", path, name);
    int64_t shape[2] = {rows, cols};
    float *x = malloc((size_t)(rows * (cols ? cols : 1)) * sizeof *x);
    mx_golden_v1_fill(full, cols ? 2 : 1, cols ? shape : &shape[0], SEED, x);
    return x;
}

static void ref_layer_norm(float *y, const float *x, const char *path, const char *name, float eps) {
    char w[64], b[64];
    snprintf(w, sizeof w, "%s.weight", name);
    snprintf(b, sizeof b, "%s.bias", name);
    float *g = param(path, w, C, 0), *be = param(path, b, C, 0);
    for (int m = 0; m < B * T; m++) {
        double mean = 0, var = 0;
        for (int i = 0; i < C; i++) mean += x[m * C + i];
        mean /= C;
        for (int i = 0; i < C; i++) var += (x[m * C + i] - mean) * (x[m * C + i] - mean);
        var /= C;
        for (int i = 0; i < C; i++) y[m * C + i] = (float)((x[m * C + i] - mean) / sqrt(var + eps)) * g[i] + be[i];
    }
    free(g);
    free(be);
}

/* y[M, out] = x[M, in] · W^T + b */
static void ref_linear(float *y, const float *x, const char *path, const char *name, int out, int in) {
    char w[64], b[64];
    snprintf(w, sizeof w, "%s.weight", name);
    snprintf(b, sizeof b, "%s.bias", name);
    float *W = param(path, w, out, in), *bias = param(path, b, out, 0);
    for (int m = 0; m < B * T; m++)
        for (int o = 0; o < out; o++) {
            double s = bias[o];
            for (int i = 0; i < in; i++) s += (double)x[m * in + i] * W[o * in + i];
            y[m * out + o] = (float)s;
        }
    free(W);
    free(bias);
}

/* Softmax attention per head, query t over keys 0..T-1 (0..t when causal). */
static void ref_attention(float *out, const float *q, const float *k, const float *v, int causal) {
    int D = C / HEADS;
    for (int b = 0; b < B; b++)
        for (int h = 0; h < HEADS; h++)
            for (int t = 0; t < T; t++) {
                double s[T], mx = -1e30, sum = 0;
                int n = causal ? t + 1 : T;
                for (int j = 0; j < n; j++) {
                    s[j] = 0;
                    for (int d = 0; d < D; d++)
                        s[j] += (double)q[(b * T + t) * C + h * D + d] * k[(b * T + j) * C + h * D + d];
                    s[j] /= sqrt((double)D);
                    if (s[j] > mx) mx = s[j];
                }
                for (int j = 0; j < n; j++) sum += s[j] = exp(s[j] - mx);
                for (int d = 0; d < D; d++) {
                    double o = 0;
                    for (int j = 0; j < n; j++) o += s[j] / sum * v[(b * T + j) * C + h * D + d];
                    out[(b * T + t) * C + h * D + d] = (float)o;
                }
            }
}

static void ref_layer(float *x, const char *path, int causal, float eps) {
    float h[B * T * C], q[B * T * C], k[B * T * C], v[B * T * C], a[B * T * C], mlp[B * T * I];
    ref_layer_norm(h, x, path, "layer_norm1", eps);
    ref_linear(q, h, path, "self_attn.q_proj", C, C);
    ref_linear(k, h, path, "self_attn.k_proj", C, C);
    ref_linear(v, h, path, "self_attn.v_proj", C, C);
    ref_attention(a, q, k, v, causal);
    ref_linear(h, a, path, "self_attn.out_proj", C, C);
    for (int i = 0; i < B * T * C; i++) x[i] += h[i];
    ref_layer_norm(h, x, path, "layer_norm2", eps);
    ref_linear(mlp, h, path, "mlp.fc1", I, C);
    for (int i = 0; i < B * T * I; i++) mlp[i] = mlp[i] / (1.0f + expf(-1.702f * mlp[i])); /* quick-GELU */
    ref_linear(h, mlp, path, "mlp.fc2", C, I);
    for (int i = 0; i < B * T * C; i++) x[i] += h[i];
}

/* The layers under test on c: x0 through LAYERS layers with the given mask, into got. */
static int run_layers(const mx_ctx *c, const mx_tf_shape *s, const float *x0, float *got) {
    mx_status st;
    golden_weights b;
    mx_tf_layer l[LAYERS];
    char path[64];
    if (golden_weights_rule(&b, c, SEED, MX_F32, &st)) return fprintf(stderr, "%s\n", st.msg), -1;
    int rc = 0;
    for (int i = 0; !rc && i < LAYERS; i++) {
        snprintf(path, sizeof path, "vision_model.encoder.layers.%d", i);
        rc = mx_tf_layer_bind(&b.dev, path, s, &l[i], &st);
    }
    mx_arena a;
    mx_tf_buffers bf;
    golden_arena(c, &a, (size_t)8 << 20);
    float *x = golden_dev(c, x0, B * T * C);
    const mx_ctx *rc_ctx = mx_run_ctx(c, &a);
    if (!rc && !mx_tf_buffers_alloc(&a, B * T, s, &bf, &st)) {
        for (int i = 0; i < LAYERS; i++) mx_tf_layer_forward(rc_ctx, s, &l[i], x, B, T, &bf);
    } else {
        rc = -1;
        fprintf(stderr, "%s\n", st.msg);
    }
    if (golden_fetch(c, got, x, B * T * C)) rc = -1;
    mx_arena_destroy(&a);
    golden_weights_close(&b);
    return rc;
}

int main(void) {
    mx_ctx c;
    if (golden_ctx(&c)) return 1;
    float x0[B * T * C], want[2][B * T * C], got[B * T * C];
    mx_fill_random(x0, B * T * C, 11, -1.0f, 1.0f);
    for (int causal = 0; causal < 2; causal++) {
        mx_tf_shape s = {.hidden = C, .intermediate = I, .heads = HEADS, .eps = 1e-5f, .act = MX_TF_ACT_QUICK_GELU,
                         .causal = causal};
        memcpy(want[causal], x0, sizeof x0);
        for (int i = 0; i < LAYERS; i++) {
            char path[64];
            snprintf(path, sizeof path, "vision_model.encoder.layers.%d", i);
            ref_layer(want[causal], path, causal, s.eps);
        }
        CHECK(run_layers(&c, &s, x0, got) == 0);
        mx_check_close(causal ? "encoder layers, causal" : "encoder layers, no mask", got, want[causal], B * T * C, 1e-4);
    }
    double apart = mx_rel_l2(want[0], want[1], B * T * C);
    printf("causal vs no mask: rel_l2=%.3e (must differ)\n", apart);
    CHECK(apart > 1e-2);
    mx_ctx_destroy(&c);
    return mx_test_finish("test_nn_transformer");
}
