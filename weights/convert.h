/* `matex convert`: diffusers / transformers folders -> one matex weight file (FORMAT.md).
 * Input is either a model-set folder (subfolders unet/, controlnet/, vae/, text_encoder/,
 * tokenizer/, scheduler/; each present one is converted) or a single network folder whose
 * config.json names its type. Extra ControlNets come as NAME=DIR, a TAESD (AutoencoderTiny)
 * folder as `taesd`, a CLIP vision tower (the IP-Adapter's image encoder) as `image_encoder`, an IP-Adapter
 * file as `ip_adapter` (checked against the UNet converted with it). LoRA files are merged into the UNet and text-encoder weights; one marked as
 * the LCM-LoRA is recorded (metadata "unet.lcm_lora") so that the few-step path can require it. */
#ifndef MX_CONVERT_H
#define MX_CONVERT_H

#include <stddef.h>

#include "../runtime/status.h"
#include "../runtime/tensor.h"

#define MX_CONVERT_MAX_EXTRA 8

typedef struct mx_convert_opts {
    const char *input;  /* model-set or network folder, or a single-file checkpoint (single_file.h); may be NULL when controlnets are given */
    const char *output; /* the .mxw file, written atomically */
    mx_dtype dtype;     /* for floating tensors with >= 2 dims: MX_F32, MX_F16 or MX_BF16 */
    int prefer_fp16;    /* --variant fp16: read the *.fp16.safetensors files */
    size_t n_controlnets;
    struct {
        const char *name; /* [a-z0-9_]+, gives the prefix "controlnet_<name>." */
        const char *dir; /* a diffusers folder or a single file (single_file.h) */
    } controlnets[MX_CONVERT_MAX_EXTRA];
    const char *taesd;  /* AutoencoderTiny folder -> taesd.*, or NULL */
    const char *image_encoder; /* CLIPVisionModelWithProjection folder -> image_encoder.* (and its
                                  preprocessor_config.json -> metadata image_encoder.processor), or NULL */
    const char *ip_adapter; /* the published IP-Adapter file (ip_adapter_file.h) -> ip_adapter.*, or NULL */
    int ema;            /* single-file checkpoints: take the EMA copy of the UNet */
    const char *vae;    /* a VAE replacing the model's: a single file (single_file.h) or an AutoencoderKL folder */
    const char *tokenizer; /* folder with vocab.json + merges.txt for single files (no tokenizer/), or NULL */
    size_t n_loras;
    struct {
        const char *path;
        float scale;
        int lcm; /* the LCM-LoRA (distils the UNet for the LCM scheduler) */
    } loras[MX_CONVERT_MAX_EXTRA];
} mx_convert_opts;

/* Summary of a finished conversion, for the command line's report. */
typedef struct mx_convert_result {
    size_t tensors, networks, lora_merged; /* lora_merged: weights changed by LoRA merges */
} mx_convert_result;

int mx_convert(const mx_convert_opts *opts, mx_convert_result *res, mx_status *st);

#endif
