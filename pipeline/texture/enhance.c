/* `matex enhance` (paper §4.4, texture enhancement): SDEdit over views of a textured mesh.
 * Views: front and back, then the view schedule (Alg. 1, views.h) one view at a time from the
 * texels enhanced so far. The views run one after the other on the texture as enhanced so far
 * (the original where no view has been): each
 * view's render is the init image of the inpaint pipeline at `strength` (noised to strength,
 * SDEdit), the pixels of texels an earlier view already enhanced are the known region put back
 * after every step (latent blending), so each view continues its neighbours at the border;
 * the rest is repainted and backprojected. Texels that no view reached keep the original. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../geom/backproject.h"
#include "../geom/masks.h"
#include "../geom/raster.h"
#include "../io/mesh_load.h"
#include "condition.h"
#include "job.h"
#include "texture.h"

/* Copies of the textures given in memory (one per material). */
static int copy_textures(const mx_image *in, mx_image *out, int n, mx_status *st) {
    for (int i = 0; i < n; i++) {
        if (!in[i].data) continue;
        if (mx_image_alloc(&out[i], in[i].w, in[i].h, in[i].c, st)) return -1;
        memcpy(out[i].data, in[i].data, sizeof(float) * (size_t)in[i].w * in[i].h * in[i].c);
    }
    return 0;
}

/* The original textures resampled to the bake's size, one per layer (grey where missing). */
static int original_textures(mx_job *j, mx_image *out, mx_status *st) {
    int T = j->o->pub.texture_size, nm = j->mesh.nmat > 0 ? j->mesh.nmat : 1;
    mx_image *src = calloc((size_t)nm, sizeof *src);
    if (!src) return mx_fail(st, MX_ENOMEM, "textures: out of memory");
    int rc = j->o->mesh_textures ? copy_textures(j->o->mesh_textures, src, nm, st)
             : j->mesh.nmat > 0  ? mx_mesh_load_textures(&j->mesh, src, st)
                                 : 0;
    int have = 0;
    for (int l = 0; !rc && l < j->nlayers; l++) {
        if ((rc = mx_image_alloc(&out[l], T, T, 3, st))) break;
        const mx_image *s = l < nm ? &src[l] : NULL;
        have += s && s->data;
        for (int y = 0; y < T; y++)
            for (int x = 0; x < T; x++) {
                float rgba[4] = {0.5f, 0.5f, 0.5f, 1.0f}, *d = out[l].data + ((size_t)y * T + x) * 3;
                if (s && s->data) mx_texture_sample(s, (x + 0.5f) / T, 1.0f - (y + 0.5f) / T, rgba);
                if (s && s->data && s->c < 3) rgba[1] = rgba[2] = rgba[0];
                memcpy(d, rgba, 3 * sizeof(float));
            }
    }
    for (int i = 0; i < nm; i++) mx_image_free(&src[i]);
    free(src);
    if (!rc && !have) rc = mx_fail(st, MX_EINPUT, "%s: the mesh has no texture to enhance", j->mesh.source_path);
    return rc;
}

static int merge_textures(mx_job *j, const mx_image *orig, mx_image *out, mx_status *st);

/* One view on the texture enhanced so far: SDEdit of its render with the already enhanced
 * pixels kept (latent blending), backprojected into the texels not enhanced yet. */
static int enhance_view(mx_job *j, const mx_image *orig, mx_job_view *v, int index, mx_status *st) {
    const mx_texture_opts *o = j->o;
    int S = o->pub.image_size, rc = -1, merged = 0;
    size_t per = (size_t)3 * S * S;
    float *buf = malloc(sizeof(float) * (4 * per + (size_t)S * S));
    mx_image *current = calloc((size_t)j->nlayers, sizeof *current);
    if (!buf || !current) {
        mx_fail(st, MX_ENOMEM, "enhance: out of memory");
        goto done;
    }
    float *depth = buf, *inpaint = buf + per, *init = buf + 2 * per, *image = buf + 3 * per, *paint = buf + 4 * per;
    mx_job_view_prompt(j, v, 0);
    mx_view_planes vp = {.depth = depth, .inpaint = inpaint, .init = init, .paint = paint, .plane_w = S, .x0 = 0};
    double t = mx_now();
    if (merge_textures(j, orig, current, st)) goto done;
    merged = 1;
    mx_job_work_since(j, MX_WORK_CONTROLS, t);
    if (mx_job_view_prepare(j, v, st) || mx_job_view_controls(j, v, &vp, current, st)) goto done;
    const char *prompts[1] = {v->prompt};
    char stage[32];
    snprintf(stage, sizeof stage, "enhance view %d", index + 1);
    mx_gen_batch b = {.n = 1,
                      .image_h = S,
                      .image_w = S,
                      .prompts = prompts,
                      .depth_planes = depth,
                      .w_depth = o->pub.depth_weight[0],
                      .init_images = init,
                      .paint_masks = paint,
                      .strength = o->pub.strength,
                      .first_stream = (uint64_t)index,
                      .stage = stage};
    if (mx_job_generate(j, &b, image, st) || mx_job_backproject(j, v, image, S, 0, st)) goto done;
    mx_job_report_view(j, v, "enhance", index, j->gen.models->cn_depth ? o->pub.depth_weight[0] : 0.0f, 0.0f);
    rc = 0;
done:
    for (int l = 0; merged && l < j->nlayers; l++) mx_image_free(&current[l]);
    free(current);
    free(buf);
    return rc;
}

