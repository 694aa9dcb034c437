/* Filling the texels no view reached (docs/DESIGN.md §2 step 6): texels inside charts (covered
 * by some triangle in UV space) get a push-pull mip-pyramid interpolation of the known
 * texels; then the gutter around charts is dilated a few texels so that bilinear and mip
 * filtering across chart borders shows no cracks. */
#ifndef MX_UVFILL_H
#define MX_UVFILL_H

#include <stdint.h>

#include "image.h"
#include "mesh.h"

/* chart[t] = 1 for texels of a w x h texture whose area a UV triangle of material layer
 * `layer` touches (texel centre within half a texel of the triangle; UVs repeat).
 * Faces of other layers are skipped when the mesh has face_mat and nlayers > 1. */
int mx_uv_chart_mask(const mx_mesh *m, int layer, int nlayers, int w, int h, uint8_t *chart,
                     mx_status *st);

/* Fills tex (RGB, w x h) in place: texels with known == 0 and chart != 0 by push-pull,
 * then `gutter` rings of dilation outside the charts. Texels in neither stay as they are.
 * When nothing is known, chart texels are left unchanged. */
int mx_uv_fill(mx_image *tex, const uint8_t *known, const uint8_t *chart, int gutter, mx_status *st);

#endif
