/* `matex transfer`: the texture of a textured mesh moves onto another mesh or UV layout, with
 * the job's skeleton and nothing of its own: the destination is the job's mesh (its UVs, or an
 * atlas; its cameras, candidates, bake, fill, coverage, report and output folder), the source
 * is placed in the destination's normalised frame (both share pose and units), rendered with
 * its texture from each view, and backprojected where the destination is visible, frontal
 * enough, not internal, and the source has a surface. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../geom/raster.h"
#include "../io/mesh_load.h"
#include "job.h"
#include "texture.h"

typedef struct source {
    mx_mesh mesh;
    float *pos; /* in the job's frame */
    mx_image *tex; /* [ntex] */
    int ntex;
    mx_gbuffer gb; /* render_size x render_size */
    int gb_ready;
} source;

static void source_free(source *s) {
    for (int k = 0; s->tex && k < s->ntex; k++) mx_image_free(&s->tex[k]);
    free(s->tex);
    free(s->pos);
    if (s->gb_ready) mx_gbuffer_free(&s->gb);
    mx_mesh_free(&s->mesh);
}

/* The source mesh and its textures (before the job: bad input fails at once). */
static int source_load(const mx_texture_opts *o, source *s, mx_status *st) {
    const char *path = o->pub.source_path;
    if (mx_mesh_load(path, &s->mesh, st)) return -1;
    if (!s->mesh.face_uv || s->mesh.nmat < 1)
        return mx_fail(st, MX_EINPUT, "%s: the source has no UVs or no material to take a texture from", path);
    s->ntex = s->mesh.nmat;
    s->tex = calloc((size_t)s->ntex, sizeof *s->tex);
    if (!s->tex) return mx_fail(st, MX_ENOMEM, "transfer: out of memory");
    if (mx_mesh_load_textures(&s->mesh, s->tex, st)) return -1;
    int any = 0;
    for (int k = 0; k < s->ntex; k++) any |= s->tex[k].data != NULL;
    if (!any) return mx_fail(st, MX_EINPUT, "%s: the source has no readable texture", path);
    return 0;
}

/* The source in the job's frame, and its render buffer. */
static int source_place(mx_job *j, source *s, mx_status *st) {
    if (mx_mesh_placed(&s->mesh, mx_texture_opts_up(j->o), j->center, j->scale, &s->pos, st)) return -1;
    if (mx_gbuffer_init(&s->gb, j->o->pub.render_size, j->o->pub.render_size, st)) return -1;
    s->gb_ready = 1;
    return 0;
}

/* One view: the destination's render and mask (mx_job_view_prepare), the source's textured
 * render, backprojected where both are seen. */
/* The render through the model image, as every generated image of the texture job: cropped
 * to the destination's object, resized to image_size, pasted back bilinearly. */
static int through_model_image(const mx_job *j, const mx_job_view *v, mx_image *img, mx_status *st) {
    mx_image small = {0};
    if (mx_crop_resize(img, v->crop, j->o->pub.image_size, j->gen.ctx->pool, &small, st)) return -1;
    memset(img->data, 0, (size_t)img->w * img->h * (size_t)img->c * sizeof *img->data);
    mx_crop_paste(&small, v->crop, j->gen.ctx->pool, img);
    mx_image_free(&small);
    return 0;
}

static int transfer_view(mx_job *j, source *s, const mx_camera *cam, int index, mx_status *st) {
    mx_job_view v;
    memset(&v, 0, sizeof v);
    v.cam = *cam;
    mx_job_view_prompt(j, &v, 0);
    mx_image img = {0};
    int rc = mx_job_view_prepare(j, &v, st);
    double t = mx_now(); /* the source's render: a render of the view */
    rc = rc || mx_rasterize(&s->mesh, s->pos, cam, MX_RASTER_CULL_BACK | MX_RASTER_UV, j->gen.ctx->pool, &s->gb, st) ||
         mx_render_textured(&s->gb, &s->mesh, s->tex, s->ntex, j->o->pub.background, j->gen.ctx->pool, &img, st) ||
         (j->o->pub.through_model_image && through_model_image(j, &v, &img, st));
    mx_job_work_since(j, MX_WORK_RENDER, t);
    if (!rc) {
        for (size_t i = 0; i < (size_t)img.w * img.h; i++) v.vb.mask[i] &= s->gb.face[i] >= 0;
        rc = mx_job_backproject_render(j, &v, &img, v.vb.mask, st);
    }
    if (!rc) mx_job_report_view(j, &v, "transfer", index, 0.0f, 0.0f);
    mx_image_free(&img);
    mx_job_view_free(&v);
    return rc ? -1 : 0;
}

