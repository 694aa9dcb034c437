/* What the two autoencoders (AutoencoderKL: vae.c, vae_tiled.c; AutoencoderTiny: taesd.c) share
 * around a pass (an encoder or decoder run): running it on an arena it leaves as it found it, and
 * the SD pipelines' decode of host latents into a host image in [0, 1] and encode of one. */
#ifndef MX_AE_PASS_H
#define MX_AE_PASS_H

#include "blocks.h"

/* A pass on r's arena: in [B, ., H, W] -> out (sizes are those of `in`). */
typedef int (*mx_ae_pass_fn)(mx_run *r, const void *net, const float *in, int B, int H, int W, float *out);

/* Runs pass on arena a (in fp32 throughout when net_fp32: the network's mx_prec_net_fp32) and
 * releases what it took there; a failure is prefixed with `what`. */
int mx_ae_run(const mx_ctx *c, int net_fp32, mx_ae_pass_fn pass, const void *net, const float *in, int B,
              int H, int W, float *out, mx_arena *a, mx_status *st, const char *what);

/* The pass's dry run on a measuring arena (sizes checked by the caller): the arena bytes it needs
 * (bytes, may be NULL) and its FLOPs (flops, may be NULL). */
int mx_ae_dry_run(mx_ae_pass_fn pass, const void *net, int B, int H, int W, size_t *bytes, double *flops,
                  mx_status *st);

/* A decoder or encoder with what the host calls need to know of it. */
typedef struct mx_ae_coder {
    /* device latents [n, latent, h, w] -> device image [n, image, f h, f w], unclamped (decoder), or
     * device image in [-1, 1] -> device latents (encoder; h, w are then the image's) */
    int (*run)(const mx_ctx *c, const void *net, const float *in, int n, int h, int w, float *out, mx_arena *a,
               mx_status *st);
    const void *net;
    int latent_channels, image_channels, factor; /* image side = factor * latent side */
    float scaling_factor;
    size_t arena_bytes; /* for this call's sizes */
} mx_ae_coder;

/* On HOST arrays (uploaded and downloaded here): image [n, out, f h, f w] =
 * clamp(decode(latents / scaling_factor) / 2 + 0.5, 0, 1). */
int mx_ae_decode_host(const mx_ctx *c, const mx_ae_coder *d, const float *latents, int n, int h, int w,
                      float *image, mx_status *st);
/* On HOST arrays: latents [n, latent, H/f, W/f] = scaling_factor * encode(2 image - 1), image
 * [n, image, H, W] in [0, 1]. */
int mx_ae_encode_host(const mx_ctx *c, const mx_ae_coder *e, const float *image, int n, int H, int W, float *latents,
                      mx_status *st);

#endif
