#include "texture.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../geom/masks.h"
#include "job.h"

static void free_views(mx_job_view *v, int n) {
    for (int i = 0; i < n; i++) mx_job_view_free(&v[i]);
}

/* Stage 0 (paper §3.1, "Global Consistency"): front and back depth side by side, one image. */
static int grid_stage(mx_job *j, mx_status *st) {
    const mx_texture_opts *o = j->o;
    double t = mx_now();
    int S = o->pub.image_size, W = 2 * S, rc = -1;
    mx_job_view v[2];
    memset(v, 0, sizeof v);
    mx_job_camera(&v[0].cam, 0.0f, 0.0f);
    mx_job_camera(&v[1].cam, 180.0f, 0.0f);
    float *planes = malloc(sizeof(float) * 3 * S * W), *image = malloc(sizeof(float) * 3 * S * W);
    const char *prompts[1];
    if (!planes || !image) {
        mx_fail(st, MX_ENOMEM, "grid: out of memory");
        goto done;
    }
    for (int i = 0; i < 2; i++) {
        mx_job_view_prompt(j, &v[i], 1);
        mx_view_planes vp = {.depth = planes, .plane_w = W, .x0 = i * S};
        if (mx_job_view_prepare(j, &v[i], st) || mx_job_view_controls(j, &v[i], &vp, NULL, st)) goto done;
    }
    prompts[0] = v[0].prompt;
    mx_job_set_phase(j, "grid");
    mx_job_progress(j, "stage grid: front+back, %dx%d, depth weight %.2f", W, S, o->pub.grid_depth_weight);
    mx_gen_batch b = {.n = 1,
                      .image_h = S,
                      .image_w = W,
                      .prompts = prompts,
                      .depth_planes = planes,
                      .w_depth = o->pub.grid_depth_weight,
                      .first_stream = 0,
                      .stage = "grid"};
    if (mx_job_generate(j, &b, image, st)) goto done;
    for (int i = 0; i < 2; i++) {
        if (mx_job_backproject(j, &v[i], image, W, i * S, st)) goto done;
        mx_job_report_view(j, &v[i], "grid", 0, o->pub.grid_depth_weight, 0.0f);
    }
    mx_job_progress(j, "stage grid done: coverage %.4f (candidates %.4f)", mx_job_coverage(j),
                    mx_job_candidate_coverage(j));
    mx_job_stage_done(j, "grid", mx_now() - t);
    rc = 0;
done:
    free_views(v, 2);
    free(planes);
    free(image);
    return rc;
}

static float lerp_schedule(const float w[2], int k, int n) {
    float t = n > 1 ? (float)k / (float)(n - 1) : 0.0f;
    return w[0] + t * (w[1] - w[0]);
}

/* Buffers of one batch of n views at model size S. */
typedef struct batch_buffers {
    float *depth, *inpaint, *init, *paint, *image, *wd, *wi;
    const char **prompts;
} batch_buffers;

static void batch_free(batch_buffers *bb) {
    free(bb->depth);
    free(bb->wd);
    free(bb->prompts);
}

static int batch_alloc(batch_buffers *bb, int n, int S, mx_status *st) {
    size_t per = (size_t)3 * S * S, one = (size_t)S * S;
    bb->depth = malloc(sizeof(float) * (4 * per + one) * n);
    bb->wd = malloc(sizeof(float) * 2 * n);
    bb->prompts = calloc((size_t)n, sizeof *bb->prompts);
    if (!bb->depth || !bb->wd || !bb->prompts) {
        batch_free(bb);
        return mx_fail(st, MX_ENOMEM, "views: out of memory");
    }
    bb->inpaint = bb->depth + per * n;
    bb->init = bb->inpaint + per * n;
    bb->image = bb->init + per * n;
    bb->paint = bb->image + per * n;
    bb->wi = bb->wd + n;
    return 0;
}

/* One batch of later views: the inpaint pipeline with depth + inpainting control (each view
 * its own weights, by its order k + i among the later views), then backprojection. */
