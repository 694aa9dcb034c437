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
    cfg->hidden_act = MX_TF_ACT_QUICK_GELU;
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
    if (mx_tf_json_int(root, "hidden_size", 1, 1 << 16, &cfg->hidden_size, what, st) ||
        mx_tf_json_int(root, "intermediate_size", 1, 1 << 18, &cfg->intermediate_size, what, st) ||
        mx_tf_json_int(root, "num_attention_heads", 1, 1024, &cfg->num_attention_heads, what, st) ||
        mx_tf_json_int(root, "num_hidden_layers", 1, 256, &cfg->num_hidden_layers, what, st) ||
        mx_tf_json_int(root, "max_position_embeddings", 1, 1 << 16, &cfg->max_position_embeddings, what, st) ||
        mx_tf_json_int(root, "vocab_size", 1, 1 << 24, &cfg->vocab_size, what, st) ||
        mx_tf_json_int(root, "eos_token_id", 0, 1 << 24, &cfg->eos_token_id, what, st))
        goto done;
    cfg->layer_norm_eps = (float)mx_json_get_num(root, "layer_norm_eps", cfg->layer_norm_eps);
    if (mx_tf_act_parse(mx_json_get_str(root, "hidden_act", "quick_gelu"), &cfg->hidden_act, what, st)) goto done;
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

static int bind_layer(mx_binder *b, const mx_tf_shape *s, int i, mx_tf_layer *l, mx_status *st) {
    char path[64];
    snprintf(path, sizeof path, "text_model.encoder.layers.%d", i);
    return mx_tf_layer_bind(b, path, s, l, st);
}

int mx_clip_load(mx_clip **out, const mx_clip_config *cfg, mx_binder *b, mx_status *st) {
    mx_clip *m = calloc(1, sizeof *m);
    *out = m;
    if (!m) return mx_fail(st, MX_ENOMEM, "clip: out of memory");
    m->cfg = *cfg;
    m->shape = (mx_tf_shape){.hidden = cfg->hidden_size,
                             .intermediate = cfg->intermediate_size,
                             .heads = cfg->num_attention_heads,
                             .eps = cfg->layer_norm_eps,
                             .act = cfg->hidden_act,
                             .causal = 1};
    int64_t C = cfg->hidden_size;
    m->layers = calloc((size_t)cfg->num_hidden_layers, sizeof *m->layers);
    if (!m->layers) return mx_fail(st, MX_ENOMEM, "clip: out of memory");
    if (mx_bind(b, &m->token_embedding, st, "text_model.embeddings.token_embedding.weight", 2,
                (int64_t)cfg->vocab_size, C) ||
        mx_bind(b, &m->position_embedding, st, "text_model.embeddings.position_embedding.weight", 2,
                (int64_t)cfg->max_position_embeddings, C))
        goto fail;
    for (int i = 0; i < cfg->num_hidden_layers; i++)
        if (bind_layer(b, &m->shape, i, &m->layers[i], st)) goto fail;
    if (mx_tf_norm_bind(b, "text_model.final_layer_norm", C, &m->final_ln_w, &m->final_ln_b, st)) goto fail;
    return 0;
fail:
    mx_clip_free(m);
    *out = NULL;
    return mx_fail_prefix(st, "loading the CLIP text encoder: ");
}

void mx_clip_free(mx_clip *m) {
    if (!m) return;
    free(m->layers);
    free(m);
}

/* ---- forward ---- */

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

/* The sizes, and the ids unless NULL. */
static int check_ids(const mx_clip_config *cfg, const int32_t *ids, int B, int T, mx_status *st) {
    if (B < 1 || T < 1 || T > cfg->max_position_embeddings)
        return mx_fail(st, MX_EUSAGE, "clip: %d sequences of %d tokens (at most %d positions)", B, T,
                       cfg->max_position_embeddings);
    for (int i = 0; ids && i < B * T; i++)
        if (ids[i] < 0 || ids[i] >= cfg->vocab_size)
            return mx_fail(st, MX_EINPUT, "clip: token id %d at position %d outside the vocabulary of %d", ids[i], i,
                           cfg->vocab_size);
    return 0;
}

/* What a forward pass takes of its arena: the residual stream x [B·T, C] and the layers' buffers. */
static int alloc_activations(const mx_clip *m, mx_arena *arena, int B, int T, float **x, mx_tf_buffers *bf,
                             mx_status *st) {
    size_t M = (size_t)B * T;
    *x = mx_act_alloc(arena, M * (size_t)m->cfg.hidden_size, st);
    return !*x || mx_tf_buffers_alloc(arena, M, &m->shape, bf, st) ? -1 : 0;
}

