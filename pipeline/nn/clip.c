/* CLIP text encoder, one function per stage, following transformers 4.39 modeling_clip.py
 * (CLIPTextEmbeddings, CLIPEncoderLayer, CLIPTextTransformer) with eager attention. */
#include "clip.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"

void mx_clip_config_sd15(mx_clip_config *cfg) {
    cfg->hidden_size = 768;
    cfg->intermediate_size = 3072;
    cfg->num_attention_heads = 12;
    cfg->num_hidden_layers = 12;
    cfg->max_position_embeddings = 77;
    cfg->vocab_size = 49408;
    cfg->eos_token_id = 2;
    cfg->layer_norm_eps = 1e-5f;
    cfg->hidden_act = MX_CLIP_ACT_QUICK_GELU;
}

/* Reads an integer member in [lo, hi] (absent: keeps *v). */
static int get_int(const mx_json *root, const char *key, int lo, int hi, int *v, const char *what, mx_status *st) {
    const mx_json *j = mx_json_get(root, key);
    if (!j) return 0;
    double d = mx_json_num(j);
    if (mx_json_kind(j) != MX_JSON_NUM || d != floor(d) || d < lo || d > hi)
        return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be an integer in [%d, %d]", what, key, lo, hi);
    *v = (int)d;
    return 0;
}

int mx_clip_config_parse(mx_clip_config *cfg, const char *json_text, size_t len, const char *what,
                         mx_status *st) {
    mx_json *root = mx_json_parse(json_text, len, what, st);
    if (!root) return -1;
    int rc = -1;
    mx_clip_config_sd15(cfg);
    if (mx_json_kind(root) != MX_JSON_OBJ) {
        mx_fail(st, MX_EINPUT, "%s: config is not a JSON object", what);
        goto done;
    }
    if (get_int(root, "hidden_size", 1, 1 << 16, &cfg->hidden_size, what, st) ||
        get_int(root, "intermediate_size", 1, 1 << 18, &cfg->intermediate_size, what, st) ||
        get_int(root, "num_attention_heads", 1, 1024, &cfg->num_attention_heads, what, st) ||
        get_int(root, "num_hidden_layers", 1, 256, &cfg->num_hidden_layers, what, st) ||
        get_int(root, "max_position_embeddings", 1, 1 << 16, &cfg->max_position_embeddings, what, st) ||
        get_int(root, "vocab_size", 1, 1 << 24, &cfg->vocab_size, what, st) ||
        get_int(root, "eos_token_id", 0, 1 << 24, &cfg->eos_token_id, what, st))
        goto done;
    cfg->layer_norm_eps = (float)mx_json_get_num(root, "layer_norm_eps", cfg->layer_norm_eps);
    const char *act = mx_json_get_str(root, "hidden_act", "quick_gelu");
    if (!strcmp(act, "quick_gelu")) {
        cfg->hidden_act = MX_CLIP_ACT_QUICK_GELU;
    } else if (!strcmp(act, "gelu")) {
        cfg->hidden_act = MX_CLIP_ACT_GELU;
    } else {
        mx_fail(st, MX_EINPUT, "%s: hidden_act \"%s\" is not supported (quick_gelu, gelu)", what, act);
        goto done;
    }
    if (cfg->hidden_size % cfg->num_attention_heads != 0) {
        mx_fail(st, MX_EINPUT, "%s: hidden_size %d is not divisible by num_attention_heads %d", what,
                cfg->hidden_size, cfg->num_attention_heads);
        goto done;
    }
    if (!(cfg->layer_norm_eps > 0)) {
        mx_fail(st, MX_EINPUT, "%s: layer_norm_eps must be positive", what);
        goto done;
    }
    rc = 0;
done:
    mx_json_free(root);
    return rc;
}

/* ---- parameters ---- */

static int bind_linear(mx_binder *b, const char *base, int64_t out, int64_t in, mx_wptr *w, mx_wptr *bias,
                       mx_status *st) {
    char name[256];
    snprintf(name, sizeof name, "%s.weight", base);
    if (mx_bind(b, w, st, name, 2, out, in)) return -1;
    snprintf(name, sizeof name, "%s.bias", base);
    return mx_bind(b, bias, st, name, 1, out);
}

static int bind_norm(mx_binder *b, const char *base, int64_t c, mx_wptr *w, mx_wptr *bias, mx_status *st) {
    char name[256];
    snprintf(name, sizeof name, "%s.weight", base);
    if (mx_bind(b, w, st, name, 1, c)) return -1;
    snprintf(name, sizeof name, "%s.bias", base);
    return mx_bind(b, bias, st, name, 1, c);
}

