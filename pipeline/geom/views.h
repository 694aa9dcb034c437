/* Automatic view selection (paper Alg. 1). Every candidate camera is rendered once
 * (at a small size) into the list of texels its usable pixels look at (foreground, not an
 * internal face, frontal enough); each step then counts, per candidate, the pixels whose
 * texel is not in T^B, and picks the largest. Planning simulates the coverage of the picked
 * views so that a whole sequence can be chosen ahead, and groups views that overlap little
 * (MX_VIEW_GROUP_OVERLAP: at most 2 % of a view's untextured texels already claimed by the
 * group's earlier views), so that they can be generated in one batch. */
#ifndef MX_VIEWS_H
#define MX_VIEWS_H

#include <stdint.h>

#include "../../runtime/threadpool.h"
#include "camera.h"
#include "mesh.h"
#include "raster.h"

typedef struct mx_view_cache {
    int ncand, size;
    int tex_w, tex_h, nlayers;
    mx_camera *cams;    /* [ncand] (owned copy) */
    int32_t **texels;   /* [ncand][ntexels[c]] texel ids (layer * tex_w * tex_h + row * tex_w + col) */
    int64_t *ntexels;
} mx_view_cache;

/* Renders every candidate at size x size (culled, with the unculled depth for the
 * internal-face mask; normals of normal_source (MX_NORMAL_*, the same as the backprojection
 * of the chosen views uses) against frontal_threshold, 0 keeps every visible pixel; edges
 * eroded by erode_radius pixels of this size as mx_view_erode_edges, 0 = none), so that
 * selection counts the pixels backprojection will use. */
int mx_view_cache_build(mx_view_cache *vc, const mx_mesh *m, const float *pos,
                        const mx_camera *cams, int ncand, int size, int tex_w, int tex_h,
                        int nlayers, int normal_source, float frontal_threshold, int erode_radius, mx_pool *pool,
                        mx_status *st);
/* An erosion radius of `radius` pixels at render size `from`, at render size `to` (0 stays 0,
 * otherwise at least 1). */
int mx_view_scale_radius(int radius, int from, int to);
void mx_view_cache_free(mx_view_cache *vc);

/* Pixels of candidate c whose texel is not in `known` ([nlayers][tex_h][tex_w]). */
int64_t mx_view_untextured(const mx_view_cache *vc, int c, const uint8_t *known);
/* visible[t] = 1 for texels seen by some candidate (array of nlayers * tex_w * tex_h). */
void mx_view_cache_visible(const mx_view_cache *vc, uint8_t *visible);

/* The candidate (not in `used`, may be NULL) with the most untextured pixels, at least
 * min_pixels of them; -1 when none qualifies. */
int mx_view_pick(const mx_view_cache *vc, const uint8_t *known, const uint8_t *used,
                 int64_t min_pixels);

/* Fraction of a view's untextured texels that may already be claimed by its batch. */
#define MX_VIEW_GROUP_OVERLAP 0.02

typedef struct mx_view_plan {
    int n;          /* views planned */
    int *cand;      /* [n] candidate index, in generation order */
    int *group;     /* [n] batch id: views with the same id can be generated together */
    double coverage; /* simulated fraction of candidate-visible texels in T^B at the end */
} mx_view_plan;

/* Plans up to `budget` views from the current T^B (the caller bakes front and back
 * first, paper stage 0, and passes the budget left): greedy Alg. 1 with simulated
 * coverage (a picked view's texels count as textured), stopping early when the
 * simulated coverage of candidate-visible texels reaches coverage_stop or no candidate
 * has min_pixels untextured pixels left. A view joins the current group when at most
 * MX_VIEW_GROUP_OVERLAP (2 %) of its texels untextured at the group's start are already claimed by
 * the group's earlier views (a sliver along silhouettes; the earlier view keeps those texels), else
 * it starts the next group. */
int mx_view_plan_make(const mx_view_cache *vc, const uint8_t *known, int budget,
                      double coverage_stop, int64_t min_pixels, mx_view_plan *plan, mx_status *st);
void mx_view_plan_free(mx_view_plan *plan);

