/* The views of a job: candidates and the texels they see, cameras, the schedule, each view's
 * renders and prompt, and backprojection into T^B (job_views.h). */
#include "job.h"

#include <stdio.h>
#include <stdlib.h>

#include "../../runtime/log.h"
#include "../geom/masks.h"
#include "condition.h"
#include "../geom/uvfill.h"

#define CANDIDATE_RENDER_SIZE 256
#define CAMERA_RADIUS 3.0f
#define CAMERA_HALF_EXTENT 1.02f /* the normalised mesh lies in the unit sphere */
#define CROP_MARGIN 0.05f

void mx_job_camera(mx_camera *cam, float azimuth, float elevation) {
    mx_camera_ortho(cam, azimuth, elevation, CAMERA_RADIUS, CAMERA_HALF_EXTENT);
}

int mx_job_build_candidates(mx_job *j, mx_status *st) {
    double t = mx_now();
    int n = j->o->pub.candidates;
    mx_camera tmpl, *cams = calloc((size_t)n, sizeof *cams);
    if (!cams) return mx_fail(st, MX_ENOMEM, "candidate cameras: out of memory");
    mx_job_camera(&tmpl, 0.0f, 0.0f);
    mx_camera_fibonacci(cams, n, &tmpl);
    int rc = mx_view_cache_build(&j->sched.vc, &j->mesh, j->pos, cams, n, CANDIDATE_RENDER_SIZE, j->o->pub.texture_size,
                                 j->o->pub.texture_size, j->nlayers, mx_texture_opts_normals(j->o), j->o->pub.frontal_threshold,
                                 mx_view_scale_radius(mx_view_erode_radius(j->o->pub.render_size, j->o->pub.image_size),
                                                      j->o->pub.render_size, CANDIDATE_RENDER_SIZE),
                                 j->gen.ctx->pool, st);
    free(cams);
    if (rc) return -1;
    j->sched.vc_ready = 1;
    size_t texels = (size_t)j->nlayers * j->o->pub.texture_size * j->o->pub.texture_size;
    j->sched.visible = calloc(texels, 1);
    if (!j->sched.visible) return mx_fail(st, MX_ENOMEM, "visibility mask: out of memory");
    mx_view_cache_visible(&j->sched.vc, j->sched.visible);
    j->sched.n_visible = mx_mask_count(j->sched.visible, (int64_t)texels);
    mx_job_work_since(j, MX_WORK_CANDIDATES, t);
    if (j->sched.n_visible == 0)
        return mx_fail(st, MX_EINPUT, "%s: no view sees any texel of the mesh (are all its faces of zero area?)",
                       j->o->pub.mesh_path);
    return 0;
}

/* The texels of the mesh (inside a face in UV space), what coverage is measured against. */
int mx_job_build_chart(mx_job *j, mx_status *st) {
    size_t plane = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    j->sched.chart = malloc(plane * (size_t)j->nlayers);
    if (!j->sched.chart) return mx_fail(st, MX_ENOMEM, "chart mask: out of memory");
    for (int l = 0; l < j->nlayers; l++)
        if (mx_uv_chart_mask(&j->mesh, l, j->nlayers, j->o->pub.texture_size, j->o->pub.texture_size, j->sched.chart + l * plane, st))
            return -1;
    j->sched.n_chart = mx_mask_count(j->sched.chart, (int64_t)(plane * (size_t)j->nlayers));
    return 0;
}

