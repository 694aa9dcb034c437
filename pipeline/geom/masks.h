/* Per-pixel masks of a view (paper §3.3, "Filtering"): foreground, frontal faces,
 * internal faces of open surfaces, and the inpainting mask. Masks are uint8 [h][w], 1 = set. */
#ifndef MX_MASKS_H
#define MX_MASKS_H

#include <stdint.h>

#include "../../runtime/threadpool.h"
#include "raster.h"

enum { MX_NORMAL_GEOMETRIC = 0, MX_NORMAL_FROM_DEPTH = 1 };

/* 1 where a face is visible. */
void mx_mask_foreground(const mx_gbuffer *gb, uint8_t *mask);

/* 1 where |n . v| >= threshold, v the direction to the eye; n is the face's geometric
 * normal (MX_NORMAL_GEOMETRIC) or the normal of the depth map (MX_NORMAL_FROM_DEPTH,
 * the paper's choice: cross product of the unprojected neighbours' differences; at depth
 * discontinuities the smaller one-sided difference is used). 0 on background. */
void mx_mask_frontal(const mx_gbuffer *gb, int normal_source, float threshold, uint8_t *mask);
/* The same for rows [y0, y1) only (mask is still the whole [h][w] array), so that callers
 * can split the work into tasks. */
void mx_mask_frontal_rows(const mx_gbuffer *gb, int normal_source, float threshold, int y0, int y1,
                          uint8_t *mask);

/* Internal faces of open surfaces (paper Fig. 6): 1 where the depth rendered with
 * backface culling and the depth rendered without it differ (by more than a relative
 * 1e-4, background counting as infinitely far), n pixels. The two depths come from one
 * mx_rasterize with MX_RASTER_CULL_BACK | MX_RASTER_DEPTH_UNCULLED (depth, depth_unculled)
 * or from two renders of the same camera. */
void mx_mask_internal(const float *depth_culled, const float *depth_unculled, int64_t n, uint8_t *mask);

/* Texel of a UV for a tex_w x tex_h texture (v up, repeat), nearest texel centre. */
int64_t mx_uv_texel(float u, float v, int tex_w, int tex_h);

/* Inpainting mask of a view: 1 where visible (allowed != 0, or every foreground pixel when
 * allowed is NULL) and the texel under the pixel is not yet in T^B (`known`, tex_w x tex_h,
 * for the face's material: `known` holds nmat planes when the mesh has several). Needs uv. Rows
 * on pool (NULL: serial). */
void mx_mask_inpaint(const mx_gbuffer *gb, const mx_mesh *m, const uint8_t *allowed,
                     const uint8_t *known, int tex_w, int tex_h, mx_pool *pool, uint8_t *mask);

/* dst = a & ~b (pixelwise), n pixels. */
void mx_mask_and_not(const uint8_t *a, const uint8_t *b, uint8_t *dst, int64_t n);
/* Number of set pixels. */
int64_t mx_mask_count(const uint8_t *mask, int64_t n);

#endif