/* The view schedule after front and back (paper Alg. 1), one for `matex texture`, `enhance` and
 * `transfer`: each call of mx_view_schedule_next plans from T^B as it is then (the views already
 * backprojected), so the schedule follows what the views really painted. What differs between
 * the commands is a parameter: how many views one step may return (texture: a batch of views
 * whose untextured texels overlap by at most MX_VIEW_GROUP_OVERLAP, generated together; enhance
 * and transfer: one, each view seeing the one before). A chosen candidate is never chosen again; the schedule ends when
 * the budget is spent, when the candidates' coverage reaches coverage_stop, or when no
 * candidate left would paint min_gain untextured pixels (at the candidate render size). */
typedef struct mx_view_schedule_params {
    int budget;            /* views after front and back */
    int max_batch;         /* most views one step returns (>= 1) */
    double coverage_stop;  /* of candidate-visible texels */
    int64_t min_gain;      /* the gain floor: fewer untextured pixels end the schedule */
} mx_view_schedule_params;

typedef struct mx_view_schedule {
    const mx_view_cache *vc;
    mx_view_schedule_params p;
    uint8_t *used; /* [ncand] candidates chosen so far */
    int done;      /* views returned so far */
} mx_view_schedule;

int mx_view_schedule_init(mx_view_schedule *s, const mx_view_cache *vc, const mx_view_schedule_params *p,
                          mx_status *st);
/* The next views (candidate indices into cand[max_batch], in generation order) from `known`;
 * *n = 0 when the schedule has ended. */
int mx_view_schedule_next(mx_view_schedule *s, const uint8_t *known, int *cand, int *n, mx_status *st);
void mx_view_schedule_free(mx_view_schedule *s);

/* One view ready for backprojection: its culled render with UVs and the unculled depth
 * (gb: depth, images, UVs, internal faces), and the backprojection mask
 * (foreground & frontal & not internal). */
typedef struct mx_view_buffers {
    mx_gbuffer gb;
    uint8_t *mask; /* [size][size] */
    uint8_t *tmp;
} mx_view_buffers;

/* The rasterizer flags of a view: culled, with UVs and the unculled depth. */
#define MX_VIEW_RASTER_FLAGS (MX_RASTER_CULL_BACK | MX_RASTER_UV | MX_RASTER_DEPTH_UNCULLED)

int mx_view_buffers_init(mx_view_buffers *vb, int size, mx_status *st);
void mx_view_buffers_free(mx_view_buffers *vb);
/* Rasterizes `cam` (MX_VIEW_RASTER_FLAGS) and computes the mask with mx_view_masks. */
int mx_view_prepare(mx_view_buffers *vb, const mx_mesh *m, const float *pos, const mx_camera *cam,
                    int normal_source, float frontal_threshold, mx_pool *pool, mx_status *st);
/* The backprojection mask of vb->gb (rasterized with MX_VIEW_RASTER_FLAGS): foreground &
 * frontal (normal_source and threshold as in mx_mask_frontal; 0 keeps every foreground
 * pixel) & not internal. */
void mx_view_masks(mx_view_buffers *vb, int normal_source, float frontal_threshold, mx_pool *pool);

/* Edge erosion of the backprojection mask. Generated images are resampled (crop to the
 * object, model size, back) and painted by a network that does not end exactly at the
 * silhouette: pixels next to the background or to a depth discontinuity (an occluding edge)
 * carry background or occluder colour. mx_view_erode_edges clears vb->mask within `radius`
 * pixels (square neighbourhood) of every edge pixel: a foreground pixel with a 4-neighbour
 * that is background, or whose depth differs from a 4-neighbour's by more than
 * MX_VIEW_DEPTH_JUMP pixel footprints (a surface steeper than ~76°, which the frontal filter
 * rejects anyway, or a jump between surfaces). The radius is MX_VIEW_ERODE_MODEL_PX pixels of
 * the model image in render pixels, ceil(1.5 · render_size / image_size): 3 pixels at the
 * default 1024 render / 512 model size (image_size 0: no resampling, 2 pixels). Measured by
 * tests/test_texture_bleed.c: 2 render pixels at a 2:1 ratio still let background through. */
#define MX_VIEW_ERODE_MODEL_PX 1.5f
#define MX_VIEW_DEPTH_JUMP 4.0f
int mx_view_erode_radius(int render_size, int image_size);
int mx_view_erode_edges(mx_view_buffers *vb, int radius, mx_status *st);

#endif
