/* The state shared by `matex texture` and `matex enhance`: context, models, the mesh with
 * its normalised positions, the bake (texture accumulation and T^B), candidate views, the
 * prompt-embedding cache and the report. Internal to pipeline/texture. */
#ifndef MX_JOB_H
#define MX_JOB_H

#include <stdint.h>

#include "../geom/backproject.h"
#include "../geom/camera.h"
#include "../geom/uvatlas.h"
#include "../geom/views.h"
#include "../../runtime/jsonw.h"
#include "models.h"
#include "outdir.h"
#include "style.h"
#include "texture.h"

#define MX_JOB_MAX_PROMPTS 16
/* The gain floor: a candidate with fewer untextured pixels (at the candidate render size, 256)
 * is not worth a view, and the schedule ends. */
#define MX_JOB_MIN_UNTEXTURED_PIXELS 16
/* model_needs of mx_job_open for a job without networks (transfer). */
#define MX_JOB_NO_MODELS (-1)

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

/* The views: candidates, what they see, what the mesh has, and the schedule (views.h). */
typedef struct mx_job_sched {
    mx_view_cache vc;
    int vc_ready;
    uint8_t *visible; /* texels seen by some candidate [nlayers][tex][tex] */
    int64_t n_visible;
    uint8_t *chart;   /* texels of the mesh: inside a face in UV space [nlayers][tex][tex] */
    int64_t n_chart;
    mx_view_schedule schedule;
    int schedule_ready;
} mx_job_sched;

/* Progress and the report: report.json as it is written, times of stages and work. */
typedef struct mx_job_rep {
    mx_jw json;     /* open object; the views array is written as views are generated */
    char phase[32]; /* stage of the progress events */
    int stop;       /* the progress callback asked to cancel */
    int views_done;
    double t0;
    double last_denoise_s, last_decode_s;      /* of the latest mx_job_generate, for the report */
    double denoise_s, decode_s, backproject_s; /* summed over the run: the report's work_s */
    double psnr_db; /* transfer onto its own mesh: PSNR of the painted texels (report), else NAN */
    int nstages;    /* seconds per stage, for the report */
    const char *stage_name[8];
    double stage_s[8];
} mx_job_rep;

typedef struct mx_job {
    const mx_texture_opts *o;
    mx_outdir out; /* opened (checked, staging folder created) before anything else */
    mx_job_gen gen;
    mx_mesh mesh;
    float *pos;  /* normalised positions for rendering: (R p - center) * scale */
    float center[3], scale;
    int nlayers; /* textures: one per material keeping its own UVs, else 1 */
    int atlas_built;
    mx_uvatlas_report atlas;
    int keep_unreached; /* enhance: texels no view reached keep their colour (mx_job_finish does not fill) */
    int write_flags;    /* backprojection policy: MX_BACKPROJECT_OVERWRITE (angle-aware) or 0 (first wins), from o->pub.first_wins */
    mx_bake bake;
    int bake_ready;
    mx_job_sched sched;
    mx_job_rep rep;
} mx_job;

/* One view of a batch: its camera, prompt word, renders and crop. */
typedef struct mx_job_view {
    mx_camera cam;
    char prompt[1200];
    mx_view_buffers vb;
    int vb_ready;
    mx_crop crop;
    int64_t untextured_pixels; /* visible pixels still to paint (all foreground pixels before any paint) */
} mx_job_view;

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

/* Output folder when o->pub.out_dir is set (checked, staging folder created), context and models
 * (o->models with its context, else loaded from o->weights_path; needs: MX_MODELS_NEED_*, or
 * MX_JOB_NO_MODELS), mesh (a copy of o->mesh, else loaded from o->pub.mesh_path) and its normalised
 * copy, bake sized tex_size with nlayers layers, candidate cache and the report's header.
 * mx_job_close removes the staging folder of a run that did not finish. */
int mx_job_open(mx_job *j, const mx_texture_opts *o, int model_needs, int need_uvs, mx_status *st);
void mx_job_close(mx_job *j);

