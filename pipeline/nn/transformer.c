/* The CLIP encoder layer (transformer.h), transformers 4.39 modeling_clip.py CLIPEncoderLayer with
 * eager attention. */
#include "transformer.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../runtime/json.h"

int mx_tf_json_int(const mx_json *root, const char *key, int lo, int hi, int *v, const char *what, mx_status *st) {
    const mx_json *j = mx_json_get(root, key);
    if (!j) return 0;
    double d = mx_json_num(j);
    if (mx_json_kind(j) != MX_JSON_NUM || d != floor(d) || d < lo || d > hi)
        return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be an integer in [%d, %d]", what, key, lo, hi);
    *v = (int)d;
    return 0;
}

int mx_tf_act_parse(const char *name, mx_tf_act *act, const char *what, mx_status *st) {
    if (!strcmp(name, "quick_gelu"))
        *act = MX_TF_ACT_QUICK_GELU;
    else if (!strcmp(name, "gelu"))
        *act = MX_TF_ACT_GELU;
    else
        return mx_fail(st, MX_EINPUT, "%s: hidden_act \"%s\" is not supported (quick_gelu, gelu)", what, name);
    return 0;
}

static int bind_linear(mx_binder *b, const char *base, int64_t out, int64_t in, mx_wptr *w, mx_wptr *bias,
                       mx_status *st) {
    char name[256];
    snprintf(name, sizeof name, "%s.weight", base);
    if (mx_bind(b, w, st, name, 2, out, in)) return -1;
    snprintf(name, sizeof name, "%s.bias", base);
    return mx_bind(b, bias, st, name, 1, out);
}

int mx_tf_norm_bind(mx_binder *b, const char *base, int64_t c, mx_wptr *w, mx_wptr *bias, mx_status *st) {
    char name[256];
    snprintf(name, sizeof name, "%s.weight", base);
    if (mx_bind(b, w, st, name, 1, c)) return -1;
    snprintf(name, sizeof name, "%s.bias", base);
    return mx_bind(b, bias, st, name, 1, c);
}

int mx_tf_layer_bind(mx_binder *b, const char *path, const mx_tf_shape *s, mx_tf_layer *l, mx_status *st) {
    char sub[256];
    int64_t C = s->hidden, I = s->intermediate;
#define SUB(x) (snprintf(sub, sizeof sub, "%s.%s", path, x), sub)
    if (mx_tf_norm_bind(b, SUB("layer_norm1"), C, &l->ln1_w, &l->ln1_b, st) ||
        bind_linear(b, SUB("self_attn.q_proj"), C, C, &l->q_w, &l->q_b, st) ||
        bind_linear(b, SUB("self_attn.k_proj"), C, C, &l->k_w, &l->k_b, st) ||
        bind_linear(b, SUB("self_attn.v_proj"), C, C, &l->v_w, &l->v_b, st) ||
        bind_linear(b, SUB("self_attn.out_proj"), C, C, &l->out_w, &l->out_b, st) ||
        mx_tf_norm_bind(b, SUB("layer_norm2"), C, &l->ln2_w, &l->ln2_b, st) ||
        bind_linear(b, SUB("mlp.fc1"), I, C, &l->fc1_w, &l->fc1_b, st) ||
        bind_linear(b, SUB("mlp.fc2"), C, I, &l->fc2_w, &l->fc2_b, st))
        return -1;
#undef SUB
    return 0;
}

int mx_tf_buffers_alloc(mx_arena *a, size_t M, const mx_tf_shape *s, mx_tf_buffers *bf, mx_status *st) {
    size_t MC = M * (size_t)s->hidden;
    float **bufs[] = {&bf->h, &bf->q, &bf->k, &bf->v, &bf->attn};
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++)
        if (!(*bufs[i] = mx_act_alloc(a, MC, st))) return -1;
    bf->mlp = mx_act_alloc(a, M * (size_t)s->intermediate, st);
    return bf->mlp ? 0 : -1;
}

/* x += out_proj(attention(LN1(x))), with the causal mask when s->causal. */
static void attention_block(const mx_ctx *c, const mx_tf_shape *s, const mx_tf_layer *l, float *x, int B, int T,
                            const mx_tf_buffers *bf) {
    int C = s->hidden, H = s->heads, D = C / H, M = B * T;
    mx_layer_norm(c, bf->h, x, M, C, l->ln1_w, l->ln1_b, s->eps);
    mx_linear(c, bf->q, bf->h, l->q_w, l->q_b, M, C, C);
    mx_linear(c, bf->k, bf->h, l->k_w, l->k_b, M, C, C);
    mx_linear(c, bf->v, bf->h, l->v_w, l->v_b, M, C, C);
    mx_attention(c, bf->attn, bf->q, bf->k, bf->v, B, H, T, T, D, C, C, C, s->causal, 1.0f / sqrtf((float)D));
    mx_linear(c, bf->h, bf->attn, l->out_w, l->out_b, M, C, C);
    mx_add(c, x, x, bf->h, (size_t)M * (size_t)C);
}

/* x += fc2(act(fc1(LN2(x)))). */
static void mlp_block(const mx_ctx *c, const mx_tf_shape *s, const mx_tf_layer *l, float *x, int M,
                      const mx_tf_buffers *bf) {
    int C = s->hidden, I = s->intermediate;
    mx_layer_norm(c, bf->h, x, M, C, l->ln2_w, l->ln2_b, s->eps);
    mx_linear(c, bf->mlp, bf->h, l->fc1_w, l->fc1_b, M, I, C);
    if (s->act == MX_TF_ACT_QUICK_GELU)
        mx_quick_gelu(c, bf->mlp, (size_t)M * (size_t)I);
    else
        mx_gelu(c, bf->mlp, (size_t)M * (size_t)I);
    mx_linear(c, bf->h, bf->mlp, l->fc2_w, l->fc2_b, M, C, I);
    mx_add(c, x, x, bf->h, (size_t)M * (size_t)C);
}

void mx_tf_layer_forward(const mx_ctx *c, const mx_tf_shape *s, const mx_tf_layer *l, float *x, int B, int T,
                         const mx_tf_buffers *bf) {
    attention_block(c, s, l, x, B, T, bf);
    mlp_block(c, s, l, x, B * T, bf);
}
