/* Progress events, cancellation, coverage and report.json of a job (job_report.c). Internal to
 * pipeline/texture. */
#ifndef MX_JOB_REPORT_H
#define MX_JOB_REPORT_H

#include "../../runtime/jsonw.h"
#include "../../runtime/tensor.h"
#include "job_views.h"

/* mx_job (job.h) as its stages see it. */
typedef struct mx_job mx_job;

/* The report's work_s: the parts of the stages, each timed where it runs and summed over the run
 * (the one list: the enum, the report's keys and their order come from it). The parts do not
 * overlap, so their sum is the stages' time less their untimed glue; a part a verb does not run
 * stays 0. X(ID, key, what). */
#define MX_JOB_WORK_PARTS(X)                                                                                 \
    X(CANDIDATES, "candidates", "the candidate cameras' renders and the texels they see (load stage)")      \
    X(RENDER, "render", "a view's renders: rasterisation, masks, edge erosion, crop (mx_job_view_prepare)") \
    X(CONTROLS, "controls", "control planes: the current textures, I', the paint mask, resizes")            \
    X(SELECT, "select", "view selection: each step of the schedule")                                        \
    X(ENCODE_TEXT, "encode_text", "CLIP: the negative prompt and each view prompt not yet encoded")         \
    X(ENCODE_IMAGE, "encode_image", "the VAE (or TAESD) encoding of the init images of a view")             \
    X(DENOISE, "denoise", "the denoising loops: networks, scheduler, latent blending")                      \
    X(DECODE, "decode", "the VAE (or TAESD) decode of the generated images")                                \
    X(BACKPROJECT, "backproject", "pasting an image into its view and the splat into the texture")          \
    X(FILL, "fill", "the UV fill of the texels no view reached")                                             \
    X(WRITE, "write", "the output files but report.json: textures (PNG, EXR), OBJ, GLB")

typedef enum {
#define MX_JOB_WORK_ID_(id, key, what) MX_WORK_##id,
    MX_JOB_WORK_PARTS(MX_JOB_WORK_ID_)
#undef MX_JOB_WORK_ID_
    MX_WORK_COUNT
} mx_job_work;

/* Progress and the report: report.json as it is written, times of stages and work. */
typedef struct mx_job_rep {
    mx_jw json;     /* open object; the views array is written as views are generated */
    char phase[32]; /* stage of the progress events */
    int stop;       /* the progress callback asked to cancel */
    int views_done;
    double coverage; /* mx_job_coverage as of the latest backprojection: what every progress event says */
    double t0;
    double last_denoise_s, last_decode_s; /* of the latest mx_job_generate, for the report */
    double work_s[MX_WORK_COUNT];         /* summed over the run: the report's work_s */
    double load_s;  /* reading the weight file onto the device (CPU or GPU): the report's load_s; 0 when
                     * the job used a model set already loaded */
    double psnr_db; /* transfer onto its own mesh: PSNR of the painted texels (report), else NAN */
    int nstages;    /* seconds per stage, for the report */
    const char *stage_name[8];
    double stage_s[8];
} mx_job_rep;

/* Names the stage that the following progress events belong to (copied). */
void mx_job_set_phase(mx_job *j, const char *stage);
/* -1 with MX_ECANCEL "interrupted" once the caller's cancel flag is set or the progress
 * callback asked to stop, else 0. */
int mx_job_check_cancel(const mx_job *j, mx_status *st);
/* Adds the seconds since t0 (an mx_now()) to a part of the report's work_s; returns them. */
double mx_job_work_since(mx_job *j, mx_job_work part, double t0);
/* Records the time of a finished stage (name: a string literal). */
void mx_job_stage_done(mx_job *j, const char *name, double seconds);
/* Progress line on stderr (unless quiet) and to the progress callback. */
void mx_job_progress(mx_job *j, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Sends one event to the progress callback; a non-zero answer stops the run. */
void mx_job_emit_progress(mx_job *j, int step, int steps, const char *message);
/* The denoising loop's step callback (mx_sd_request.progress): the progress line and event. */
int mx_job_report_step(void *user, int step, int n_steps, int64_t timestep);
/* The kernels and arithmetic of a context, for the log and report.json. */
int mx_job_ctx_on_cuda(const mx_ctx *c);
const char *mx_job_ctx_kernels_name(const mx_ctx *c);
const char *mx_job_ctx_precision_name(const mx_ctx *c);
/* report.json: the header (the run's inputs and options, the mesh), one entry per view, and the end
 * (coverage, stage and work times); mx_job_report_end returns the whole text (NULL: out of memory). */
void mx_job_report_header(mx_job *j);
/* Adds the view to the report. */
void mx_job_report_view(mx_job *j, const mx_job_view *v, const char *stage, int batch, float w_depth,
                        float w_inpaint);
const char *mx_job_report_end(mx_job *j);
/* Coverage: the fraction of the mesh's texels (inside a face in UV space) in T^B, what the
 * texture has; the candidate coverage: of the texels some candidate sees (what the schedule
 * can reach, and what coverage_stop is measured against). */
double mx_job_coverage(const mx_job *j);
double mx_job_candidate_coverage(const mx_job *j);
#endif
