/* One diffusion call of a job: prompt embeddings (cached), the denoising with its controls and
 * style tokens, the decode (job_generate.h). */
#include "job.h"

#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../../runtime/rng.h"
#include "../nn/sd_edit.h"
#include "../nn/vae_tiled.h"

/* VAE decode in tiles of this many latents (512 pixels: diffusers' own tile for SD1.5, so a 512x512
 * view decodes untiled, as diffusers decodes it), one image at a time; the 1024x512 grid takes 3x2
 * tiles blended as diffusers' tiled_decode (pipeline/nn/vae_tiled.h). Tiles of 48 cost a view 1.41x
 * the work for 0.15 GB less memory (docs/PERFORMANCE.md, "Memory (peak RSS)"). */
#define VAE_TILE 64

/* Warns, once per job, when `text` is longer than the 75 tokens CLIP reads: how many tokens are
 * dropped (the count `matex tokenize` gives) and where the dropped part begins. */
int mx_job_warn_if_truncated(mx_job *j, const char *what, const char *text, mx_status *st) {
    if (j->gen.truncation_warned || !j->gen.models->tok) return 0;
    mx_tok_result r;
    if (mx_tok_encode(j->gen.models->tok, text, &r, st)) return -1;
    if (r.n_dropped == 0) return 0;
    mx_warn("%s longer than the %d tokens CLIP reads: %d%s tokens dropped, from \"%s\"", what, MX_CLIP_CONTEXT - 2,
            r.n_dropped, r.n_dropped + MX_CLIP_CONTEXT - 2 >= MX_TOK_MAX_COUNTED ? " or more" : "", r.dropped_from);
    j->gen.truncation_warned = 1;
    return 0;
}

int mx_job_encode_negative(mx_job *j, mx_status *st) {
    int C = mx_models_text_dim(j->gen.models);
    j->gen.uncond = malloc(sizeof(float) * MX_CLIP_CONTEXT * (size_t)C);
    if (!j->gen.uncond) return mx_fail(st, MX_ENOMEM, "prompt embeddings: out of memory");
    int dropped = 0;
    double t = mx_now();
    if (mx_models_encode_text(j->gen.models, j->gen.ctx, j->o->pub.negative_prompt, j->gen.uncond, &dropped, st)) return -1;
    mx_job_work_since(j, MX_WORK_ENCODE_TEXT, t);
    if (dropped) mx_warn("negative prompt longer than 77 tokens: truncated (%d tokens dropped)", dropped);
    return 0;
}

/* The style images' tokens, once for the whole run (style.h). */
int mx_job_encode_style(mx_job *j, mx_status *st) {
    mx_style *s = &j->gen.style;
    if (!s->n) return 0;
    double t = mx_now();
    if (mx_style_check_models(j->gen.models, st) || mx_style_encode(s, j->gen.models, j->gen.ctx, st)) return -1;
    mx_job_progress(j, "style: %d image(s), %d image tokens at scale %.2f, encoded in %.2fs", s->n, s->ntokens,
                    s->scale, mx_now() - t);
    return 0;
}

/* --fast runs the LCM scheduler on an LCM-distilled UNet and decodes with TAESD: both must be in
 * the weight file. */
int mx_job_check_fast_models(const mx_job *j, mx_status *st) {
    const mx_models *m = j->gen.models;
    if (m->lcm && m->taesd) return 0;
    return mx_fail(st, MX_EINPUT,
                   "%s: --fast needs a weight file with the LCM-LoRA merged into the UNet and TAESD; this one has %s. "
                   "Make one with: matex convert SD15_DIR --controlnet depth=DIR --controlnet inpaint=DIR "
                   "--lcm-lora lcm-lora-sdv1-5.safetensors --taesd TAESD_DIR -o W.mxw",
                   mx_models_path(m), !m->lcm && !m->taesd ? "neither" : !m->lcm ? "no LCM-LoRA (metadata unet.lcm_lora)"
                                                                                : "no TAESD (taesd.*)");
}

