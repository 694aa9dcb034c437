/* The end of a job: the fill of unreached texels, the output folder and the in-memory result
 * (job_output.h). */
#include "job.h"

#include <stdlib.h>
#include <string.h>

#include "../../runtime/fileio.h"
#include "../../runtime/log.h"
#include "../geom/raster.h"
#include "../geom/uvfill.h"
#include "../io/export.h"
#include "../io/io.h"

#define UV_GUTTER 4

/* What the fill of one texture reports: a progress line at most every FILL_TICK_S seconds, and the
 * cancel flag at every tick. */
#define FILL_TICK_S 2.0
typedef struct {
    mx_job *j;
    int layer;
    double last;
} fill_ticks;

static int fill_tick(void *user, double done) {
    fill_ticks *f = user;
    if (mx_now() - f->last >= FILL_TICK_S) {
        mx_job_progress(f->j, "uv fill: texture %d/%d, solve %.0f%%", f->layer + 1, f->j->nlayers, 100 * done);
        f->last = mx_now();
    }
    mx_status ignored;
    return mx_job_check_cancel(f->j, &ignored) != 0;
}

/* Harmonic fill across UV seams of every layer's unreached chart texels, gutter dilation. */
int mx_job_fill_textures(mx_job *j, mx_image *tex, mx_status *st) {
    size_t plane = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    for (int l = 0; l < j->nlayers; l++) {
        double t = mx_now();
        int64_t open = 0;
        for (size_t i = 0; i < plane; i++) open += j->sched.chart[l * plane + i] && !j->bake.known[l * plane + i];
        mx_job_progress(j, "uv fill: texture %d/%d, %lld texels to fill (%dx%d)", l + 1, j->nlayers, (long long)open,
                        j->o->pub.texture_size, j->o->pub.texture_size);
        fill_ticks ticks = {.j = j, .layer = l, .last = t};
        mx_uv_fill_ticker ticker = {.tick = fill_tick, .user = &ticks};
        if (mx_uv_fill_harmonic(&tex[l], j->bake.known + l * plane, &j->mesh, l, j->nlayers, UV_GUTTER, &ticker, st))
            return -1;
        mx_job_work_since(j, MX_WORK_FILL, t);
        mx_job_progress(j, "uv fill: texture %d/%d done in %.1fs", l + 1, j->nlayers, mx_now() - t);
        if (mx_job_check_cancel(j, st)) return -1;
    }
    return 0;
}

/* The in-memory result: its containers are allocated before the folder is published, and the
 * textures, mesh and report are moved in after it, so that nothing can fail once the output exists. */
static int result_reserve(const mx_job *j, const char *report, mx_texture_result *res, mx_status *st) {
    size_t view_bytes = res->view_bytes;
    memset(res, 0, sizeof *res);
    res->view_bytes = view_bytes;
    if (!j->o->keep_outputs) return 0;
    res->textures = calloc((size_t)j->nlayers, sizeof *res->textures);
    res->report_json = strdup(report);
    if (view_bytes) res->views_room = calloc((size_t)j->nlayers, view_bytes);
    if (!res->textures || !res->report_json || (view_bytes && !res->views_room)) {
        mx_texture_result_free(res);
        return mx_fail(st, MX_ENOMEM, "result: out of memory");
    }
    return 0;
}

static void result_fill(mx_job *j, mx_image *tex, mx_texture_result *res) {
    res->coverage = mx_job_coverage(j);
    res->candidate_coverage = mx_job_candidate_coverage(j);
    res->views = j->rep.views_done;
    res->seconds = mx_now() - j->rep.t0;
    if (!j->o->keep_outputs) return;
    res->ntex = j->nlayers;
    for (int l = 0; l < j->nlayers; l++) {
        res->textures[l] = tex[l];
        memset(&tex[l], 0, sizeof tex[l]);
    }
    res->mesh = j->mesh;
    memset(&j->mesh, 0, sizeof j->mesh);
}

/* front.png in the staging folder: the textured mesh from the front, cropped to the object as a view
 * is, image_size pixels on the views' grey (what `matex batch --theme-from-first` passes on). */
static int write_front_render(mx_job *j, const mx_image *tex, mx_status *st) {
    mx_job_view v;
    memset(&v, 0, sizeof v);
    mx_job_camera(&v.cam, 0.0f, 0.0f);
    mx_image rgb = {0}, small = {0};
    char path[4300];
    int rc = mx_job_view_prepare(j, &v, st) ||
             mx_render_textured(&v.vb.gb, &j->mesh, tex, j->nlayers, mx_job_grey, j->gen.ctx->pool, &rgb, st) ||
             mx_crop_resize(&rgb, v.crop, j->o->pub.image_size, j->gen.ctx->pool, &small, st) ||
             mx_path_join(path, sizeof path, j->out.stage, "front.png", st) || mx_io_write_png(path, &small, st);
    mx_image_free(&rgb);
    mx_image_free(&small);
    mx_job_view_free(&v);
    return rc ? -1 : 0;
}

/* The output files but the report into the staging folder (timed: the report's work_s.write). */
static int write_files(mx_job *j, const mx_image *tex, mx_status *st) {
    if (j->o->pub.front_render && write_front_render(j, tex, st)) return -1;
    double t = mx_now();
    if (mx_write_output_files(j->out.stage, &j->mesh, tex, j->nlayers, mx_pool_threads(j->gen.ctx->pool), st)) return -1;
    mx_job_work_since(j, MX_WORK_WRITE, t);
    return 0;
}

int mx_job_finish(mx_job *j, mx_image *tex, mx_texture_result *res, mx_status *st) {
    double t = mx_now();
    mx_job_set_phase(j, "finish");
    if (mx_job_check_cancel(j, st) || (!j->keep_unreached && mx_job_fill_textures(j, tex, st))) return -1;
    mx_job_stage_done(j, "uv_fill", mx_now() - t);
    if (mx_job_check_cancel(j, st) || (j->o->pub.out_dir && write_files(j, tex, st))) return -1;
    const char *text = mx_job_report_end(j);
    if (!text) return mx_fail(st, MX_ENOMEM, "report: out of memory");
    if (res && result_reserve(j, text, res, st)) return -1;
    if (j->o->pub.out_dir && (mx_write_report(j->out.stage, text, st) || mx_outdir_publish(&j->out, j->o->pub.cancel, st))) {
        if (res) mx_texture_result_free(res);
        return -1;
    }
    if (j->o->pub.out_dir)
        mx_job_progress(j, "wrote %s (coverage %.4f of the mesh's texels, %.4f of the candidates', %d views)",
                        j->o->pub.out_dir, mx_job_coverage(j), mx_job_candidate_coverage(j), j->rep.views_done);
    if (res) result_fill(j, tex, res);
    return 0;
}

void mx_texture_result_free(mx_texture_result *res) {
    if (!res) return;
    for (int l = 0; l < res->ntex; l++) mx_image_free(&res->textures[l]);
    free(res->textures);
    free(res->report_json);
    free(res->views_room);
    mx_mesh_free(&res->mesh);
    memset(res, 0, sizeof *res);
}
