/* CLIP vision tower with projection (transformers 4.39 CLIPVisionModelWithProjection): the image
 * encoder of the IP-Adapter (issue 26). The published SD1.5 IP-Adapter uses ViT-H/14 (hidden
 * 1280, 32 layers, 16 heads, patch 14, 224² images, projection 1024, gelu); every size comes from
 * the config.
 *
 *   patches   conv patch×patch, stride patch, no bias: pixel_values [B,3,S,S] -> [B, G², hidden]
 *   tokens    [class_embedding; patches] + position_embedding       [B, 1 + G², hidden]
 *   pre_layrnorm (sic, transformers' name), the CLIP encoder layers without the causal mask
 *   (transformer.h) -> last_hidden_state (no final norm)
 *   post_layernorm of the class token, visual_projection (no bias) -> image_embeds [B, proj]
 *
 * Parameters are bound by their transformers names ("vision_model.embeddings.class_embedding",
 * "vision_model.encoder.layers.{i}...", "visual_projection.weight"); in a matex weight file the
 * prefix is "image_encoder." and the config the metadata "image_encoder.config". The forward pass
 * calls ops only; under a bf16 context it follows the context, as the text encoder does. */
#ifndef MX_CLIP_VISION_H
#define MX_CLIP_VISION_H

#include "../../ops/ops.h"
#include "../../runtime/status.h"
#include "net_io.h"
#include "params.h"
#include "transformer.h"

typedef struct mx_clip_vision_config {
    int hidden_size;       /* 1280 for ViT-H/14 */
    int intermediate_size; /* 5120 */
    int num_attention_heads;
    int num_hidden_layers;
    int num_channels;      /* 3 */
    int image_size;        /* 224 */
    int patch_size;        /* 14 */
    int projection_dim;    /* 1024 */
    float layer_norm_eps;
    mx_tf_act hidden_act;  /* "gelu" (ViT-H) or "quick_gelu" (OpenAI's ViT-L) */
} mx_clip_vision_config;

/* Parses a transformers config.json text (a CLIPVisionConfig, or a CLIPConfig's "vision_config");
 * missing keys take transformers' CLIPVisionConfig defaults (ViT-B/32 sizes); sizes are
 * validated (positive, hidden divisible by heads, image a multiple of the patch). */
int mx_clip_vision_config_parse(mx_clip_vision_config *cfg, const char *json_text, size_t len, const char *what,
                                mx_status *st);
/* Tokens per image: 1 + (image_size / patch_size)². */
int mx_clip_vision_tokens(const mx_clip_vision_config *cfg);

typedef struct mx_clip_vision {
    mx_clip_vision_config cfg;
    mx_wptr class_embedding;    /* [hidden] */
    mx_wptr patch_w;            /* [hidden, channels, patch, patch] */
    mx_wptr position_embedding; /* [tokens, hidden] */
    mx_wptr pre_ln_w, pre_ln_b, post_ln_w, post_ln_b;
    mx_wptr projection;         /* [projection_dim, hidden] */
    mx_tf_shape shape;          /* of every encoder layer: not causal */
    mx_tf_layer *layers;        /* num_hidden_layers, malloc'ed */
} mx_clip_vision;

/* Binds every parameter through b (or only enumerates them when b->enumerating) into a new *out
 * (NULL after a failure); mx_clip_vision_free(NULL) does nothing. */
int mx_clip_vision_load(mx_clip_vision **out, const mx_clip_vision_config *cfg, mx_binder *b, mx_status *st);
void mx_clip_vision_free(mx_clip_vision *m);
/* Arena bytes of mx_clip_vision_forward on B images (its dry run). */
int mx_clip_vision_arena_bytes(const mx_clip_vision *m, int B, size_t *bytes, mx_status *st);

/* Runs the tower on pixel_values [B, channels, image_size, image_size] (CLIP-normalised,
 * clip_image.h). Outputs (backend memory of c; any may be NULL):
 *   image_embeds [B, projection_dim]
 *   last_hidden  [B, tokens, hidden]   the last layer's output
 *   penultimate  [B, tokens, hidden]   the output of the layer before it (hidden_states[-2], what
 *                                      the IP-Adapter "Plus" models take)
 * Temporaries come from `arena`; on a measuring arena only allocations are made (the dry run). */
int mx_clip_vision_forward(const mx_clip_vision *m, const mx_ctx *c, mx_arena *arena, const float *pixels, int B,
                           float *image_embeds, float *last_hidden, float *penultimate, mx_status *st);
/* The same on HOST arrays: pixels [B, channels, S, S] -> image_embeds [B, projection_dim] (host),
 * through an arena of the dry run's size on c's backend. */
int mx_clip_vision_embed_images(const mx_ctx *c, const mx_clip_vision *m, const float *pixels, int B,
                                float *image_embeds, mx_status *st);

/* The registry's entry points (registry.h). */
int mx_clip_vision_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                               mx_status *st);
int mx_clip_vision_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_clip_vision_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
extern const mx_net_slot mx_clip_vision_slots[]; /* its slots (registry.h) */

#endif