/* The context of a run (device, threads, precision of o), as a job or a model set makes it. */
int mx_job_ctx_create(mx_ctx *c, const mx_texture_opts *o, mx_status *st);

/* Runs one diffusion call: images out [n][3][h][w] in [0, 1]. */
int mx_job_generate(mx_job *j, const mx_gen_batch *b, float *images, mx_status *st);

/* Renders the view (culled + unculled, backprojection mask) and its object crop. */
int mx_job_view_prepare(mx_job *j, mx_job_view *v, mx_status *st);
void mx_job_view_free(mx_job_view *v);
/* The orthographic camera every view uses, at (azimuth, elevation) degrees. */
void mx_job_camera(mx_camera *cam, float azimuth, float elevation);
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
/* Pastes a generated image (planes [3][S][plane_w] from column x0) back into the view's crop
 * and backprojects it into the untextured texels. */
int mx_job_backproject(mx_job *j, mx_job_view *v, const float *planes, int plane_w, int x0, mx_status *st);
/* Backprojects a render-size image of the view where mask != 0 (timed: the report's
 * work_s.backproject; counted in views_done). */
int mx_job_backproject_render(mx_job *j, mx_job_view *v, const mx_image *img, const uint8_t *mask, mx_status *st);
/* The view's prompt, built here only: the grid's "<grid_word> <prompt>", a later view's
 * "<side|front|...> view of <prompt>" (paper §3.1: the view in the prompt against the Janus
 * problem), a transfer view's "<word> view" (no prompt; the report names the view). */
void mx_job_view_prompt(const mx_job *j, mx_job_view *v, int grid);
/* The view schedule after front and back (mx_view_schedule, views.h) over the job's candidates,
 * o->pub.views - 2 views, o->pub.coverage_stop and the MX_JOB_MIN_UNTEXTURED_PIXELS gain floor; max_batch:
 * the most views one step returns. mx_job_schedule_next plans the next step from T^B as it is
 * now: candidates into cand[max_batch], *n = 0 when the schedule has ended. */
int mx_job_schedule_begin(mx_job *j, int max_batch, mx_status *st);
int mx_job_schedule_next(mx_job *j, int *cand, int *n, mx_status *st);
/* Adds the view to the report. */
void mx_job_report_view(mx_job *j, const mx_job_view *v, const char *stage, int batch, float w_depth,
                        float w_inpaint);
/* Coverage: the fraction of the mesh's texels (inside a face in UV space) in T^B, what the
 * texture has; the candidate coverage: of the texels some candidate sees (what the schedule
 * can reach, and what coverage_stop is measured against). */
double mx_job_coverage(const mx_job *j);
double mx_job_candidate_coverage(const mx_job *j);
/* Fills unreached texels (harmonic fill across UV seams inside the charts, mx_uv_fill_harmonic;
 * gutter dilation) of every layer. */
int mx_job_fill_textures(mx_job *j, mx_image *tex, mx_status *st);
/* Fills unreached texels, writes the output folder (staged, then moved into place) when
 * o->pub.out_dir is set, and fills res (may be NULL): with o->keep_outputs it takes the textures
 * (their data is moved: textures[l] is left empty), the mesh and the report. Fails without writing
 * anything once the run is cancelled; nothing can fail after the folder is published. */
int mx_job_finish(mx_job *j, mx_image *textures, mx_texture_result *res, mx_status *st);
/* Names the stage that the following progress events belong to (copied). */
void mx_job_set_phase(mx_job *j, const char *stage);
/* -1 with MX_ECANCEL "interrupted" once the caller's cancel flag is set or the progress
 * callback asked to stop, else 0. */
int mx_job_check_cancel(const mx_job *j, mx_status *st);
/* Records the time of a finished stage (name: a string literal). */
void mx_job_stage_done(mx_job *j, const char *name, double seconds);
/* Progress line on stderr (unless quiet) and to the progress callback. */
void mx_job_progress(mx_job *j, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

#endif
