/* Tensor names of the original Stable Diffusion (LDM) layout <-> diffusers names, both ways,
 * for the UNet, the ControlNet, the VAE and the CLIP text encoder of SD1.x. The rules are those
 * of diffusers' single-file conversion (convert_ldm_unet_checkpoint, convert_ldm_vae_checkpoint,
 * convert_controlnet_checkpoint), written as index arithmetic over the block layout. Names are
 * given without the file's network prefix (model.diffusion_model., first_stage_model.,
 * cond_stage_model.transformer., control_model.). */
#ifndef MX_LDM_NAMES_H
#define MX_LDM_NAMES_H

#include <stddef.h>

typedef enum { MX_LDM_UNET, MX_LDM_CONTROLNET, MX_LDM_VAE, MX_LDM_CLIP } mx_ldm_net;

/* What the index arithmetic needs to know of a network. */
typedef struct mx_ldm_layout {
    int layers_per_block; /* UNet/ControlNet resnets per down level; VAE encoder resnets per level */
    int levels;           /* down levels (UNet, ControlNet, VAE) */
    unsigned up_attention; /* UNet: bit b set when up block b has attentions (diffusers order) */
    int hint_convs;        /* ControlNet: convolutions of the conditioning embedding (conv_in, blocks, conv_out) */
} mx_ldm_layout;

/* 0 with the diffusers name in out, or -1 when the name is not one of the network's. */
int mx_ldm_to_diffusers(mx_ldm_net net, const mx_ldm_layout *l, const char *ldm, char *out, size_t cap);
/* The inverse: 0 with the LDM name in out, or -1. */
int mx_diffusers_to_ldm(mx_ldm_net net, const mx_ldm_layout *l, const char *diffusers, char *out, size_t cap);

/* Whether a diffusers VAE name is one of the mid-block attention projections that the LDM layout
 * stores as 1x1 convolutions ([C, C, 1, 1]) and diffusers as linear layers ([C, C]). */
int mx_ldm_vae_attn_linear(const char *diffusers);

#endif
