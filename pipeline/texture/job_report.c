/* Progress events, cancellation, coverage and report.json (job_report.h). */
#include "job.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../../runtime/version.h"

/* Sends one event to the progress callback; a non-zero answer stops the run. */
void mx_job_emit_progress(mx_job *j, int step, int steps, const char *message) {
    const mx_texture_opts *o = j->o;
    if (!o->progress) return;
    mx_texture_progress p = {.stage = j->rep.phase,
                             .step = step,
                             .steps = steps,
                             .views_done = j->rep.views_done,
                             .views_total = o->pub.views,
                             .coverage = j->rep.coverage, /* not counted again at every denoising step */
                             .seconds = mx_now() - j->rep.t0,
                             .message = message};
    if (o->progress(o->progress_user, &p)) j->rep.stop = 1;
}

void mx_job_progress(mx_job *j, const char *fmt, ...) {
    if (!j->o->pub.verbose && !j->o->progress) return;
    char line[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    if (!!j->o->pub.verbose) fprintf(stderr, "matex: [%7.2fs] %s\n", mx_now() - j->rep.t0, line);
    mx_job_emit_progress(j, 0, 0, line);
}

void mx_job_set_phase(mx_job *j, const char *stage) { snprintf(j->rep.phase, sizeof j->rep.phase, "%s", stage); }

int mx_job_check_cancel(const mx_job *j, mx_status *st) {
    if (j->rep.stop || (j->o->pub.cancel && *j->o->pub.cancel)) return mx_fail(st, MX_ECANCEL, "interrupted");
    return 0;
}

double mx_job_work_since(mx_job *j, mx_job_work part, double t0) {
    double s = mx_now() - t0;
    j->rep.work_s[part] += s;
    return s;
}

void mx_job_stage_done(mx_job *j, const char *name, double seconds) {
    if (j->rep.nstages == (int)(sizeof j->rep.stage_s / sizeof j->rep.stage_s[0])) return;
    j->rep.stage_name[j->rep.nstages] = name;
    j->rep.stage_s[j->rep.nstages++] = seconds;
}

/* The kernels and arithmetic of a context, for the log and report.json: a CPU level and its
 * precision, or CUDA, "mixed": it computes each product in its weights' type (fp16/bf16 weights on
 * tensor cores with fp32 sums, fp32 weights in fp32; ops/cuda/cuda_backend.h). */
int mx_job_ctx_on_cuda(const mx_ctx *c) { return c->be && c->be->kind == MX_BACKEND_CUDA; }

const char *mx_job_ctx_kernels_name(const mx_ctx *c) { return mx_job_ctx_on_cuda(c) ? "cuda" : mx_isa_name(c->k->isa); }

const char *mx_job_ctx_precision_name(const mx_ctx *c) {
    return mx_job_ctx_on_cuda(c) ? "mixed" : mx_precision_name(mx_isa_precision(c->k->isa));
}

void mx_job_report_header(mx_job *j) {
    const mx_texture_opts *o = j->o;
    mx_jw *w = &j->rep.json;
    mx_jw_init(w);
    mx_jw_begin_obj(w, NULL);
    mx_jw_str(w, "matex_version", MX_VERSION);
    mx_jw_str(w, "verb", mx_options_verb_name(j->verb));
    mx_jw_str(w, "mesh", j->mesh.source_path);
    if (o->pub.source_path) mx_jw_str(w, "source", o->pub.source_path);
    if (j->gen.models) {
        mx_jw_str(w, "prompt", o->pub.prompt);
        mx_jw_str(w, "negative_prompt", o->pub.negative_prompt);
        mx_jw_int(w, "seed", (long long)o->pub.seed);
        mx_jw_int(w, "steps", o->pub.steps);
        mx_jw_bool(w, "fast", o->pub.fast);
        mx_jw_num(w, "guidance", o->pub.guidance);
        mx_jw_int(w, "image_size", o->pub.image_size);
        mx_style_report(&j->gen.style, w);
    }
    mx_options_report(&o->pub, j->verb, w);
    mx_jw_int(w, "texture_size", o->pub.texture_size);
    mx_jw_int(w, "render_size", o->pub.render_size);
    mx_jw_int(w, "threads", mx_pool_threads(j->gen.ctx->pool));
    if (j->gen.models) {
        mx_jw_str(w, "precision", mx_job_ctx_precision_name(j->gen.ctx));
        mx_jw_str(w, "kernels", mx_job_ctx_kernels_name(j->gen.ctx));
        mx_jw_str(w, "weights", mx_models_path(j->gen.models));
        mx_jw_str(w, "weights_digest", j->gen.models->digest);
    }
    mx_jw_int(w, "faces", j->mesh.nfaces);
    mx_jw_int(w, "vertices", j->mesh.nverts);
    mx_jw_int(w, "textures", j->nlayers);
    mx_jw_bool(w, "uv_atlas_built", j->atlas_built);
    if (j->atlas_built) {
        mx_jw_begin_obj(w, "uv_atlas");
        mx_jw_int(w, "charts", j->atlas.charts);
        mx_jw_num(w, "utilisation", j->atlas.utilisation);
        mx_jw_num(w, "stretch_mean", j->atlas.stretch_mean);
        mx_jw_num(w, "seconds", j->atlas.seconds);
        mx_jw_end_obj(w);
    }
    mx_jw_int(w, "candidate_views", o->pub.candidates);
    mx_jw_num(w, "candidate_visible_texels", (double)j->sched.n_visible);
    mx_jw_num(w, "mesh_texels", (double)j->sched.n_chart);
    mx_jw_begin_arr(w, "views");
}

/* After each denoising step: the progress line and event; non-zero stops the loop. */
int mx_job_report_step(void *user, int step, int n_steps, int64_t timestep) {
    mx_job *j = user;
    char line[160];
    snprintf(line, sizeof line, "%s: step %d/%d (t=%lld)", j->rep.phase, step + 1, n_steps, (long long)timestep);
    if (!!j->o->pub.verbose) fprintf(stderr, "matex: [%7.2fs] %s\n", mx_now() - j->rep.t0, line);
    mx_job_emit_progress(j, step + 1, n_steps, line);
    return j->rep.stop || (j->o->pub.cancel && *j->o->pub.cancel);
}

/* Fraction of the texels in `of` (n_of of them) that are in T^B. */
static double painted_fraction(const mx_job *j, const uint8_t *of, int64_t n_of) {
    if (n_of == 0) return 1.0;
    int64_t n = (int64_t)j->nlayers * j->o->pub.texture_size * j->o->pub.texture_size, hit = 0;
    for (int64_t i = 0; i < n; i++) hit += of[i] && j->bake.known[i];
    return (double)hit / (double)n_of;
}

double mx_job_coverage(const mx_job *j) { return painted_fraction(j, j->sched.chart, j->sched.n_chart); }

double mx_job_candidate_coverage(const mx_job *j) {
    return painted_fraction(j, j->sched.visible, j->sched.n_visible);
}

void mx_job_report_view(mx_job *j, const mx_job_view *v, const char *stage, int batch, float w_depth,
                        float w_inpaint) {
    mx_jw *w = &j->rep.json;
    mx_jw_begin_obj(w, NULL);
    mx_jw_str(w, "stage", stage);
    mx_jw_int(w, "batch", batch);
    mx_jw_num(w, "azimuth", v->cam.azimuth);
    mx_jw_num(w, "elevation", v->cam.elevation);
    mx_jw_str(w, "view_word", mx_camera_view_word(&v->cam));
    mx_jw_str(w, "prompt", v->prompt);
    mx_jw_num(w, "depth_weight", w_depth);
    mx_jw_num(w, "inpaint_weight", w_inpaint);
    mx_jw_int(w, "untextured_pixels", v->untextured_pixels);
    mx_jw_num(w, "coverage_after", mx_job_coverage(j));
    mx_jw_num(w, "candidate_coverage_after", mx_job_candidate_coverage(j));
    mx_jw_num(w, "batch_denoise_s", j->rep.last_denoise_s);
    mx_jw_num(w, "batch_decode_s", j->rep.last_decode_s);
    mx_jw_num(w, "time_s", mx_now() - j->rep.t0);
    mx_jw_end_obj(w);
}

const char *mx_job_report_end(mx_job *j) {
    mx_jw *w = &j->rep.json;
    mx_jw_end_arr(w); /* views */
    mx_jw_num(w, "coverage", mx_job_coverage(j));
    mx_jw_num(w, "candidate_coverage", mx_job_candidate_coverage(j));
    mx_jw_int(w, "views_generated", j->rep.views_done);
    if (!isnan(j->rep.psnr_db)) mx_jw_num(w, "psnr_db", j->rep.psnr_db);
    mx_jw_begin_obj(w, "stages_s");
    for (int i = 0; i < j->rep.nstages; i++) mx_jw_num(w, j->rep.stage_name[i], j->rep.stage_s[i]);
    mx_jw_end_obj(w);
    mx_jw_begin_obj(w, "work_s"); /* the parts of the stages (MX_JOB_WORK_PARTS) */
#define MX_JOB_WORK_KEY_(id, key, what) mx_jw_num(w, key, j->rep.work_s[MX_WORK_##id]);
    MX_JOB_WORK_PARTS(MX_JOB_WORK_KEY_)
#undef MX_JOB_WORK_KEY_
    mx_jw_end_obj(w);
    mx_jw_num(w, "load_s", j->rep.load_s); /* the weights onto the device: inside stages_s.load */
    mx_jw_num(w, "total_s", mx_now() - j->rep.t0);
    mx_jw_end_obj(w);
    return mx_jw_text(w);
}
