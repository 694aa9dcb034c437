/* One Stable Diffusion denoising loop (diffusers StableDiffusionControlNetPipeline semantics):
 * per step, x_in = [x, x] (uncond first); every ControlNet runs on x_in with the embeddings
 * [uncond, cond] and its control image (repeated for both halves) at its conditioning scale,
 * the residuals of all ControlNets are summed; the UNet predicts eps on x_in with the summed
 * residuals; CFG combines eps_u + g·(eps_c − eps_u); the scheduler steps.
 * With guidance <= 1 there is no unconditional half (diffusers' do_classifier_free_guidance).
 * The networks run on one latent (its CFG pair) at a time: they are batch-independent, so this
 * changes no result and bounds a step's memory to that of one latent.
 *
 * Also the small helpers around the loop: latents <-> images through the VAE with the SD1.5
 * scaling factor, as the pipelines do it. */
#ifndef MX_SD_PIPELINE_H
#define MX_SD_PIPELINE_H

#include <stddef.h>
#include <stdint.h>

#include "../../ops/ops.h"
#include "../../runtime/status.h"
#include "clip.h"
#include "controlnet.h"
#include "scheduler.h"
#include "tokenizer.h"
#include "unet.h"
#include "vae.h"

#define MX_SD_MAX_CONTROLNETS 4
#define MX_SD_VAE_SCALE 0.18215f

typedef struct mx_sd_control {
    const mx_controlnet *net;
    const float *image; /* [n, cond_ch, 8h, 8w] in the range the ControlNet expects, one per latent */
    float weight;       /* conditioning scale (w_D, w_I); 0 skips the ControlNet */
    const float *item_weights; /* [n] one scale per latent (both CFG halves), or NULL: weight for all */
} mx_sd_control;

/* Called after each step with the step index (0-based), the number of steps, the timestep
 * and the latents [n, 4, h, w]; returning non-zero cancels the loop (mx_sd_denoise then
 * fails with "cancelled"). */
typedef int (*mx_sd_progress)(void *user, int step, int n_steps, int64_t timestep, const float *latents,
                              size_t numel);
/* Called after each scheduler step (before progress) and may change the latents [n, 4, h, w]
 * (memory of c's backend) in place through ops (the inpaint pipeline puts the known region
 * back here); non-zero is an error already recorded in st. */
typedef int (*mx_sd_after_step)(void *user, const mx_ctx *c, int step, int n_steps, float *latents,
                                mx_status *st);

/* Image guidance of the loop (IP-Adapter, ip_adapter.h): image tokens in every cross-attention of
 * the UNet (not the ControlNets) at `scale`. The conditional half gets `cond`, the unconditional
 * half `uncond`, the tokens of a zero embedding as diffusers' prepare_ip_adapter_image_embeds
 * makes them (mx_ip_adapter_guidance_tokens gives both). Host memory, [sets, n_tokens,
 * cross_attention_dim] each: one set shared by every latent (a batch of views with one style
 * image), or one per latent (per_latent). */
typedef struct mx_sd_image_guide {
    const mx_ip_adapter *adapter;
    const float *cond, *uncond; /* uncond unused when guidance <= 1 */
    int n_tokens;               /* per set: num_tokens × images */
    int per_latent;             /* 0: one set for all latents; 1: n sets */
    float scale;                /* 0: the plain UNet */
} mx_sd_image_guide;

typedef struct mx_sd_request {
    const mx_unet *unet;
    const mx_sd_control *controls; /* 0..MX_SD_MAX_CONTROLNETS */
    int n_controls;
    const float *cond_text;   /* [n, T, cross_attention_dim] prompt embeddings */
    const float *uncond_text; /* [n, T, cross_attention_dim] negative embeddings (unused when guidance <= 1) */
    int T;                    /* 77 */
    float guidance;           /* 7.5 in SD1.5 pipelines */
    mx_sched *sched;          /* initialised for numel = n*4*h*w, strength applied, not yet stepped */
    mx_sd_progress progress;  /* may be NULL */
    void *progress_user;
    mx_sd_after_step after_step; /* may be NULL */
    void *after_step_user;
    const mx_sd_image_guide *image; /* NULL: no image guidance */
} mx_sd_request;

/* Runs every remaining scheduler step in place on latents [n, C, h, w] (C = the UNet's
 * in_channels), which hold the start latents already scaled by the initial noise sigma (or
 * noised with mx_sched_add_noise for SDEdit). All working memory (batched inputs, residuals,
 * eps, one arena sized by dry runs of the networks) is allocated once before the loop. */
int mx_sd_denoise(const mx_sd_request *rq, const mx_ctx *c, float *latents, int n, int h, int w,
                  mx_status *st);

/* Prompt embeddings as the SD pipelines make them: each prompt tokenized to 77 ids and
 * encoded, embeds [n, 77, hidden] = last_hidden_state. n_dropped (may be NULL) receives the
 * tokens each prompt lost to truncation (the caller warns). An empty prompt is the usual
 * negative prompt. */
int mx_sd_encode_prompts(const mx_ctx *c, const mx_clip *clip, const mx_tokenizer *tok, const char *const *prompts,
                         int n, float *embeds, int *n_dropped, mx_status *st);

/* image [n, 3, 8h, 8w] in [0, 1] = clamp(decode(latents / 0.18215) / 2 + 0.5, 0, 1). */
int mx_sd_decode_latents(const mx_ctx *c, const mx_vae *vae, const float *latents, int n, int h, int w,
                         float *image, mx_status *st);
/* latents [n, 4, H/8, W/8] = 0.18215 · mean of encode(2·image − 1), image in [0, 1]
 * (the deterministic "argmax" latent, as used for SDEdit in matex). */
int mx_sd_encode_image(const mx_ctx *c, const mx_vae *vae, const float *image, int n, int H, int W,
                       float *latents, mx_status *st);

#endif
