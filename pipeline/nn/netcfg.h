/* Network configs: the diffusers config.json of each network parsed into plain structs.
 * Parsing validates every size (positive, bounded, divisible where the architecture needs it)
 * and rejects features matex does not implement with a message naming the source and the key. */
#ifndef MX_NETCFG_H
#define MX_NETCFG_H

#include <stddef.h>

#include "../../runtime/status.h"

#define MX_NET_MAX_LEVELS 8   /* block_out_channels entries */
#define MX_NET_MAX_COND_CH 8  /* ControlNet conditioning_embedding_out_channels entries */

/* UNet2DConditionModel and ControlNetModel share the encoder half of this config. */
typedef struct mx_unet_config {
    int is_controlnet;            /* parsed from a ControlNetModel config */
    int in_channels, out_channels;
    int nlevels;                  /* len(block_out_channels) */
    int block_out_channels[MX_NET_MAX_LEVELS];
    int layers_per_block;
    int down_cross[MX_NET_MAX_LEVELS]; /* 1: CrossAttnDownBlock2D, 0: DownBlock2D */
    int up_cross[MX_NET_MAX_LEVELS];   /* 1: CrossAttnUpBlock2D, 0: UpBlock2D (UNet only) */
    int heads[MX_NET_MAX_LEVELS];      /* attention heads per level (num_attention_heads, or the
                                          legacy attention_head_dim when that is null) */
    int transformer_layers[MX_NET_MAX_LEVELS];
                                  /* the mid block is always UNetMidBlock2DCrossAttn */
    int cross_attention_dim;
    int norm_num_groups;
    float norm_eps;
    int use_linear_projection;
    int flip_sin_to_cos;
    float freq_shift;
    int conv_in_kernel, conv_out_kernel;
    int downsample_padding;
    float mid_block_scale_factor; /* output_scale_factor of the mid block's resnets */
    int time_embed_dim;           /* block_out_channels[0] * 4 unless time_embedding_dim is set */
    /* ControlNet only */
    int conditioning_channels;
    int n_cond_emb;
    int cond_emb_channels[MX_NET_MAX_COND_CH];
    int cond_bgr;                 /* controlnet_conditioning_channel_order == "bgr" */
} mx_unet_config;

typedef struct mx_vae_config {
    int in_channels, out_channels, latent_channels;
    int nlevels;
    int block_out_channels[MX_NET_MAX_LEVELS];
    int layers_per_block;
    int norm_num_groups;
    int mid_attention;            /* mid_block_add_attention */
    int use_quant_conv, use_post_quant_conv;
    float scaling_factor;         /* informational: not applied by the VAE calls */
} mx_vae_config;

/* AutoencoderTiny (TAESD). diffusers' EncoderTiny/DecoderTiny only run when every level has
 * the same channel count, so one `channels` describes them. */
typedef struct mx_taesd_config {
    int in_channels, out_channels, latent_channels;
    int nlevels;
    int channels;                           /* block_out_channels (all equal) */
    int enc_blocks[MX_NET_MAX_LEVELS];      /* num_encoder_blocks */
    int dec_blocks[MX_NET_MAX_LEVELS];      /* num_decoder_blocks */
    float scaling_factor;                   /* informational: 1.0 for TAESD */
} mx_taesd_config;

/* Parse text[0..len) (config.json contents); `what` names the source in messages. A UNet
 * parser accepts UNet2DConditionModel and ControlNetModel configs. */
int mx_unet_config_parse(mx_unet_config *cfg, const char *text, size_t len, const char *what, mx_status *st);
int mx_vae_config_parse(mx_vae_config *cfg, const char *text, size_t len, const char *what, mx_status *st);
int mx_taesd_config_parse(mx_taesd_config *cfg, const char *text, size_t len, const char *what, mx_status *st);

/* Class of a config text ("_class_name", else "architectures"[0], else the class of its
 * "model_type" in weights/networks.h: clip_text_model, clip_vision_model), copied into buf (empty
 * when none). */
int mx_config_class_name(char *buf, size_t cap, const char *text, size_t len, const char *what, mx_status *st);

#endif
