/* The views of a job: candidates and the texels they see, the schedule, each view's cameras, renders,
 * crop and prompt, and backprojection into T^B (job_views.c). Internal to pipeline/texture. */
#ifndef MX_JOB_VIEWS_H
#define MX_JOB_VIEWS_H

#include <stdint.h>

#include "../geom/backproject.h"
#include "../geom/camera.h"
#include "../geom/views.h"

/* The gain floor: a candidate with fewer untextured pixels (at the candidate render size, 256)
 * is not worth a view, and the schedule ends. */
#define MX_JOB_MIN_UNTEXTURED_PIXELS 16

/* mx_job (job.h) as its stages see it. */
typedef struct mx_job mx_job;

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

/* One view of a batch: its camera, prompt word, renders and crop. */
typedef struct mx_job_view {
    mx_camera cam;
    char prompt[1200];
    mx_view_buffers vb;
    int vb_ready;
    mx_crop crop;
    int64_t untextured_pixels; /* visible pixels still to paint (all foreground pixels before any paint) */
} mx_job_view;

/* The orthographic camera every view uses, at (azimuth, elevation) degrees. */
void mx_job_camera(mx_camera *cam, float azimuth, float elevation);
/* The candidate views (a Fibonacci sphere of o->pub.candidates cameras) and the texels they see;
 * the texels of the mesh (inside a face in UV space), what coverage is measured against. */
int mx_job_build_candidates(mx_job *j, mx_status *st);
int mx_job_build_chart(mx_job *j, mx_status *st);
/* Renders the view (culled + unculled, backprojection mask) and its object crop. */
int mx_job_view_prepare(mx_job *j, mx_job_view *v, mx_status *st);
void mx_job_view_free(mx_job_view *v);
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
#endif
