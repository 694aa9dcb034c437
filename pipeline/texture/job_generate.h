/* The diffusion call of a job and the control planes it takes: prompt embeddings (cached), denoising
 * with ControlNets and style tokens, decoding (job_generate.c); depth and inpainting planes of a view
 * (job_controls.c). Internal to pipeline/texture. */
#ifndef MX_JOB_GENERATE_H
#define MX_JOB_GENERATE_H

#include <stdint.h>

#include "job_views.h"
#include "models.h"
#include "style.h"

#define MX_JOB_MAX_PROMPTS 16

/* mx_job (job.h) as its stages see it. */
typedef struct mx_job mx_job;

typedef struct mx_prompt_cache {
    int n;
    char *text[MX_JOB_MAX_PROMPTS];
    float *emb[MX_JOB_MAX_PROMPTS]; /* [77][C] */
} mx_prompt_cache;

/* Generation: where the networks run, the networks, the prompt embeddings. */
typedef struct mx_job_gen {
    const mx_ctx *ctx; /* the model set's context (o->models), or own_ctx */
    mx_ctx own_ctx;
    int own_ctx_ready;
    const mx_models *models; /* o->models, or own_models; NULL with MX_JOB_NO_MODELS */
    mx_models own_models;
    int own_models_ready;
    mx_prompt_cache prompts;
    float *uncond; /* negative prompt embedding [77][C] */
    int truncation_warned;
    mx_style style; /* the style images and their tokens, encoded once for every view (style.h) */
} mx_job_gen;

/* What one diffusion call generates: n items of image_h x image_w, with their control
 * planes [n][3][image_h][image_w] (NULL: that ControlNet is off) and prompts. With
 * init_images it is the inpaint pipeline (paint_masks given, latent blending of the rest; the
 * view step at strength 1, enhance below 1) or the img2img pipeline (paint_masks NULL, SDEdit
 * at `strength`), sd_edit.h. */
typedef struct mx_gen_batch {
    int n, image_h, image_w;
    const char *const *prompts;
    const float *depth_planes;
    const float *inpaint_planes;
    float w_depth, w_inpaint;
    const float *w_depth_items, *w_inpaint_items; /* [n] per-item weights, or NULL: w_depth, w_inpaint */
    const float *init_images; /* [n][3][h][w] in [0,1]: the current render (views) or the texture (enhance) */
    const float *paint_masks; /* [n][1][h][w], 1 = paint; NULL: img2img */
    float strength;
    uint64_t first_stream; /* item i uses noise stream first_stream + i */
    const char *stage;     /* for progress lines */
} mx_gen_batch;

/* Checks that the weights hold what --fast needs, encodes the style images once, encodes the
 * negative prompt; warns (once per job) when a prompt is longer than CLIP reads. */
int mx_job_check_fast_models(const mx_job *j, mx_status *st);
int mx_job_encode_style(mx_job *j, mx_status *st);
int mx_job_encode_negative(mx_job *j, mx_status *st);
int mx_job_warn_if_truncated(mx_job *j, const char *what, const char *text, mx_status *st);
/* Runs one diffusion call: images out [n][3][h][w] in [0, 1]. */
int mx_job_generate(mx_job *j, const mx_gen_batch *b, float *images, mx_status *st);

/* Frees the prompt cache, the style tokens, and the context and models the job made itself. */
void mx_job_gen_free(mx_job_gen *g);

/* Where a view's model-size planes go: each [c][S][plane_w], the view at column x0. */
typedef struct mx_view_planes {
    float *depth;   /* depth control, always */
    float *inpaint; /* inpaint control (NULL: none, and no init/paint either) */
    float *init;    /* I′, the current textures rendered (may be NULL) */
    float *paint;   /* 1 channel: the paint mask (may be NULL) */
    int plane_w, x0;
} mx_view_planes;

/* The control planes of a view at the model image size S: depth, and (when p->inpaint is not
 * NULL) the render I′ of `current` (mx_job_current_textures, one per layer) with the pixels
 * to paint set to -1, I′ itself and the paint mask. */
int mx_job_view_controls(mx_job *j, mx_job_view *v, const mx_view_planes *p, const mx_image *current,
                         mx_status *st);
/* The current textures (one per layer): unknown texels mid grey, except the ring of
 * CURRENT_DILATE_TEXELS around known texels, which repeats their colours. Free each with mx_image_free. */
int mx_job_current_textures(mx_job *j, mx_image *tex, mx_status *st);
#endif
