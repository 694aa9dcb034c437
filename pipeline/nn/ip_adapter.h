/* The IP-Adapter for SD1.5 (h94/IP-Adapter; diffusers v0.35.2 ImageProjection and
 * IPAdapterAttnProcessor2_0): image guidance of the UNet's cross-attentions.
 *
 * ImageProjection turns one image embedding e [E] (the CLIP vision tower's image_embeds) into
 * num_tokens tokens: tokens = LayerNorm(reshape(proj(e), [num_tokens, cross_attention_dim])).
 * Several images per sample give their tokens one after the other. Each cross-attention layer of
 * the UNet has to_k_ip / to_v_ip (no bias) and adds scale · attention(q, to_k_ip(tokens),
 * to_v_ip(tokens)) to its text attention: the UNet does that (unet.h, mx_unet_input.ip*); the
 * ControlNets never see the tokens.
 *
 * Parameters (weight-file prefix "ip_adapter.") keep their published names: image_proj.proj.*,
 * image_proj.norm.*, and "{2j+1}.to_k_ip.weight" / "{2j+1}.to_v_ip.weight" for cross-attention
 * layer j, numbered as diffusers' unet.attn_processors lists the UNet's attentions (down blocks,
 * up blocks, the mid block; the self-attentions take the even numbers). The config, written by
 * `matex convert --ip-adapter` from the shapes (weights/ip_adapter_file.h):
 *   {"_class_name": "IPAdapter", "image_embed_dim": E, "num_tokens": N, "cross_attention_dim": C,
 *    "hidden_sizes": [width of cross-attention layer j, ...]} */
#ifndef MX_NN_IP_ADAPTER_H
#define MX_NN_IP_ADAPTER_H

#include "../../ops/ops.h"
#include "blocks.h"
#include "net_io.h"
#include "params.h"

#define MX_IP_MAX_LAYERS 64
#define MX_IP_MAX_TOKENS 4096 /* image tokens per sample (num_tokens × images) */

typedef struct mx_ip_adapter {
    int embed_dim, num_tokens, cross_dim, n_layers;
    int hidden[MX_IP_MAX_LAYERS]; /* width of cross-attention layer j */
    mx_lin proj;                  /* image_proj.proj: E -> N·C */
    mx_ln norm;                   /* image_proj.norm over C */
    mx_lin k[MX_IP_MAX_LAYERS], v[MX_IP_MAX_LAYERS]; /* to_k_ip, to_v_ip: C -> hidden[j] */
} mx_ip_adapter;

/* Parses the config text[0..len) (`what` names it) and binds every parameter from b. */
int mx_ip_adapter_load(mx_ip_adapter **out, const char *text, size_t len, const char *what, mx_binder *b,
                       mx_status *st);
void mx_ip_adapter_free(mx_ip_adapter *ad);

/* Arena bytes of mx_ip_adapter_tokens for n embeddings (dry run). */
int mx_ip_adapter_arena_bytes(const mx_ip_adapter *ad, int n, size_t *bytes, mx_status *st);
/* tokens [n, num_tokens, cross_dim] of embeds [n, embed_dim] (both in c's memory). */
int mx_ip_adapter_tokens(const mx_ctx *c, const mx_ip_adapter *ad, const float *embeds, int n, float *tokens,
                         mx_arena *a, mx_status *st);
/* The tokens of the two halves of classifier-free guidance, in host memory, as diffusers' pipelines
 * make them (prepare_ip_adapter_image_embeds): cond [n_images·num_tokens, cross_dim] of embeds
 * [n_images, embed_dim] (host), uncond the same for zero embeddings (may be NULL: not made). */
int mx_ip_adapter_guidance_tokens(const mx_ctx *c, const mx_ip_adapter *ad, const float *embeds, int n_images,
                                  float *cond, float *uncond, mx_status *st);

/* The registry's entry points (registry.h). */
int mx_ip_adapter_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                              mx_status *st);
int mx_ip_adapter_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_ip_adapter_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
extern const mx_net_slot mx_ip_adapter_slots[]; /* its slots (registry.h) */

#endif
