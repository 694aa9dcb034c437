/* The control planes of a view: depth, and the inpainting inputs from the current textures
 * (job_generate.h). */
#include "job.h"

#include <stdlib.h>

#include "../../runtime/log.h"

#include "../geom/masks.h"
#include "../geom/raster.h"
#include "../geom/uvfill.h"
#include "condition.h"

/* I′ (the current texture rendered into a view) samples texels bilinearly: known colours are
 * spread this many texels into the unknown ones so that no grey fringe appears at the border
 * of the painted region (the unknown pixels are repainted anyway). */
#define CURRENT_DILATE_TEXELS 4
/* The inpaint pipeline keeps or repaints whole latent cells; a cell is repainted when it or a
 * neighbouring cell holds an untextured pixel (mx_paint_mask_cells). */
#define PAINT_DILATE_CELLS 1

int mx_job_current_textures(mx_job *j, mx_image *tex, mx_status *st) {
    size_t plane = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    for (int l = 0; l < j->nlayers; l++)
        if (mx_bake_texture(&j->bake, l, mx_job_grey, j->gen.ctx->pool, &tex[l], st) ||
            mx_uv_dilate(&tex[l], j->bake.known + l * plane, CURRENT_DILATE_TEXELS, j->gen.ctx->pool, st)) {
            for (int k = 0; k <= l; k++) mx_image_free(&tex[k]);
            return -1;
        }
    return 0;
}

/* crop + resize of the depth control to the model size, then into each of the 3 planes. */
static int place_depth(const mx_image *depth, mx_crop crop, int S, mx_pool *pool, float *planes, int plane_w, int x0,
                       mx_status *st) {
    mx_image small;
    if (mx_crop_resize(depth, crop, S, pool, &small, st)) return -1;
    for (int k = 0; k < 3; k++) mx_image_to_planes(&small, planes + (size_t)k * S * plane_w, plane_w, x0);
    mx_image_free(&small);
    return 0;
}

/* Inpainting inputs of a view at the model size: the render of the current textures I′ (init),
 * the paint mask (untextured pixels, grown to whole latent cells) and the inpaint control (I′
 * with the painted pixels at -1). */
static int inpaint_inputs(mx_job *j, mx_job_view *v, const mx_image *tex, const mx_view_planes *p, mx_status *st) {
    int R = j->o->pub.render_size, S = j->o->pub.image_size, rc = -1;
    mx_image rgb = {0}, mask_img = {0}, rgb_s = {0}, mask_s = {0}, paint = {0}, ctl = {0};
    uint8_t *mask = malloc((size_t)R * R), *open = NULL;
    if (!mask) return mx_fail(st, MX_ENOMEM, "inpainting mask: out of memory");
    const uint8_t *known = j->bake.known;
    if (j->write_flags & MX_BACKPROJECT_OVERWRITE) { /* texels this view will take over are repainted */
        if (!(open = malloc((size_t)j->nlayers * j->o->pub.texture_size * j->o->pub.texture_size))) {
            free(mask);
            return mx_fail(st, MX_ENOMEM, "inpainting mask: out of memory");
        }
        mx_bake_open_texels(&j->bake, &v->vb.gb, &j->mesh, v->vb.mask, open);
        known = open;
    }
    mx_mask_inpaint(&v->vb.gb, &j->mesh, NULL, known, j->o->pub.texture_size, j->o->pub.texture_size, j->gen.ctx->pool,
                    mask);
    free(open);
    v->untextured_pixels = mx_mask_count(mask, (int64_t)R * R);
    if (!mx_render_textured(&v->vb.gb, &j->mesh, tex, j->nlayers, mx_job_grey, j->gen.ctx->pool, &rgb, st) &&
        !mx_mask_image(mask, R, R, &mask_img, st) && !mx_crop_resize(&rgb, v->crop, S, j->gen.ctx->pool, &rgb_s, st) &&
        !mx_crop_resize(&mask_img, v->crop, S, j->gen.ctx->pool, &mask_s, st) &&
        !mx_paint_mask_cells(&mask_s, mx_vae_factor(j->gen.models->vae), PAINT_DILATE_CELLS, &paint, st) &&
        !mx_inpaint_image(&rgb_s, &paint, &ctl, st)) {
        mx_image_to_planes(&ctl, p->inpaint, p->plane_w, p->x0);
        if (p->init) mx_image_to_planes(&rgb_s, p->init, p->plane_w, p->x0);
        if (p->paint) mx_image_to_planes(&paint, p->paint, p->plane_w, p->x0);
        rc = 0;
    }
    mx_image_free(&rgb);
    mx_image_free(&mask_img);
    mx_image_free(&rgb_s);
    mx_image_free(&mask_s);
    mx_image_free(&paint);
    mx_image_free(&ctl);
    free(mask);
    return rc;
}

int mx_job_view_controls(mx_job *j, mx_job_view *v, const mx_view_planes *p, const mx_image *current,
                         mx_status *st) {
    double t = mx_now();
    mx_image depth;
    if (mx_depth_image(&v->vb.gb, &depth, st)) return -1;
    int rc = place_depth(&depth, v->crop, j->o->pub.image_size, j->gen.ctx->pool, p->depth, p->plane_w, p->x0, st);
    mx_image_free(&depth);
    if (!rc && p->inpaint) rc = inpaint_inputs(j, v, current, p, st);
    mx_job_work_since(j, MX_WORK_CONTROLS, t);
    return rc;
}