int mx_clip_arena_bytes(const mx_clip *m, int B, int T, size_t *bytes, mx_status *st) {
    mx_arena a;
    mx_tf_buffers bf;
    float *x;
    if (check_ids(&m->cfg, NULL, B, T, st)) return -1;
    mx_arena_measure(&a);
    if (alloc_activations(m, &a, B, T, &x, &bf, st)) return -1;
    *bytes = a.peak + 4 * MX_ARENA_ALIGN;
    return 0;
}

int mx_clip_forward(const mx_clip *m, const mx_ctx *c, mx_arena *arena, const int32_t *ids, int B, int T,
                    float *last_hidden, float *pooled, float **hidden_states, mx_status *st) {
    const mx_clip_config *cfg = &m->cfg;
    if (check_ids(cfg, ids, B, T, st)) return -1;
    int C = cfg->hidden_size, M = B * T;
    size_t MC = (size_t)M * (size_t)C, mark = mx_arena_mark(arena);
    mx_tf_buffers bf;
    c = mx_run_ctx(c, arena);
    float *x;
    if (alloc_activations(m, arena, B, T, &x, &bf, st)) return mx_fail_prefix(st, "clip forward: ");
    mx_embed_tokens(c, x, ids, B, T, C, m->token_embedding, m->position_embedding);
    if (hidden_states && hidden_states[0]) mx_copy(c, hidden_states[0], x, MC);
    for (int i = 0; i < cfg->num_hidden_layers; i++) {
        mx_tf_layer_forward(c, &m->shape, &m->layers[i], x, B, T, &bf);
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

/* ---- the registry's entry points (registry.h) ---- */

int mx_clip_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st) {
    mx_clip_config cfg;
    return mx_clip_config_parse(&cfg, text, len, what, st) ? -1 : mx_clip_load((mx_clip **)net, &cfg, b, st);
}

/* run-net clip: input_ids [B,T] -> last_hidden_state, pooler_output, hidden_states.{i} (slot
 * CLIP_HIDDEN + i, i = 0..num_hidden_layers). */
enum { CLIP_IDS, CLIP_LAST, CLIP_POOLED, CLIP_HIDDEN };
const mx_net_slot mx_clip_slots[] = {
    [CLIP_IDS] = {"input_ids", MX_SLOT_IN},
    [CLIP_LAST] = {"last_hidden_state", MX_SLOT_OUT},
    [CLIP_POOLED] = {"pooler_output", MX_SLOT_OUT},
    [CLIP_HIDDEN] = {NULL, 0},
};

int mx_clip_more_slots(const void *net, mx_net_slots *s, mx_status *st) {
    const mx_clip *m = net;
    for (int i = 0; i <= m->cfg.num_hidden_layers; i++) {
        char name[48];
        snprintf(name, sizeof name, "hidden_states.%d", i);
        if (mx_net_slots_add(s, name, MX_SLOT_OUT, st)) return -1;
    }
    return 0;
}

static int input_ids_shape(const mx_clip *m, mx_net_io *io, int64_t is[2], mx_status *st) {
    is[0] = is[1] = -1;
    if (io->shape(io, CLIP_IDS, 2, is, st)) return -1;
    if (is[1] > m->cfg.max_position_embeddings)
        return mx_fail(st, MX_EINPUT, "%s: input_ids has %lld tokens, the model takes at most %d", io->source,
                       (long long)is[1], m->cfg.max_position_embeddings);
    return 0;
}

int mx_clip_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st) {
    int64_t is[2];
    return input_ids_shape(net, io, is, st) ? -1 : mx_clip_arena_bytes(net, (int)is[0], (int)is[1], bytes, st);
}

int mx_clip_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st) {
    const mx_clip *m = net;
    int L = m->cfg.num_hidden_layers, C = m->cfg.hidden_size, rc = -1;
    int64_t is[2];
    const float *idf = input_ids_shape(m, io, is, st) ? NULL : io->host(io, CLIP_IDS, 2, is, st);
    if (!idf) return -1;
    int B = (int)is[0], T = (int)is[1];
    float **hs = calloc((size_t)L + 1, sizeof *hs), *last, *pooled;
    int32_t *ids = malloc((size_t)B * T * sizeof *ids);
    if (!hs || !ids) {
        mx_fail(st, MX_ENOMEM, "clip: out of memory");
        goto done;
    }
    for (size_t i = 0; i < (size_t)B * T; i++) ids[i] = (int32_t)idf[i];
    int64_t hshape[3] = {B, T, C}, pshape[2] = {B, C};
    if (!(last = io->output(io, CLIP_LAST, 3, hshape, st)) ||
        !(pooled = io->output(io, CLIP_POOLED, 2, pshape, st)))
        goto done;
    for (int i = 0; i <= L; i++)
        if (!(hs[i] = io->output(io, CLIP_HIDDEN + i, 3, hshape, st))) goto done;
    if (mx_clip_forward(m, c, a, ids, B, T, last, pooled, hs, st)) goto done;
    rc = 0;
done:
    free(ids);
    free(hs);
    return rc;
}
