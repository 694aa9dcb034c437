/* Tiled VAE decode, as diffusers' AutoencoderKL.tiled_decode (v0.35.2) computes it, to bound
 * the decoder's memory by one tile instead of the whole image:
 *   tile T (latent side, a multiple of 4; diffusers: sample_size / 8 = 64 for SD1.5),
 *   overlap_size = floor(0.75 T) latent, blend = floor(8 T * 0.25) pixels, row_limit = 8 T - blend;
 *   tiles start every overlap_size latents in each direction and are decoded independently
 *   (GroupNorm statistics are per tile, as in diffusers); in row-major order each decoded tile is
 *   blended in place with the (already blended) tile above over its first min(blend, heights) rows,
 *   b[y] = a[H_a - E + y] (1 - y/E) + b[y] (y/E), then likewise with the tile to its left over its
 *   columns; the output is the concatenation of each tile's top-left row_limit x row_limit crop.
 * A latent no larger than T in both directions is decoded untiled (bit-identical to mx_vae_decode),
 * as diffusers does. Batch items are decoded one after the other. */
#ifndef MX_VAE_TILED_H
#define MX_VAE_TILED_H

#include "vae.h"

/* latents [B, latent_channels, h, w] -> image [B, out_channels, 8h, 8w] (unclamped, no scaling). */
int mx_vae_decode_tiled_arena_bytes(const mx_vae *v, int h, int w, int tile, size_t *bytes, mx_status *st);
int mx_vae_decode_tiled(const mx_ctx *c, const mx_vae *v, const float *latents, int B, int h, int w, int tile,
                        float *image, mx_arena *a, mx_status *st);

/* The SD pipelines' post-processing on the tiled decode, on HOST arrays (uploaded and downloaded
 * here): image [n, 3, 8h, 8w] in [0, 1] = clamp(tiled_decode(latents / scaling_factor) / 2 + 0.5, 0, 1). */
int mx_vae_decode_image_tiled(const mx_ctx *c, const mx_vae *v, const float *latents, int n, int h, int w, int tile,
                              float *image, mx_status *st);

#endif