/* Final textures: enhanced texels where a view reached them, the original elsewhere. */
static int merge_textures(mx_job *j, const mx_image *orig, mx_image *out, mx_status *st) {
    if (mx_job_current_textures(j, out, st)) return -1;
    size_t T2 = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    for (int l = 0; l < j->nlayers; l++)
        for (size_t i = 0; i < T2; i++)
            if (!j->bake.known[l * T2 + i]) memcpy(out[l].data + 3 * i, orig[l].data + 3 * i, 3 * sizeof(float));
    return 0;
}

/* One view at (azimuth, elevation) of cam, as enhance_view. */
static int enhance_camera(mx_job *j, const mx_image *orig, const mx_camera *cam, int index, mx_status *st) {
    mx_job_view v;
    memset(&v, 0, sizeof v);
    v.cam = *cam;
    int rc = mx_job_check_cancel(j, st) || enhance_view(j, orig, &v, index, st);
    mx_job_view_free(&v);
    return rc ? -1 : 0;
}

/* Front and back, then the schedule (views.h) one view at a time from the texels enhanced so
 * far: each view sees the ones before it. */
static int enhance_views(mx_job *j, const mx_image *orig, mx_status *st) {
    double t = mx_now();
    mx_camera cam;
    int index = 0, cand = 0, n = 0;
    for (int k = 0; k < 2 && k < j->o->pub.views; k++) {
        mx_job_camera(&cam, k ? 180.0f : 0.0f, 0.0f);
        if (enhance_camera(j, orig, &cam, index++, st)) return -1;
    }
    if (mx_job_schedule_begin(j, 1, st)) return -1;
    while (1) {
        if (mx_job_schedule_next(j, &cand, &n, st)) return -1;
        if (n == 0) break;
        if (enhance_camera(j, orig, &j->sched.vc.cams[cand], index++, st)) return -1;
    }
    mx_job_stage_done(j, "views", mx_now() - t);
    return 0;
}

int mx_enhance_run(const mx_texture_opts *o, mx_texture_result *res, mx_status *st) {
    if (mx_texture_opts_check(o, MX_VERB_ENHANCE, st)) return -1;
    mx_job j;
    int rc = mx_job_open(&j, o, 0, MX_VERB_ENHANCE, st);
    mx_image *orig = NULL, *out = NULL;
    if (!rc) {
        orig = calloc((size_t)j.nlayers, sizeof *orig);
        out = calloc((size_t)j.nlayers, sizeof *out);
        if (!orig || !out) rc = mx_fail(st, MX_ENOMEM, "enhance: out of memory");
    }
    j.keep_unreached = 1;
    j.write_flags = 0; /* the first enhanced view of a texel keeps it: later views blend it in */
    if (!rc) rc = original_textures(&j, orig, st);
    if (!rc) rc = enhance_views(&j, orig, st);
    double t = mx_now();
    if (!rc && !(rc = merge_textures(&j, orig, out, st))) mx_job_work_since(&j, MX_WORK_FILL, t);
    if (!rc) rc = mx_job_finish(&j, out, res, st);
    for (int l = 0; orig && l < j.nlayers; l++) mx_image_free(&orig[l]);
    for (int l = 0; out && l < j.nlayers; l++) mx_image_free(&out[l]);
    free(orig);
    free(out);
    mx_job_close(&j);
    return rc;
}