static int bind_layer(mx_binder *b, const mx_clip_config *cfg, int i, mx_clip_layer *l, mx_status *st) {
    char base[128], sub[192];
    int64_t C = cfg->hidden_size, I = cfg->intermediate_size;
    snprintf(base, sizeof base, "text_model.encoder.layers.%d", i);
#define SUB(s) (snprintf(sub, sizeof sub, "%s.%s", base, s), sub)
    if (bind_norm(b, SUB("layer_norm1"), C, &l->ln1_w, &l->ln1_b, st) ||
        bind_linear(b, SUB("self_attn.q_proj"), C, C, &l->q_w, &l->q_b, st) ||
        bind_linear(b, SUB("self_attn.k_proj"), C, C, &l->k_w, &l->k_b, st) ||
        bind_linear(b, SUB("self_attn.v_proj"), C, C, &l->v_w, &l->v_b, st) ||
        bind_linear(b, SUB("self_attn.out_proj"), C, C, &l->out_w, &l->out_b, st) ||
        bind_norm(b, SUB("layer_norm2"), C, &l->ln2_w, &l->ln2_b, st) ||
        bind_linear(b, SUB("mlp.fc1"), I, C, &l->fc1_w, &l->fc1_b, st) ||
        bind_linear(b, SUB("mlp.fc2"), C, I, &l->fc2_w, &l->fc2_b, st))
        return -1;
#undef SUB
    return 0;
}

int mx_clip_load(mx_clip *m, const mx_clip_config *cfg, mx_binder *b, mx_status *st) {
    memset(m, 0, sizeof *m);
    m->cfg = *cfg;
    int64_t C = cfg->hidden_size;
    m->layers = calloc((size_t)cfg->num_hidden_layers, sizeof *m->layers);
    if (!m->layers) return mx_fail(st, MX_ENOMEM, "clip: out of memory");
    if (mx_bind(b, &m->token_embedding, st, "text_model.embeddings.token_embedding.weight", 2,
                (int64_t)cfg->vocab_size, C) ||
        mx_bind(b, &m->position_embedding, st, "text_model.embeddings.position_embedding.weight", 2,
                (int64_t)cfg->max_position_embeddings, C))
        goto fail;
    for (int i = 0; i < cfg->num_hidden_layers; i++)
        if (bind_layer(b, cfg, i, &m->layers[i], st)) goto fail;
    if (bind_norm(b, "text_model.final_layer_norm", C, &m->final_ln_w, &m->final_ln_b, st)) goto fail;
    return 0;
fail:
    mx_clip_free(m);
    return mx_fail_prefix(st, "loading the CLIP text encoder: ");
}

void mx_clip_free(mx_clip *m) {
    free(m->layers);
    m->layers = NULL;
}

/* ---- forward ---- */

/* Activations of one forward pass, M = B*T rows. */
typedef struct clip_buffers {
    float *h, *q, *k, *v, *attn, *mlp;
} clip_buffers;

static int alloc_buffers(mx_arena *a, size_t M, const mx_clip_config *cfg, clip_buffers *bf, mx_status *st) {
    size_t MC = M * (size_t)cfg->hidden_size;
    float **bufs[] = {&bf->h, &bf->q, &bf->k, &bf->v, &bf->attn};
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++)
        if (!(*bufs[i] = mx_act_alloc(a, MC, st))) return -1;
    bf->mlp = mx_act_alloc(a, M * (size_t)cfg->intermediate_size, st);
    return bf->mlp ? 0 : -1;
}

/* x += out_proj(attention(LN1(x))) with a causal mask. */
static void attention_block(const mx_clip *m, const mx_clip_layer *l, const mx_ctx *c, float *x, int B, int T,
                            const clip_buffers *bf) {
    const mx_clip_config *cfg = &m->cfg;
    int C = cfg->hidden_size, H = cfg->num_attention_heads, D = C / H, M = B * T;
    mx_layer_norm(c, bf->h, x, M, C, l->ln1_w, l->ln1_b, cfg->layer_norm_eps);
    mx_linear(c, bf->q, bf->h, l->q_w, l->q_b, M, C, C);
    mx_linear(c, bf->k, bf->h, l->k_w, l->k_b, M, C, C);
    mx_linear(c, bf->v, bf->h, l->v_w, l->v_b, M, C, C);
    mx_attention(c, bf->attn, bf->q, bf->k, bf->v, B, H, T, T, D, C, C, C, 1, 1.0f / sqrtf((float)D));
    mx_linear(c, bf->h, bf->attn, l->out_w, l->out_b, M, C, C);
    mx_add(c, x, x, bf->h, (size_t)M * (size_t)C);
}

