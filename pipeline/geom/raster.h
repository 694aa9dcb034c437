/* CPU rasterizer: tiled, multithreaded, exact integer edge functions on vertices snapped
 * to 1/256 pixel, with the top-left fill rule, so triangles sharing an edge cover each
 * pixel centre exactly once (no cracks, no double coverage). Closest depth wins; on equal
 * depth the lower face id wins, so results are the same for any thread count.
 *
 * Per pixel it gives the face id (-1: background), perspective-correct barycentrics,
 * the depth (distance along the viewing axis), and, when asked, the interpolated
 * per-corner UV and the depth without backface culling (same pass). Only face ids and
 * depths are written while drawing; barycentrics and UVs are resolved afterwards, once
 * per pixel. */
#ifndef MX_RASTER_H
#define MX_RASTER_H

#include <stdint.h>

#include "../../runtime/threadpool.h"
#include "camera.h"
#include "image.h"
#include "mesh.h"

enum {
    MX_RASTER_CULL_BACK = 1, /* skip faces whose corners appear clockwise from the camera */
    MX_RASTER_UV = 2,        /* fill gbuffer.uv from the mesh's per-corner UVs */
    MX_RASTER_DEPTH_UNCULLED = 4, /* with CULL_BACK: also fill depth_unculled in the same pass */
};

typedef struct mx_gbuffer {
    int w, h;
    int32_t *face;         /* [h][w] face id, -1 where no face is visible */
    float *depth;          /* [h][w] view depth, INFINITY where face < 0 */
    float *depth_unculled; /* [h][w] depth with back faces too (MX_RASTER_DEPTH_UNCULLED), or NULL */
    float *bary;           /* [h][w][2] barycentric weights of corners 1 and 2 (corner 0: 1-b1-b2) */
    float *uv;             /* [h][w][2] UV (v up; NaN on faces without UVs), NULL if none */
    mx_camera cam;
    void *scratch; /* reused between calls (screen-space vertices, face setup and normals, bins) */
} mx_gbuffer;

/* Allocates a w x h buffer (uv and depth_unculled storage is allocated on first use). */
int mx_gbuffer_init(mx_gbuffer *gb, int w, int h, mx_status *st);
void mx_gbuffer_free(mx_gbuffer *gb);

/* Rasterizes mesh `m` with vertex positions `pos` ([m->nverts][3]; m->pos when NULL,
 * normally the normalised copy) seen by `cam`. flags: MX_RASTER_*. */
int mx_rasterize(const mx_mesh *m, const float *pos, const mx_camera *cam, int flags,
                 mx_pool *pool, mx_gbuffer *gb, mx_status *st);

/* Unit geometric normal (counter-clockwise, world space) of the face visible at pixel i;
 * zero vector for background or a degenerate face. */
void mx_gbuffer_normal(const mx_gbuffer *gb, int64_t i, float out[3]);
/* The table behind mx_gbuffer_normal: [nfaces][3], valid for the faces that appear in
 * gb->face (per-pixel loops read it directly instead of calling per pixel). */
const float *mx_gbuffer_face_normals(const mx_gbuffer *gb);

/* Textured render: out (RGB, w x h, allocated here) gets the bilinear lookup of the face's
 * material texture at the pixel's UV (UVs repeat); `textures` has one image per material
 * (ntex of them; faces of a material without an image, or all when ntex is 0, get
 * `background`-independent mid grey), background pixels get `background`. */
int mx_render_textured(const mx_gbuffer *gb, const mx_mesh *m, const mx_image *textures, int ntex,
                       const float background[3], mx_pool *pool, mx_image *out, mx_status *st);
/* Shaded render of the normals (|n| mapped to colour, lit from the camera), for previews. */
int mx_render_normals(const mx_gbuffer *gb, const float background[3], mx_image *out, mx_status *st);

/* Bilinear lookup with repeat wrapping at UV (v up), into out[img->c]. */
void mx_texture_sample(const mx_image *img, float u, float v, float *out);

#endif
