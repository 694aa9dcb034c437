/* Single-file Stable Diffusion 1.x checkpoints in the original (LDM) layout, as .safetensors or
 * as a PyTorch zip checkpoint (.ckpt/.pt/.pth): model.diffusion_model.* (UNet),
 * first_stage_model.* (VAE), cond_stage_model.transformer.* (CLIP text encoder),
 * control_model.* or bare ControlNet keys. The architecture is read from the tensors' shapes:
 * SD1.x (4 latent channels, convolutional proj_in, no OpenCLIP or SDXL parts) is accepted, SD2.x,
 * SDXL and the 9-channel inpainting UNet are refused by name. Schedule buffers are checked
 * (alphas_cumprod against SD1.5's scaled-linear schedule) and skipped, like the EMA copy of the
 * UNet (used instead with MX_SF_EMA) and CLIP's position_ids. Each network comes out with
 * diffusers tensor names and a diffusers config made from the shapes (8 attention heads for the
 * UNet and ControlNet as in every SD1.x model; hidden_size / 64 heads for CLIP, as ViT-L/14: widths that are no multiple of 64, the test models', get one head). */
#ifndef MX_SINGLE_FILE_H
#define MX_SINGLE_FILE_H

#include <stdio.h>

#include "../runtime/status.h"
#include "safetensors.h"

/* MX_SF_CONTROLNET_ONLY: only the ControlNet (control_model.* or bare keys). MX_SF_VAE_ONLY: only the
 * VAE (first_stage_model.*, or a VAE file of its own with LDM names encoder.*, decoder.* or diffusers
 * names, e.g. vae-ft-mse-840000-ema-pruned). */
enum {
    MX_SF_EMA = 1,
    MX_SF_CONTROLNET_ONLY = 2,
    MX_SF_VAE_ONLY = 4,
    MX_SF_TAESD = 8,      /* taesd_file.h */
    MX_SF_IP_ADAPTER = 16 /* ip_adapter_file.h */
};

typedef struct mx_sf_net {
    const char *kind; /* "unet", "controlnet", "vae", "text_encoder" */
    char *config;     /* diffusers config JSON */
    mx_st_tensor *tensors; /* diffusers names (malloc'ed); data points into the source file */
    size_t count;
} mx_sf_net;

typedef struct mx_single_file {
    mx_safetensors src; /* the file's own tensors (LDM names), mapped */
    mx_safetensors aux; /* the TAESD encoder file beside the decoder (taesd_file.h), else empty */
    const char *container; /* "safetensors" or "PyTorch zip" */
    mx_sf_net nets[4];
    size_t n_nets;
    size_t skipped;       /* tensors and values not converted (schedule, EMA, other parts) */
    char skipped_example[160];
    int has_ema;          /* the file carries an EMA copy of the UNet */
    int used_ema;
    int schedule_checked; /* alphas_cumprod was present and matched */
    int sd15_sizes;       /* the UNet has SD1.5's sizes (320 channels first, 768-wide cross-attention) */
} mx_single_file;

/* The tensors of a .safetensors file or a PyTorch zip checkpoint (by its first bytes), as they are
 * named; *container gets "safetensors" or "PyTorch zip", *skipped the non-tensor entries. */
int mx_sf_open_tensors(mx_safetensors *src, const char *path, const char **container, size_t *skipped,
                       mx_status *st);
/* Whether path is a regular file (not a diffusers folder). */
int mx_sf_is_file(const char *path);
int mx_sf_open(mx_single_file *sf, const char *path, int flags, mx_status *st);
void mx_sf_close(mx_single_file *sf);
/* `matex info` text: container, architecture, networks with sizes, dtype, counts, skipped keys. */
void mx_sf_print_info(const mx_single_file *sf, FILE *out);

#endif
