/* CLIP text encoder (transformers 4.39 CLIPTextModel): token + position embeddings, pre-LN
 * transformer layers with a causal mask, quick-GELU (or GELU) MLP, final layer norm, and the
 * pooled output at the end-of-text token. SD1.5 uses last_hidden_state [B, 77, 768].
 *
 * Parameters are bound by their transformers names ("text_model.embeddings.token_embedding.weight",
 * "text_model.encoder.layers.{i}.self_attn.q_proj.weight", ...) through an mx_binder; in a
 * matex weight file the binder's prefix is "text_encoder." and the config is the metadata
 * "text_encoder.config". */
#ifndef MX_CLIP_H
#define MX_CLIP_H

#include <stdint.h>

#include "../../ops/ops.h"
#include "../../runtime/status.h"
#include "net_io.h"
#include "params.h"
#include "transformer.h"

typedef struct mx_clip_config {
    int hidden_size;             /* 768 for SD1.5 */
    int intermediate_size;       /* 3072 */
    int num_attention_heads;     /* 12 */
    int num_hidden_layers;       /* 12 */
    int max_position_embeddings; /* 77 */
    int vocab_size;              /* 49408 */
    int eos_token_id;            /* 2 in the SD1.5 config: pooling then uses argmax(ids), as transformers */
    float layer_norm_eps;        /* 1e-5 */
    mx_tf_act hidden_act;        /* "quick_gelu" or "gelu" */
} mx_clip_config;

/* The SD1.5 text encoder (CLIP ViT-L/14) configuration. */
void mx_clip_config_sd15(mx_clip_config *cfg);
/* Parses a transformers config.json text; missing keys take the SD1.5 values; sizes are
 * validated (positive, hidden divisible by heads). `what` names the source in errors. */
int mx_clip_config_parse(mx_clip_config *cfg, const char *json_text, size_t len, const char *what,
                         mx_status *st);

typedef struct mx_clip {
    mx_clip_config cfg;
    mx_wptr token_embedding;    /* [vocab, C] */
    mx_wptr position_embedding; /* [max_pos, C] */
    mx_wptr final_ln_w, final_ln_b;
    mx_tf_shape shape;     /* of every encoder layer: causal */
    mx_tf_layer *layers;   /* num_hidden_layers, malloc'ed */
} mx_clip;

/* Binds every parameter through b (or only enumerates them when b->enumerating) into a new *out
 * (NULL after a failure); mx_clip_free(NULL) does nothing. */
int mx_clip_load(mx_clip **out, const mx_clip_config *cfg, mx_binder *b, mx_status *st);
void mx_clip_free(mx_clip *m);
/* Arena bytes of mx_clip_forward on ids [B, T]. */
int mx_clip_arena_bytes(const mx_clip *m, int B, int T, size_t *bytes, mx_status *st);

/* Runs the encoder on ids [B, T] (T <= max_position_embeddings; ids are checked against
 * vocab_size). Outputs (caller-owned, any may be NULL except last_hidden):
 *   last_hidden   [B, T, C]  final layer norm of the last layer
 *   pooled        [B, C]     last_hidden at the end-of-text token (transformers 4.39 rule)
 *   hidden_states num_hidden_layers + 1 pointers, each [B, T, C] (0 = embeddings, i = after
 *                 layer i, before the final layer norm); a NULL entry is skipped.
 * Outputs are backend memory of c (ids stay on the host). Temporaries come from `arena`; when
 * the arena is measuring, only allocations are made and nothing is computed (the dry run that
 * sizes the arena). */
int mx_clip_forward(const mx_clip *m, const mx_ctx *c, mx_arena *arena, const int32_t *ids, int B, int T,
                    float *last_hidden, float *pooled, float **hidden_states, mx_status *st);

/* The registry's entry points (registry.h): config parse + load, arena bytes and run on a run-net io. */
int mx_clip_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st);
int mx_clip_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_clip_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
/* Its slots (registry.h): the static table, and hidden_states.{i} after it. */
extern const mx_net_slot mx_clip_slots[];
int mx_clip_more_slots(const void *net, mx_net_slots *s, mx_status *st);

#endif
