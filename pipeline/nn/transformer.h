/* The pre-norm transformer encoder layer of CLIP (transformers' CLIPEncoderLayer):
 *   x += out_proj(attention(LN1(x)))      causal or not
 *   x += fc2(act(fc1(LN2(x))))
 * The text encoder (clip.c) runs it with the causal mask, a vision tower without. Parameters are
 * bound by their names under a layer's path ("text_model.encoder.layers.3"). */
#ifndef MX_NN_TRANSFORMER_H
#define MX_NN_TRANSFORMER_H

#include "../../ops/ops.h"
#include "../../runtime/status.h"
#include "params.h"

typedef enum { MX_TF_ACT_QUICK_GELU = 0, MX_TF_ACT_GELU = 1 } mx_tf_act;

/* The sizes and options every layer of one encoder shares. */
typedef struct mx_tf_shape {
    int hidden, intermediate, heads;
    float eps;      /* LayerNorm epsilon */
    mx_tf_act act;  /* of the MLP */
    int causal;     /* 1: token i attends to tokens <= i (text); 0: to all (vision) */
} mx_tf_shape;

typedef struct mx_tf_layer {
    mx_wptr ln1_w, ln1_b;
    mx_wptr q_w, q_b, k_w, k_b, v_w, v_b, out_w, out_b;
    mx_wptr ln2_w, ln2_b;
    mx_wptr fc1_w, fc1_b, fc2_w, fc2_b;
} mx_tf_layer;

/* Activations of layers run on M = B*T rows, from one arena (mx_tf_buffers_alloc). */
typedef struct mx_tf_buffers {
    float *h, *q, *k, *v, *attn, *mlp;
} mx_tf_buffers;

/* Config helpers of the CLIP towers (text and vision): an integer member `key` of a JSON object
 * in [lo, hi] (absent: keeps *v), and the activation named by "hidden_act" (quick_gelu, gelu). */
struct mx_json;
int mx_tf_json_int(const struct mx_json *root, const char *key, int lo, int hi, int *v, const char *what,
                   mx_status *st);
int mx_tf_act_parse(const char *name, mx_tf_act *act, const char *what, mx_status *st);

/* Binds a LayerNorm's weight and bias under `path`. */
int mx_tf_norm_bind(mx_binder *b, const char *path, int64_t c, mx_wptr *w, mx_wptr *bias, mx_status *st);
/* Binds the layer under `path` (layer_norm1, self_attn.{q,k,v,out}_proj, layer_norm2, mlp.fc{1,2}). */
int mx_tf_layer_bind(mx_binder *b, const char *path, const mx_tf_shape *s, mx_tf_layer *l, mx_status *st);
int mx_tf_buffers_alloc(mx_arena *a, size_t M, const mx_tf_shape *s, mx_tf_buffers *bf, mx_status *st);
/* x [B, T, hidden] through one layer, in place. */
void mx_tf_layer_forward(const mx_ctx *c, const mx_tf_shape *s, const mx_tf_layer *l, float *x, int B, int T,
                         const mx_tf_buffers *bf);

#endif