/* Front and back, then the schedule (views.h) one view at a time from the real T^B. */
static int transfer_views(mx_job *j, source *s, mx_status *st) {
    double t = mx_now();
    mx_camera cam;
    int index = 0, cand = 0, n = 0;
    for (int k = 0; k < 2; k++) {
        mx_job_camera(&cam, k ? 180.0f : 0.0f, 0.0f);
        if (mx_job_check_cancel(j, st) || transfer_view(j, s, &cam, index++, st)) return -1;
    }
    if (mx_job_schedule_begin(j, 1, st)) return -1;
    while (1) {
        if (mx_job_check_cancel(j, st) || mx_job_schedule_next(j, &cand, &n, st)) return -1;
        if (n == 0) break;
        if (transfer_view(j, s, &j->sched.vc.cams[cand], index++, st)) return -1;
    }
    mx_job_stage_done(j, "views", mx_now() - t);
    mx_job_progress(j, "transfer: %d views, coverage %.4f (candidates %.4f)", j->rep.views_done, mx_job_coverage(j),
                    mx_job_candidate_coverage(j));
    return 0;
}

/* PSNR of the painted texels against the source's own texture (source and destination are
 * the same file, so the same UVs). */
static double psnr_against_source(const mx_job *j, const source *s, const mx_image *tex) {
    size_t w = (size_t)j->bake.w, plane = w * j->bake.h, n = 0;
    double se = 0;
    for (int l = 0; l < j->nlayers; l++) {
        const mx_image *ref = l < s->ntex ? &s->tex[l] : NULL;
        if (!ref || !ref->data) continue;
        for (size_t i = 0; i < plane; i++) {
            if (!j->bake.known[l * plane + i]) continue;
            float want[4] = {0, 0, 0, 0};
            mx_texture_sample(ref, ((float)(i % w) + 0.5f) / (float)w, 1.0f - ((float)(i / w) + 0.5f) / (float)j->bake.h,
                              want);
            if (ref->c < 3) want[1] = want[2] = want[0];
            for (int c = 0; c < 3; c++) {
                double d = (double)tex[l].data[3 * i + c] - want[c];
                se += d * d;
            }
            n += 3;
        }
    }
    return n ? 10 * log10(1.0 / (se / (double)n + 1e-20)) : 0;
}

static int finish(mx_job *j, const source *s, mx_texture_result *res, mx_status *st) {
    mx_image *tex = calloc((size_t)j->nlayers, sizeof *tex);
    if (!tex) return mx_fail(st, MX_ENOMEM, "transfer: out of memory");
    double t = mx_now();
    int rc = mx_job_current_textures(j, tex, st);
    if (!rc) {
        mx_job_work_since(j, MX_WORK_FILL, t);
        if (j->o->pub.mesh_path && !strcmp(j->o->pub.source_path, j->o->pub.mesh_path)) { /* a mesh in memory: no path */
            j->rep.psnr_db = psnr_against_source(j, s, tex);
            mx_job_progress(j, "transfer onto the source's own UVs: PSNR %.2f dB", j->rep.psnr_db);
        }
        rc = mx_job_finish(j, tex, res, st);
        for (int l = 0; l < j->nlayers; l++) mx_image_free(&tex[l]);
    }
    free(tex);
    return rc;
}

int mx_transfer_run(const mx_texture_opts *o, mx_texture_result *res, mx_status *st) {
    if (mx_texture_opts_check(o, MX_VERB_TRANSFER, st)) return -1;
    mx_job j;
    memset(&j, 0, sizeof j);
    source s;
    memset(&s, 0, sizeof s);
    int rc = source_load(o, &s, st);
    if (!rc) rc = mx_job_open(&j, o, MX_JOB_NO_MODELS, MX_VERB_TRANSFER, st);
    if (!rc) rc = source_place(&j, &s, st);
    if (!rc) rc = transfer_views(&j, &s, st);
    if (!rc) rc = finish(&j, &s, res, st); /* res filled as texture's, in memory too with keep_outputs */
    source_free(&s);
    mx_job_close(&j);
    return rc;
}
