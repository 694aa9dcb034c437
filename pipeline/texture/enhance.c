/* `matex enhance` (paper §4.4, texture enhancement): SDEdit over views of a textured mesh.
 * Views: front and back, then the candidates Algorithm 1 picks over the whole texture, with
 * the texels front and back will reach already counted as painted. The views run one after
 * the other on the texture as enhanced so far (the original where no view has been): each
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

/* Marks in `known` the texels under the backprojection mask of a prepared view. */
static void mark_view_texels(const mx_job *j, const mx_job_view *v, uint8_t *known) {
    const mx_gbuffer *gb = &v->vb.gb;
    size_t plane = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    for (size_t i = 0; i < (size_t)gb->w * gb->h; i++)
        if (v->vb.mask[i] && isfinite(gb->uv[2 * i]) && isfinite(gb->uv[2 * i + 1]))
            known[(size_t)mx_face_layer(&j->mesh, gb->face[i], j->nlayers) * plane +
                  (size_t)mx_uv_texel(gb->uv[2 * i], gb->uv[2 * i + 1], j->o->pub.texture_size, j->o->pub.texture_size)] = 1;
}

/* Cameras: front, back, then the plan of Algorithm 1 over the whole texture, front and back
 * counted as painted. */
static int enhance_cameras(mx_job *j, mx_camera *cams, int *n, mx_status *st) {
    mx_job_camera(&cams[0], 0.0f, 0.0f);
    mx_job_camera(&cams[1], 180.0f, 0.0f);
    *n = 2;
    if (j->o->pub.views <= 2) return 0;
    uint8_t *sim = calloc((size_t)j->nlayers * j->o->pub.texture_size * j->o->pub.texture_size, 1);
    if (!sim) return mx_fail(st, MX_ENOMEM, "enhance: out of memory");
    int rc = 0;
    for (int k = 0; k < 2 && !rc; k++) {
        mx_job_view v;
        memset(&v, 0, sizeof v);
        v.cam = cams[k];
        rc = mx_job_view_prepare(j, &v, st);
        if (!rc) mark_view_texels(j, &v, sim);
        mx_job_view_free(&v);
    }
    mx_view_plan plan;
    if (rc || mx_view_plan_make(&j->vc, sim, j->o->pub.views - 2, j->o->pub.coverage_stop, MX_JOB_MIN_UNTEXTURED_PIXELS,
                                &plan, st)) {
        free(sim);
        return -1;
    }
    for (int i = 0; i < plan.n && *n < j->o->pub.views; i++) cams[(*n)++] = j->vc.cams[plan.cand[i]];
    mx_view_plan_free(&plan);
    free(sim);
    return 0;
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
    snprintf(v->prompt, sizeof v->prompt, "%s view of %s", mx_camera_view_word(&v->cam), o->pub.prompt);
    mx_view_planes vp = {depth, inpaint, init, paint, S, 0};
    if (merge_textures(j, orig, current, st)) goto done;
    merged = 1;
    if (mx_job_view_prepare(j, v, st) || mx_job_view_controls(j, v, &vp, current, st)) goto done;
    const char *prompts[1] = {v->prompt};
    char stage[32];
    snprintf(stage, sizeof stage, "enhance view %d", index + 1);
    mx_gen_batch b = {1,     S,     S, prompts, depth, NULL, o->pub.depth_weight[0], 0.0f, NULL, NULL, init,
                      paint, o->pub.strength, (uint64_t)index, stage};
    if (mx_job_generate(j, &b, image, st) || mx_job_backproject(j, v, image, S, 0, st)) goto done;
    mx_job_report_view(j, v, "enhance", index, j->models->cn_depth ? o->pub.depth_weight[0] : 0.0f, 0.0f);
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

int mx_enhance_run(const mx_texture_opts *o, mx_texture_result *res, mx_status *st) {
    if (mx_texture_opts_check(o, MX_TEXTURE_MODE_ENHANCE, st)) return -1;
    mx_job j;
    int rc = mx_job_open(&j, o, 0, 1, st);
    mx_image *orig = NULL, *out = NULL;
    mx_camera *cams = NULL;
    int ncam = 0;
    if (!rc) {
        orig = calloc((size_t)j.nlayers, sizeof *orig);
        out = calloc((size_t)j.nlayers, sizeof *out);
        cams = calloc((size_t)(o->pub.views > 2 ? o->pub.views : 2), sizeof *cams);
        if (!orig || !out || !cams) rc = mx_fail(st, MX_ENOMEM, "enhance: out of memory");
    }
    j.keep_unreached = 1;
    j.write_flags = 0; /* the first enhanced view of a texel keeps it: later views blend it in */
    if (!rc) rc = original_textures(&j, orig, st);
    if (!rc) rc = enhance_cameras(&j, cams, &ncam, st);
    double t = mx_now();
    for (int i = 0; !rc && i < ncam && i < o->pub.views; i++) {
        if ((rc = mx_job_check_cancel(&j, st))) break;
        mx_job_view v;
        memset(&v, 0, sizeof v);
        v.cam = cams[i];
        rc = enhance_view(&j, orig, &v, i, st);
        mx_job_view_free(&v);
    }
    if (!rc) {
        mx_job_stage_done(&j, "views", mx_now() - t);
        rc = merge_textures(&j, orig, out, st);
    }
    if (!rc) rc = mx_job_finish(&j, out, res, st);
    for (int l = 0; orig && l < j.nlayers; l++) mx_image_free(&orig[l]);
    for (int l = 0; out && l < j.nlayers; l++) mx_image_free(&out[l]);
    free(orig);
    free(out);
    free(cams);
    mx_job_close(&j);
    return rc;
}
