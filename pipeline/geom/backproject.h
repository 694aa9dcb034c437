/* Fast backprojection (paper §3.5): every visible, unmasked pixel of a view is bilinearly
 * splatted into the 4 texels around its UV; texels accumulate sum(w * colour) and sum(w).
 * The texture is T = sum(w c) / sum(w), and T^B (`known`) marks texels with sum(w) > eps.
 * A view writes texels that were not in T^B before it; its aliasing holes (texels between its
 * pixels) take the mean of the texels around (backproject.c). MX_BACKPROJECT_OVERWRITE also
 * lets it repaint texels it sees at a clearly better angle than the views that wrote them
 * (|n.v| higher by overwrite_margin = 0.15, from the face normals; the angle-aware policy of
 * `matex texture` and `matex transfer`), blended over a feathered border so that the source
 * of the texels changes smoothly, never one isolated texel of a view inside another's region.
 *
 * Meshes whose materials keep their own UV sets get one layer per material (nlayers =
 * max(1, nmat)); a pixel goes to the layer of its face's material.
 * Threads: the texture is cut into bands of rows; each task owns one band and processes,
 * in pixel order, the pixels whose splat lands in it, so there are no data races and the
 * result does not depend on the thread count. */
#ifndef MX_BACKPROJECT_H
#define MX_BACKPROJECT_H

#include <stdint.h>

#include "../../runtime/threadpool.h"
#include "image.h"
#include "mesh.h"
#include "raster.h"

enum { MX_BACKPROJECT_OVERWRITE = 1 };

/* A texel enters T^B (is "known") only with at least this much splat weight: a quarter of one
 * pixel's full weight. A texel grazed by the corner of a single pixel (typically at a
 * silhouette or a seam) stays open for a view that sees it properly. */
#define MX_BAKE_KNOWN_WEIGHT 0.25f

typedef struct mx_bake {
    int w, h, nlayers;
    float eps;       /* T^B threshold on sum(w); MX_BAKE_KNOWN_WEIGHT by default */
    float overwrite_margin; /* |n.v| gain at which a view takes half of a texel (OVERWRITE); 0.15 */
    float *sum_wc;   /* [nlayers][h][w][3] */
    float *sum_w;    /* [nlayers][h][w] */
    uint8_t *known;  /* [nlayers][h][w] T^B */
    float *quality;  /* [nlayers][h][w] best |n.v| among the views that wrote the texel */
    void *scratch;   /* per-view pixel lists, reused */
} mx_bake;

int mx_bake_init(mx_bake *b, int w, int h, int nlayers, mx_status *st);
void mx_bake_free(mx_bake *b);
/* Clears sums and T^B. */
void mx_bake_reset(mx_bake *b);

/* Splats image `img` (gb->w x gb->h, 3 or more channels, the first 3 used) of the view
 * rasterized in `gb` (which must carry UVs) where mask != 0 (NULL: every foreground
 * pixel), then updates T^B. */
int mx_backproject(mx_bake *b, const mx_gbuffer *gb, const mx_mesh *m, const mx_image *img,
                   const uint8_t *mask, int flags, mx_pool *pool, mx_status *st);

/* T^B as the view in gb would leave it open for painting: out = b->known without the texels
 * that mx_backproject with MX_BACKPROJECT_OVERWRITE would mostly repaint for this view (its |n.v|
 * at a pixel over the texel exceeds the texel's quality by overwrite_margin; nearest texel of
 * each pixel where mask != 0, NULL: every foreground pixel). out has b's size. */
void mx_bake_open_texels(const mx_bake *b, const mx_gbuffer *gb, const mx_mesh *m, const uint8_t *mask,
                         uint8_t *out);

/* The texture of one layer: out (w x h x 3, allocated here) = sum(w c)/sum(w) where known,
 * `fill` elsewhere; texels on pool (NULL: serial). */
int mx_bake_texture(const mx_bake *b, int layer, const float fill[3], mx_pool *pool, mx_image *out, mx_status *st);
/* Texels in T^B (all layers). */
int64_t mx_bake_known_count(const mx_bake *b);

/* Material layer of a face (0 when the mesh has no materials or the index is invalid). */
int mx_face_layer(const mx_mesh *m, int face, int nlayers);

#endif
