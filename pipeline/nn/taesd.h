/* AutoencoderTiny (TAESD; diffusers v0.35.2 autoencoder_tiny.py, vae.py EncoderTiny /
 * DecoderTiny / AutoencoderTinyBlock): a small ReLU conv net that maps images to SD latents and
 * back, ~100x cheaper than the AutoencoderKL decoder. Its latents are SD's scaled latents
 * (scaling factor 1.0): decode(x) takes what the UNet denoises, with no 1/0.18215.
 *
 *   encode: image [B, 3, H, W] in [-1, 1] -> (x + 1) / 2 -> conv, blocks; per further level a
 *           stride-2 conv (no bias) and blocks; conv -> latents [B, 4, H/f, W/f]
 *   decode: latents -> 3 tanh(x / 3) -> conv, ReLU; per level blocks, then (but the last) a 2x
 *           nearest upsample and a conv (no bias); last conv -> image * 2 - 1 (unclamped)
 *   block:  ReLU(conv(ReLU(conv(ReLU(conv(x))))) + x)
 * Weights are bound as "encoder.layers.<i>..." / "decoder.layers.<i>..." (prefix "taesd." in a
 * weight file). Forward passes take all memory from the arena (size it with the *_arena_bytes
 * dry runs) and call ops only. */
#ifndef MX_TAESD_H
#define MX_TAESD_H

#include "../../ops/ops.h"
#include "net_io.h"
#include "netcfg.h"
#include "params.h"

typedef struct mx_taesd mx_taesd;

int mx_taesd_load(mx_taesd **out, const mx_taesd_config *cfg, mx_binder *b, mx_status *st);
void mx_taesd_free(mx_taesd *t);
const mx_taesd_config *mx_taesd_cfg(const mx_taesd *t);
/* Downscale factor image -> latent: 2^(nlevels-1) (8 for TAESD). */
int mx_taesd_factor(const mx_taesd *t);

/* image [B, in_channels, H, W] in [-1, 1], H and W multiples of the factor ->
 * latents [B, latent_channels, H/f, W/f]. */
int mx_taesd_encode_arena_bytes(const mx_taesd *t, int B, int H, int W, size_t *bytes, mx_status *st);
int mx_taesd_encode(const mx_ctx *c, const mx_taesd *t, const float *image, int B, int H, int W, float *latents,
                    mx_arena *a, mx_status *st);
/* latents [B, latent_channels, h, w] -> image [B, out_channels, h*f, w*f] in about [-1, 1] (unclamped). */
int mx_taesd_decode_arena_bytes(const mx_taesd *t, int B, int h, int w, size_t *bytes, mx_status *st);
int mx_taesd_decode(const mx_ctx *c, const mx_taesd *t, const float *latents, int B, int h, int w, float *image,
                    mx_arena *a, mx_status *st);
/* As the SD pipelines post-process it, on HOST arrays (uploaded and downloaded here): image
 * [n, 3, h*f, w*f] in [0, 1] = clamp(decode(latents / scaling_factor) / 2 + 0.5, 0, 1). */
int mx_taesd_decode_image(const mx_ctx *c, const mx_taesd *t, const float *latents, int n, int h, int w,
                          float *image, mx_status *st);
/* As the SD img2img/inpaint pipelines encode with it (AutoencoderTiny.encode(...).latents times
 * scaling_factor), on HOST arrays: image [n, 3, H, W] in [0, 1] -> latents [n, 4, H/f, W/f]. */
int mx_taesd_encode_image(const mx_ctx *c, const mx_taesd *t, const float *image, int n, int H, int W, float *latents,
                          mx_status *st);
double mx_taesd_decode_flops(const mx_taesd *t, int B, int h, int w);

/* The registry's entry points (registry.h): config parse + load, the run-net adapters. */
int mx_taesd_load_config(void **net, const char *text, size_t len, const char *what, mx_binder *b, mx_status *st);
int mx_taesd_encode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_taesd_encode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
int mx_taesd_decode_arena_io(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
int mx_taesd_decode_run_io(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);
/* Their slots (registry.h). */
extern const mx_net_slot mx_taesd_encode_slots[], mx_taesd_decode_slots[];

#endif