/* x += fc2(act(fc1(LN2(x)))). */
static void mlp_block(const mx_clip *m, const mx_clip_layer *l, const mx_ctx *c, float *x, int M,
                      const clip_buffers *bf) {
    const mx_clip_config *cfg = &m->cfg;
    int C = cfg->hidden_size, I = cfg->intermediate_size;
    mx_layer_norm(c, bf->h, x, M, C, l->ln2_w, l->ln2_b, cfg->layer_norm_eps);
    mx_linear(c, bf->mlp, bf->h, l->fc1_w, l->fc1_b, M, I, C);
    if (cfg->hidden_act == MX_CLIP_ACT_QUICK_GELU)
        mx_quick_gelu(c, bf->mlp, (size_t)M * (size_t)I);
    else
        mx_gelu(c, bf->mlp, (size_t)M * (size_t)I);
    mx_linear(c, bf->h, bf->mlp, l->fc2_w, l->fc2_b, M, C, I);
    mx_add(c, x, x, bf->h, (size_t)M * (size_t)C);
}

/* transformers 4.39: with the legacy eos_token_id == 2 the pooled token is argmax(ids) (the
 * highest id, which is <|endoftext|> in CLIP's vocabulary); otherwise the first position
 * whose id equals eos_token_id (position 0 when there is none, as torch's argmax of zeros). */
static int pooled_position(const mx_clip_config *cfg, const int32_t *ids, int T) {
    int best = 0;
    for (int t = 0; t < T; t++) {
        if (cfg->eos_token_id == 2) {
            if (ids[t] > ids[best]) best = t;
        } else if (ids[t] == cfg->eos_token_id) {
            return t;
        }
    }
    return best;
}

static int check_ids(const mx_clip_config *cfg, const int32_t *ids, int B, int T, mx_status *st) {
    if (B < 1 || T < 1 || T > cfg->max_position_embeddings)
        return mx_fail(st, MX_EUSAGE, "clip: %d sequences of %d tokens (at most %d positions)", B, T,
                       cfg->max_position_embeddings);
    for (int i = 0; i < B * T; i++)
        if (ids[i] < 0 || ids[i] >= cfg->vocab_size)
            return mx_fail(st, MX_EINPUT, "clip: token id %d at position %d outside the vocabulary of %d", ids[i], i,
                           cfg->vocab_size);
    return 0;
}

int mx_clip_forward(const mx_clip *m, const mx_ctx *c, mx_arena *arena, const int32_t *ids, int B, int T,
                    float *last_hidden, float *pooled, float **hidden_states, mx_status *st) {
    const mx_clip_config *cfg = &m->cfg;
    if (check_ids(cfg, ids, B, T, st)) return -1;
    int C = cfg->hidden_size, M = B * T;
    size_t MC = (size_t)M * (size_t)C, mark = mx_arena_mark(arena);
    clip_buffers bf;
    c = mx_run_ctx(c, arena);
    float *x = mx_act_alloc(arena, MC, st);
    if (!x || alloc_buffers(arena, (size_t)M, cfg, &bf, st)) return mx_fail_prefix(st, "clip forward: ");
    mx_embed_tokens(c, x, ids, B, T, C, m->token_embedding, m->position_embedding);
    if (hidden_states && hidden_states[0]) mx_copy(c, hidden_states[0], x, MC);
    for (int i = 0; i < cfg->num_hidden_layers; i++) {
        attention_block(m, &m->layers[i], c, x, B, T, &bf);
        mlp_block(m, &m->layers[i], c, x, M, &bf);
        if (hidden_states && hidden_states[i + 1]) mx_copy(c, hidden_states[i + 1], x, MC);
    }
    mx_layer_norm(c, last_hidden, x, M, C, m->final_ln_w, m->final_ln_b, cfg->layer_norm_eps);
    for (int b = 0; pooled && b < B; b++) {
        int t = pooled_position(cfg, ids + (size_t)b * T, T);
        mx_copy(c, pooled + (size_t)b * C, last_hidden + ((size_t)b * T + t) * C, (size_t)C);
    }
    mx_arena_reset(arena, mark);
    return 0;
}
