/* The encoder half shared by UNet2DConditionModel and ControlNetModel (diffusers v0.35.2
 * unet_2d_condition.py, controlnet.py): time embedding, conv_in, the down levels and the mid
 * block, writing every down-block residual. Its sizes (mx_unet_num_residuals,
 * mx_unet_residual_shape, mx_unet_check_sizes: unet.h) are defined next to it, in
 * unet_encoder.c. Internal to pipeline/nn. */
#ifndef MX_UNET_ENCODER_H
#define MX_UNET_ENCODER_H

#include "blocks.h"
#include "netcfg.h"


#define MX_ENC_MAX_LAYERS 16

/* One down level: layers_per_block resnets (+ transformers for CrossAttnDownBlock2D), then
 * a Downsample2D unless it is the last level. */
typedef struct mx_down_level {
    mx_resnet res[MX_ENC_MAX_LAYERS];
    mx_transformer attn[MX_ENC_MAX_LAYERS];
    mx_down down;
    int cross, has_down, cout;
} mx_down_level;

/* UNetMidBlock2DCrossAttn: resnet, transformer, resnet. */
typedef struct mx_mid_block {
    mx_resnet res0, res1;
    mx_transformer attn;
} mx_mid_block;

typedef struct mx_unet_encoder {
    mx_unet_config cfg;
    mx_time_embed time;
    mx_conv conv_in;
    mx_down_level *levels; /* cfg.nlevels */
    mx_mid_block mid;
} mx_unet_encoder;

int mx_unet_encoder_load(mx_unet_encoder *e, const mx_unet_config *cfg, mx_binder *b, mx_status *st);
void mx_unet_encoder_free(mx_unet_encoder *e);
/* conv_in(sample) [+ add, when not NULL] -> res[0]; down levels -> res[1..]; mid block -> mid.
 * res[i] are caller buffers shaped by mx_unet_residual_shape. ip: image guidance of the UNet's
 * cross-attentions (blocks.h), NULL for none (always for a ControlNet). */
int mx_unet_encoder_run(mx_run *r, const mx_unet_encoder *e, const float *sample, const float *add, int B, int H,
                        int W, const float *temb_silu, const float *context, int T, const mx_ip_guide *ip,
                        float *const *res, float *mid);

#endif
