/* The model set of the texturing method, loaded from one matex weight file: tokenizer, CLIP
 * text encoder, UNet, ControlNet depth, ControlNet inpaint, VAE and the scheduler config.
 * Tensor prefixes are those `matex convert` writes: "text_encoder.", "unet.",
 * "controlnet_depth." (or a single "controlnet."), "controlnet_inpaint.", "vae.", and for the
 * few-step path "taesd." (optional), for image guidance "image_encoder." and "ip_adapter." (optional,
 * opened when present: style images need both, pipeline/texture/style.h). */
#ifndef MX_MODELS_H
#define MX_MODELS_H

#include "../../ops/ops.h"
#include "../../weights/weights.h"
#include "../nn/clip.h"
#include "../nn/clip_image.h"
#include "../nn/clip_vision.h"
#include "../nn/controlnet.h"
#include "../nn/ip_adapter.h"
#include "../nn/params.h"
#include "../nn/scheduler.h"
#include "../nn/taesd.h"
#include "../nn/tokenizer.h"
#include "../nn/unet.h"
#include "../nn/vae.h"

enum { MX_MODELS_NEED_INPAINT = 1, MX_MODELS_NEED_DEPTH = 2 };
#define MX_MODELS_NETS 8

typedef struct mx_models {
    mx_weightfile *wf;
    mx_tokenizer *tok;
    mx_clip *clip;
    mx_unet *unet;
    mx_controlnet *cn_depth;   /* NULL when not in the file and not needed */
    mx_controlnet *cn_inpaint; /* NULL when not in the file and not needed */
    mx_vae *vae;
    mx_taesd *taesd;           /* NULL when the file has no taesd.* */
    mx_ip_adapter *ip_adapter; /* NULL when the file has no ip_adapter.*; else checked against the UNet */
    mx_clip_vision *image_encoder; /* NULL when the file has no image_encoder.* (the style images' encoder) */
    mx_clip_image_config image_processor; /* its preprocessing (with image_encoder) */
    int lcm;                   /* the UNet has a merged LCM-LoRA (metadata unet.lcm_lora) */
    mx_sched_config sched;
    const mx_ctx *c;                           /* the weights live on c's backend */
    /* per network (text encoder, UNet, depth, inpaint, VAE, TAESD, IP-Adapter, image encoder):
     * its weights on the device, and the weight file's binder behind them */
    mx_binder binders[MX_MODELS_NETS], wf_binders[MX_MODELS_NETS];
    const char *kinds[MX_MODELS_NETS]; /* per slot: the kind loaded there (MX_NET_*), NULL: none */
    char digest[32]; /* of the weight file (digest.h), for reports */
} mx_models;

/* Opens the weight file and binds every network, its weights kept on c's backend (c must
 * outlive m). `needs` (MX_MODELS_NEED_*) lists the ControlNets that must be present; a missing
 * network is an error naming the file and the prefix it looked for. */
int mx_models_load(mx_models *m, const mx_ctx *c, const char *path, int needs, mx_status *st);
void mx_models_free(mx_models *m);
/* Lets c keep the set's weights packed once for its GEMM kernels (mx_ctx_pack_weights; their
 * mapped pages given back), taking at most MX_MODELS_PACK_EXTRA bytes beyond the weights. Only
 * for a context made for this set and destroyed after it: the packed copies are keyed by address. */
int mx_models_pack_weights(mx_ctx *c, mx_status *st);
/* None: bf16 pairs take what the fp16 weights took and are kept; fp32 panels of fp16 weights (the
 * layers the precision policy keeps in fp32, the whole of a --precision fp32 run) would take
 * twice and are packed per call. Measured on a 2-step default run: 256 MB of room for those
 * raised the peak RSS from the weights + 0.89 GB (before packing) to + 1.24 GB, past the goal of
 * weights + 1 GB. */
#define MX_MODELS_PACK_EXTRA ((size_t)0)
/* The same check for a model set already open (needs: MX_MODELS_NEED_*). */
int mx_models_check(const mx_models *m, int needs, mx_status *st);
/* 1 when a network of this kind (weights/networks.h: MX_NET_CONTROLNET, ...) is loaded, else 0. */
int mx_models_has_kind(const mx_models *m, const char *kind);
/* The weight file's path. */
const char *mx_models_path(const mx_models *m);

/* Prompt -> CLIP last_hidden_state [77, C] (C = text hidden size) in host memory. *n_dropped gets
 * the number of tokens cut by truncation to 77 (the caller warns). */
int mx_models_encode_text(const mx_models *m, const mx_ctx *c, const char *text, float *out, int *n_dropped,
                          mx_status *st);
/* Hidden size of the text encoder (= the UNet's cross-attention dim). */
int mx_models_text_dim(const mx_models *m);

#endif