int mx_job_view_prepare(mx_job *j, mx_job_view *v, mx_status *st) {
    double t = mx_now();
    int R = j->o->pub.render_size;
    if (mx_view_buffers_init(&v->vb, R, st)) return -1;
    v->vb_ready = 1;
    if (mx_view_prepare(&v->vb, &j->mesh, j->pos, &v->cam, mx_texture_opts_normals(j->o), j->o->pub.frontal_threshold, j->gen.ctx->pool,
                        st) ||
        mx_view_erode_edges(&v->vb, mx_view_erode_radius(R, j->o->pub.image_size), st))
        return -1;
    uint8_t *fg = malloc((size_t)R * R);
    if (!fg) return mx_fail(st, MX_ENOMEM, "view mask: out of memory");
    mx_mask_foreground(&v->vb.gb, fg);
    v->crop = mx_crop_from_mask(fg, R, R, CROP_MARGIN);
    v->untextured_pixels = mx_mask_count(fg, (int64_t)R * R);
    free(fg);
    mx_job_work_since(j, MX_WORK_RENDER, t);
    return 0;
}

void mx_job_view_free(mx_job_view *v) {
    if (v->vb_ready) mx_view_buffers_free(&v->vb);
    v->vb_ready = 0;
}

void mx_job_view_prompt(const mx_job *j, mx_job_view *v, int grid) {
    const char *prompt = j->o->pub.prompt ? j->o->pub.prompt : "";
    if (grid)
        snprintf(v->prompt, sizeof v->prompt, "%s %s", j->o->pub.front_back_words, prompt);
    else if (j->gen.models)
        snprintf(v->prompt, sizeof v->prompt, "%s view of %s", mx_camera_view_word(&v->cam), prompt);
    else /* transfer: no prompt, the view word names the view in the report */
        snprintf(v->prompt, sizeof v->prompt, "%s view", mx_camera_view_word(&v->cam));
}

int mx_job_schedule_begin(mx_job *j, int max_batch, mx_status *st) {
    double t = mx_now();
    mx_view_schedule_params p = {.budget = j->o->pub.views - 2,
                                 .max_batch = max_batch,
                                 .coverage_stop = j->o->pub.coverage_stop,
                                 .min_gain = MX_JOB_MIN_UNTEXTURED_PIXELS};
    if (mx_view_schedule_init(&j->sched.schedule, &j->sched.vc, &p, st)) return -1;
    j->sched.schedule_ready = 1;
    mx_job_work_since(j, MX_WORK_SELECT, t);
    return 0;
}

int mx_job_schedule_next(mx_job *j, int *cand, int *n, mx_status *st) {
    double t = mx_now();
    if (mx_view_schedule_next(&j->sched.schedule, j->bake.known, cand, n, st)) return -1;
    mx_job_work_since(j, MX_WORK_SELECT, t);
    if (*n == 0)
        mx_job_progress(j, "view selection: schedule ended after %d views (budget, coverage or gain floor)",
                        j->rep.views_done);
    return 0;
}

int mx_job_backproject(mx_job *j, mx_job_view *v, const float *planes, int plane_w, int x0, mx_status *st) {
    int R = j->o->pub.render_size, S = j->o->pub.image_size;
    double t = mx_now();
    mx_image gen, canvas;
    if (mx_planes_to_image(planes, 3, S, plane_w, x0, S, &gen, st)) return -1;
    if (mx_image_alloc(&canvas, R, R, 3, st)) {
        mx_image_free(&gen);
        return -1;
    }
    mx_crop_paste(&gen, v->crop, j->gen.ctx->pool, &canvas);
    mx_job_work_since(j, MX_WORK_BACKPROJECT, t); /* mx_job_backproject_render adds its own time */
    int rc = mx_job_backproject_render(j, v, &canvas, v->vb.mask, st);
    mx_image_free(&gen);
    mx_image_free(&canvas);
    return rc;
}

int mx_job_backproject_render(mx_job *j, mx_job_view *v, const mx_image *img, const uint8_t *mask, mx_status *st) {
    double t = mx_now();
    int rc = mx_backproject(&j->bake, &v->vb.gb, &j->mesh, img, mask, j->write_flags, j->gen.ctx->pool, st);
    mx_job_work_since(j, MX_WORK_BACKPROJECT, t);
    if (rc) return -1;
    j->rep.views_done++;
    j->rep.coverage = mx_job_coverage(j);
    mx_job_emit_progress(j, 0, 0, "view backprojected");
    return 0;
}
