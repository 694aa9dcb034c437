/* Filling the texels no view reached (docs/DESIGN.md §2 step 6): texels inside charts (covered
 * by some triangle in UV space) get a push-pull mip-pyramid interpolation of the known
 * texels; then the gutter around charts is dilated a few texels so that bilinear and mip
 * filtering across chart borders shows no cracks. */
#ifndef MX_UVFILL_H
#define MX_UVFILL_H

#include <stdint.h>

#include "../../runtime/threadpool.h"
#include "image.h"
#include "mesh.h"

/* chart[t] = 1 for texels of a w x h texture whose area a UV triangle of material layer
 * `layer` touches (texel centre within half a texel of the triangle; UVs repeat).
 * Faces of other layers are skipped when the mesh has face_mat and nlayers > 1. */
int mx_uv_chart_mask(const mx_mesh *m, int layer, int nlayers, int w, int h, uint8_t *chart,
                     mx_status *st);

/* The same, and face_map[t] = a face whose UV triangle marks texel t (-1 outside charts). */
int mx_uv_chart_faces(const mx_mesh *m, int layer, int nlayers, int w, int h, uint8_t *chart, int32_t *face_map,
                      mx_status *st);

/* Fills tex (RGB, w x h) in place: texels with known == 0 and chart != 0 by push-pull,
 * then `gutter` rings of dilation outside the charts. Texels in neither stay as they are.
 * When nothing is known, chart texels are left unchanged. */
int mx_uv_fill(mx_image *tex, const uint8_t *known, const uint8_t *chart, int gutter, mx_status *st);

/* Fill by harmonic inpainting across UV seams (layer `layer` of nlayers, as mx_uv_chart_mask):
 * unknown chart texels are solved so that each is the mean of its neighbours in a texel graph
 * (known texels fixed): the 4-neighbours in the texture whose faces touch in 3D (same face or
 * a shared, position-welded vertex: texels of unrelated charts that lie side by side in the
 * atlas are not linked), and, along every UV seam (a mesh edge whose two faces map it to
 * different UVs), the texels on the two sides of the seam at the same point of the edge.
 * Push-pull gives the start; successive over-relaxation (MX_UV_HARMONIC_ITERS sweeps, omega
 * 1.9) solves. Then `gutter` rings of dilation outside the charts, as mx_uv_fill. */
#define MX_UV_HARMONIC_ITERS 300
/* A large texture's fill runs for minutes (8192²: ~200 s), so it reports how far it has come: `tick`
 * is called after the texel graph is built (done 0) and every MX_UV_TICK_SWEEPS sweeps of the solve
 * (done in (0, 1]); a non-zero return stops the fill with MX_ECANCEL ("interrupted"). */
#define MX_UV_TICK_SWEEPS 20
typedef struct mx_uv_fill_ticker {
    int (*tick)(void *user, double done);
    void *user;
} mx_uv_fill_ticker;
/* ticker may be NULL. */
int mx_uv_fill_harmonic(mx_image *tex, const uint8_t *known, const mx_mesh *m, int layer, int nlayers, int gutter,
                        const mx_uv_fill_ticker *ticker, mx_status *st);

/* Spreads the colour of known texels `rings` texels into the unknown ones around them (each
 * ring: an unknown texel takes the mean of its already filled 8-neighbours), so that bilinear
 * sampling at the border of the known region does not mix in the colour of unknown texels. Rows on
 * pool (NULL: serial), the same result on any pool. */
int mx_uv_dilate(mx_image *tex, const uint8_t *known, int rings, mx_pool *pool, mx_status *st);

#endif