/* Cached CLIP embedding of a prompt ([77][C], owned by the cache). */
static const float *prompt_embedding(mx_job *j, const char *text, mx_status *st) {
    mx_prompt_cache *pc = &j->gen.prompts;
    for (int i = 0; i < pc->n; i++)
        if (!strcmp(pc->text[i], text)) return pc->emb[i];
    if (pc->n == MX_JOB_MAX_PROMPTS) {
        free(pc->text[0]);
        free(pc->emb[0]);
        memmove(pc->text, pc->text + 1, sizeof(pc->text[0]) * (MX_JOB_MAX_PROMPTS - 1));
        memmove(pc->emb, pc->emb + 1, sizeof(pc->emb[0]) * (MX_JOB_MAX_PROMPTS - 1));
        pc->n--;
    }
    size_t floats = (size_t)MX_CLIP_CONTEXT * mx_models_text_dim(j->gen.models);
    float *emb = malloc(floats * sizeof *emb);
    char *copy = strdup(text);
    int dropped = 0;
    double t = mx_now();
    if (!emb || !copy || mx_models_encode_text(j->gen.models, j->gen.ctx, text, emb, &dropped, st)) {
        free(emb);
        free(copy);
        if (!st->msg[0]) mx_fail(st, MX_ENOMEM, "prompt embeddings: out of memory");
        return NULL;
    }
    mx_job_work_since(j, MX_WORK_ENCODE_TEXT, t);
    if (dropped && mx_job_warn_if_truncated(j, "view prompt", text, st)) {
        free(emb);
        free(copy);
        return NULL;
    }
    pc->text[pc->n] = copy;
    pc->emb[pc->n] = emb;
    return pc->emb[pc->n++];
}

/* Embeddings of every item, cond and uncond, [n][77][C]. */
static int batch_embeddings(mx_job *j, const mx_gen_batch *b, float *cond, float *uncond, mx_status *st) {
    size_t per = (size_t)MX_CLIP_CONTEXT * mx_models_text_dim(j->gen.models);
    for (int i = 0; i < b->n; i++) {
        const float *e = prompt_embedding(j, b->prompts[i], st);
        if (!e) return -1;
        memcpy(cond + i * per, e, per * sizeof *e);
        memcpy(uncond + i * per, j->gen.uncond, per * sizeof *e);
    }
    return 0;
}

/* Runs the denoising of a batch from seeded noise (item i: stream first_stream + i): plain
 * text-to-image, or the inpaint / img2img pipeline when the batch has init images (their
 * encoding into image_lat, timed as its own part of the report, then the loop). */
static int denoise_batch(mx_job *j, const mx_gen_batch *b, mx_sd_request *rq, float *lat, float *noise,
                         float *image_lat, size_t per_item, int h, int w, mx_status *st) {
    for (int i = 0; i < b->n; i++)
        mx_rng_fill_normal(noise + i * per_item, per_item, j->o->pub.seed, b->first_stream + (uint64_t)i, 0);
    if (!b->init_images) {
        memcpy(lat, noise, per_item * b->n * sizeof *lat);
        mx_sched_scale_initial(rq->sched, lat, per_item * b->n);
        double t = mx_now();
        int rc = mx_sd_denoise(rq, j->gen.ctx, lat, b->n, h, w, st);
        j->rep.last_denoise_s = mx_job_work_since(j, MX_WORK_DENOISE, t);
        return rc;
    }
    mx_sd_edit e = {.vae = j->gen.models->vae,
                    .image = b->init_images,
                    .mask = b->paint_masks,
                    .noise = noise,
                    .strength = b->strength,
                    .taesd = j->o->pub.fast ? j->gen.models->taesd : NULL};
    double t = mx_now();
    if (mx_sd_edit_encode(rq, &e, j->gen.ctx, b->n, h, w, image_lat, st)) return -1;
    mx_job_work_since(j, MX_WORK_ENCODE_IMAGE, t);
    t = mx_now();
    int rc = mx_sd_edit_run_encoded(rq, &e, image_lat, j->gen.ctx, b->n, h, w, lat, st);
    j->rep.last_denoise_s = mx_job_work_since(j, MX_WORK_DENOISE, t);
    return rc;
}

/* LCM step noise: item i draws from its own stream (first_stream + i) after its start latents,
 * step k at indices (k + 1) * per_item.., so an item's noise does not depend on its batch. */
typedef struct lcm_noise {
    uint64_t seed, first_stream;
    int n;
    size_t per_item;
} lcm_noise;

static int fill_lcm_noise(void *user, int step, float *noise, size_t numel) {
    const lcm_noise *z = user;
    if (numel != z->per_item * (size_t)z->n) return -1;
    for (int i = 0; i < z->n; i++)
        mx_rng_fill_normal(noise + i * z->per_item, z->per_item, z->seed, z->first_stream + (uint64_t)i,
                           (uint64_t)(step + 1) * z->per_item);
    return 0;
}

static int decode_images(mx_job *j, const float *lat, int n, int h, int w, float *images, mx_status *st) {
    if (j->o->pub.fast) return mx_taesd_decode_image(j->gen.ctx, j->gen.models->taesd, lat, n, h, w, images, st);
    return mx_vae_decode_image_tiled(j->gen.ctx, j->gen.models->vae, lat, n, h, w, VAE_TILE, images, st);
}

