/* AutoencoderKL (diffusers v0.35.2): encoder image -> (mean, logvar) and decoder latents ->
 * image. The pipeline's scaling factor (0.18215 for SD1.5) is NOT applied here.
 * Loading/arena use as in unet.h (prefix "vae."). */
#ifndef MX_VAE_H
#define MX_VAE_H

#include "../../ops/ops.h"
#include "net_io.h"
#include "netcfg.h"
#include "params.h"

typedef struct mx_vae mx_vae;

int mx_vae_load(mx_vae **out, const mx_vae_config *cfg, mx_binder *b, mx_status *st);
void mx_vae_free(mx_vae *v);
const mx_vae_config *mx_vae_cfg(const mx_vae *v);
/* Downscale factor image -> latent: 2^(nlevels-1) (8 for SD1.5). */
int mx_vae_factor(const mx_vae *v);

/* image [B, in_channels, H, W] in [-1, 1], H and W multiples of the factor ->
 * mean, logvar [B, latent_channels, H/f, W/f] (logvar clamped to [-30, 20]). logvar may be NULL. */
int mx_vae_encode_arena_bytes(const mx_vae *v, int B, int H, int W, size_t *bytes, mx_status *st);
int mx_vae_encode(const mx_ctx *c, const mx_vae *v, const float *image, int B, int H, int W, float *mean,
                  float *logvar, mx_arena *a, mx_status *st);
/* latents [B, latent_channels, h, w] -> image [B, out_channels, h*f, w*f] (unclamped). */
int mx_vae_decode_arena_bytes(const mx_vae *v, int B, int h, int w, size_t *bytes, mx_status *st);
int mx_vae_decode(const mx_ctx *c, const mx_vae *v, const float *latents, int B, int h, int w, float *image,
                  mx_arena *a, mx_status *st);
double mx_vae_decode_flops(const mx_vae *v, int B, int h, int w);

/* The registry's entry points (registry.h): config parse + load, the run-net adapters. */
int mx_vae_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st);
int mx_vae_encode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_vae_encode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
int mx_vae_decode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_vae_decode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
/* Their slots (registry.h). */
extern const mx_net_slot mx_vae_encode_slots[], mx_vae_decode_slots[];

#endif
