/* Denoising that starts from an image, as the diffusers reference pipelines do it:
 *
 * - inpaint (StableDiffusionControlNetInpaintPipeline, 4-channel UNet, any ControlNets, e.g.
 *   [depth, inpaint]): image_latents = 0.18215 · mean(encode(2·image − 1)); paint =
 *   nearest-resize(mask ≥ 0.5) to the latent size; start latents = noise · init_noise_sigma at
 *   strength 1 (else add_noise(image_latents, noise, first timestep)); after every step i the
 *   known region is put back (latent blending):
 *     known = add_noise(image_latents, noise, timesteps[i+1])  (image_latents after the last step)
 *     x = (1 − paint) · known + paint · x
 * - img2img / SDEdit (StableDiffusionControlNetImg2ImgPipeline): mask NULL; the scheduler keeps
 *   the last floor(steps · strength) timesteps and x = add_noise(image_latents, noise, first
 *   kept timestep); no blending.
 *
 * The VAE encoding is the posterior mean (the goldens' manifests state it); with a TAESD it is its
 * encoder (image_latents = scaling_factor · encode(2·image − 1), scaling_factor 1, as the diffusers
 * pipelines with vae = AutoencoderTiny). All noise is an input. The loop itself is mx_sd_denoise. */
#ifndef MX_SD_EDIT_H
#define MX_SD_EDIT_H

#include "sd_pipeline.h"
#include "taesd.h"

typedef struct mx_sd_edit {
    const mx_vae *vae;
    const float *image; /* [n, 3, 8h, 8w] in [0, 1] */
    const float *mask;  /* [n, 1, 8h, 8w], 1 = paint (binarised at 0.5); NULL: img2img */
    const float *noise; /* [n, 4, h, w] */
    float strength;     /* (0, 1]; applied to rq->sched here */
    const mx_taesd *taesd; /* non-NULL: the encoder instead of vae (the few-step path), image [n, 3, f h, f w] */
} mx_sd_edit;

/* Runs the pipeline up to the final latents [n, 4, h, w] (decode with mx_sd_decode_latents).
 * rq->sched must be freshly initialised for n·4·h·w values; rq->after_step (may be NULL) sees
 * the latents after the blending of each step. */
int mx_sd_edit_run(const mx_sd_request *rq, const mx_sd_edit *e, const mx_ctx *c, int n, int h, int w,
                   float *latents, mx_status *st);
/* mx_sd_edit_run in its two parts, for a caller that times the encoding apart from the loop: the
 * image latents of e->image [n, 4, h, w] (host; the request checked first), then the run from them
 * (e->image unused). */
int mx_sd_edit_encode(const mx_sd_request *rq, const mx_sd_edit *e, const mx_ctx *c, int n, int h, int w,
                      float *image_latents, mx_status *st);
int mx_sd_edit_run_encoded(const mx_sd_request *rq, const mx_sd_edit *e, const float *image_latents, const mx_ctx *c,
                           int n, int h, int w, float *latents, mx_status *st);

#endif