static int view_batch(mx_job *j, const int *cand, int n, int k, int n_later, int batch_id, mx_status *st) {
    const mx_texture_opts *o = j->o;
    int S = o->pub.image_size, rc = -1;
    size_t per = (size_t)3 * S * S;
    batch_buffers bb;
    mx_job_view *v = calloc((size_t)n, sizeof *v);
    mx_image *current = calloc((size_t)j->nlayers, sizeof *current);
    int have_current = 0;
    memset(&bb, 0, sizeof bb);
    if (!v || !current) {
        mx_fail(st, MX_ENOMEM, "views: out of memory");
        goto done;
    }
    if (batch_alloc(&bb, n, S, st)) goto done;
    /* the views of a batch all see T as it is before the batch */
    double t = mx_now();
    if (mx_job_current_textures(j, current, st)) goto done;
    have_current = 1;
    mx_job_work_since(j, MX_WORK_CONTROLS, t);
    char stage[32];
    snprintf(stage, sizeof stage, "views %d-%d", k + 3, k + 2 + n);
    mx_job_set_phase(j, stage);
    for (int i = 0; i < n; i++) {
        v[i].cam = j->sched.vc.cams[cand[i]];
        mx_job_view_prompt(j, &v[i], 0);
        bb.prompts[i] = v[i].prompt;
        bb.wd[i] = lerp_schedule(o->pub.depth_weight, k + i, n_later);
        bb.wi[i] = lerp_schedule(o->pub.inpaint_weight, k + i, n_later);
        mx_view_planes vp = {.depth = bb.depth + i * per,
                             .inpaint = bb.inpaint + i * per,
                             .init = bb.init + i * per,
                             .paint = bb.paint + i * per / 3,
                             .plane_w = S,
                             .x0 = 0};
        if (mx_job_view_prepare(j, &v[i], st) || mx_job_view_controls(j, &v[i], &vp, current, st)) goto done;
        mx_job_progress(j, "view %d/%d: azimuth %.0f, elevation %.0f (%s), %lld untextured pixels", k + i + 3, o->pub.views,
                        v[i].cam.azimuth, v[i].cam.elevation, mx_camera_view_word(&v[i].cam),
                        (long long)v[i].untextured_pixels);
    }
    mx_gen_batch b = {.n = n,
                      .image_h = S,
                      .image_w = S,
                      .prompts = bb.prompts,
                      .depth_planes = bb.depth,
                      .inpaint_planes = bb.inpaint,
                      .w_depth = bb.wd[0],
                      .w_inpaint = bb.wi[0],
                      .w_depth_items = bb.wd,
                      .w_inpaint_items = bb.wi,
                      .init_images = bb.init,
                      .paint_masks = bb.paint,
                      .strength = 1.0f,
                      .first_stream = (uint64_t)(k + 1),
                      .stage = stage};
    if (mx_job_generate(j, &b, bb.image, st)) goto done;
    for (int i = 0; i < n; i++) {
        if (mx_job_backproject(j, &v[i], bb.image + i * per, S, 0, st)) goto done;
        mx_job_report_view(j, &v[i], "inpaint", batch_id, bb.wd[i], bb.wi[i]);
    }
    rc = 0;
done:
    if (v) free_views(v, n);
    for (int l = 0; have_current && l < j->nlayers; l++) mx_image_free(&current[l]);
    free(current);
    free(v);
    batch_free(&bb);
    return rc;
}

/* Stage 1 (paper §3.2, Alg. 1): the views the schedule picks from the real T^B, a batch at a
 * time (views that overlap by at most MX_VIEW_GROUP_OVERLAP of their untextured texels, views.h,
 * are generated together). */
static int view_stage(mx_job *j, mx_status *st) {
    const mx_texture_opts *o = j->o;
    double t = mx_now();
    int max_batch = o->pub.batch > 0 ? o->pub.batch : 1, n_later = o->pub.views - 2, k = 0, batch_id = 1, n = 0;
    int *cand = malloc(sizeof(int) * (size_t)max_batch);
    if (!cand) return mx_fail(st, MX_ENOMEM, "views: out of memory");
    int rc = mx_job_schedule_begin(j, max_batch, st);
    while (!rc && !(rc = mx_job_check_cancel(j, st)) && !(rc = mx_job_schedule_next(j, cand, &n, st)) && n > 0) {
        rc = view_batch(j, cand, n, k, n_later, batch_id++, st);
        k += n;
        if (!rc)
            mx_job_progress(j, "coverage after %d views: %.4f (candidates %.4f)", k + 2, mx_job_coverage(j),
                            mx_job_candidate_coverage(j));
    }
    free(cand);
    if (rc) return -1;
    mx_job_stage_done(j, "views", mx_now() - t);
    return 0;
}

/* Stage 2 (paper §3, post-processing): the texels no view reached are filled in UV space
 * (mx_job_finish), then the outputs. */
static int fill_stage(mx_job *j, mx_texture_result *res, mx_status *st) {
    mx_image tex[j->nlayers];
    double t = mx_now();
    if (mx_job_current_textures(j, tex, st)) return -1;
    mx_job_work_since(j, MX_WORK_FILL, t);
    int rc = mx_job_finish(j, tex, res, st);
    for (int l = 0; l < j->nlayers; l++) mx_image_free(&tex[l]);
    return rc;
}

int mx_texture_run(const mx_texture_opts *o, mx_texture_result *res, mx_status *st) {
    if (mx_texture_opts_check(o, MX_VERB_TEXTURE, st)) return -1;
    mx_job j;
    int rc = mx_job_open(&j, o, MX_MODELS_NEED_DEPTH | (o->pub.views > 2 ? MX_MODELS_NEED_INPAINT : 0), MX_VERB_TEXTURE, st);
    if (!rc) rc = mx_job_check_cancel(&j, st) || grid_stage(&j, st) ? -1 : 0;
    if (!rc) rc = view_stage(&j, st);
    if (!rc) rc = fill_stage(&j, res, st);
    mx_job_close(&j);
    return rc;
}