/* The run's style tokens for a diffusion call, the same for every item (NULL without style images). */
static const mx_sd_image_guide *style_guide(const mx_job *j, mx_sd_image_guide *g) {
    const mx_style *s = &j->gen.style;
    if (!s->n) return NULL;
    *g = (mx_sd_image_guide){.adapter = j->gen.models->ip_adapter,
                             .cond = s->tokens,
                             .uncond = s->zero_tokens,
                             .n_tokens = s->ntokens,
                             .per_latent = 0,
                             .scale = s->scale};
    return g;
}

int mx_job_generate(mx_job *j, const mx_gen_batch *b, float *images, mx_status *st) {
    int f = j->o->pub.fast ? mx_taesd_factor(j->gen.models->taesd) : mx_vae_factor(j->gen.models->vae);
    if (b->image_h % f || b->image_w % f)
        return mx_fail(st, MX_EINPUT, "image size %dx%d is not a multiple of the VAE factor %d", b->image_w,
                       b->image_h, f);
    int h = b->image_h / f, w = b->image_w / f;
    size_t per_item = (size_t)4 * h * w, per_text = (size_t)MX_CLIP_CONTEXT * mx_models_text_dim(j->gen.models);
    float *lat = malloc(3 * per_item * b->n * sizeof *lat), *noise = lat + per_item * b->n;
    float *image_lat = noise + per_item * b->n;
    float *cond = malloc(per_text * b->n * sizeof *cond), *uncond = malloc(per_text * b->n * sizeof *uncond);
    mx_sched s;
    mx_sched_config scfg = j->gen.models->sched;
    lcm_noise lcm = {.seed = j->o->pub.seed, .first_stream = b->first_stream, .n = b->n, .per_item = per_item};
    memset(&s, 0, sizeof s);
    int rc = -1, sched_ready = 0;
    if (j->o->pub.fast) mx_sched_config_lcm(&scfg, &j->gen.models->sched);
    if (!lat || !cond || !uncond) {
        mx_fail(st, MX_ENOMEM, "generation buffers: out of memory");
        goto done;
    }
    if (batch_embeddings(j, b, cond, uncond, st)) goto done;
    if (mx_sched_init(&s, j->gen.ctx, &scfg, j->o->pub.steps, per_item * b->n, st)) goto done;
    sched_ready = 1;
    s.noise_fn = fill_lcm_noise;
    s.noise_user = &lcm;
    mx_sd_control controls[2];
    int nc = 0;
    if (b->depth_planes && j->gen.models->cn_depth && (b->w_depth != 0 || b->w_depth_items))
        controls[nc++] = (mx_sd_control){j->gen.models->cn_depth, b->depth_planes, b->w_depth, b->w_depth_items};
    if (b->inpaint_planes && j->gen.models->cn_inpaint && (b->w_inpaint != 0 || b->w_inpaint_items))
        controls[nc++] = (mx_sd_control){j->gen.models->cn_inpaint, b->inpaint_planes, b->w_inpaint, b->w_inpaint_items};
    mx_job_set_phase(j, b->stage);
    mx_sd_image_guide guide;
    mx_sd_request rq = {.unet = j->gen.models->unet,
                        .controls = controls,
                        .n_controls = nc,
                        .cond_text = cond,
                        .uncond_text = uncond,
                        .T = MX_CLIP_CONTEXT,
                        .guidance = j->o->pub.guidance,
                        .sched = &s,
                        .progress = mx_job_report_step,
                        .progress_user = j,
                        .image = style_guide(j, &guide)};
    if (denoise_batch(j, b, &rq, lat, noise, image_lat, per_item, h, w, st)) {
        mx_job_check_cancel(j, st); /* a stop asked by report_step reads "interrupted" */
        goto done;
    }
    double t = mx_now();
    rc = decode_images(j, lat, b->n, h, w, images, st);
    j->rep.last_decode_s = mx_job_work_since(j, MX_WORK_DECODE, t);
done:
    if (sched_ready) mx_sched_free(&s);
    free(lat);
    free(cond);
    free(uncond);
    return rc;
}

void mx_job_gen_free(mx_job_gen *g) {
    for (int i = 0; i < g->prompts.n; i++) {
        free(g->prompts.text[i]);
        free(g->prompts.emb[i]);
    }
    free(g->uncond);
    mx_style_free(&g->style);
    if (g->own_models_ready) mx_models_free(&g->own_models);
    if (g->own_ctx_ready) mx_ctx_destroy(&g->own_ctx);
}
