/* UV atlas for meshes without UVs (DESIGN.md §2 step 2): chart segmentation by region growing
 * on face normals, a planar projection per chart (split until no triangle folds or overlaps),
 * and skyline packing of the charts' rectangles into the unit square at one common scale
 * (uniform texel density) with a gutter between charts. Deterministic: the same mesh and
 * options always give the same atlas. */
#ifndef MX_UVATLAS_H
#define MX_UVATLAS_H

#include "../../runtime/status.h"
#include "mesh.h"

typedef struct mx_uvatlas_opts {
    int texture_size;      /* texels per side the atlas is laid out for; 0: 1024 */
    int gutter;            /* empty texels guaranteed between two charts (and the border); 0: 2 */
    float max_chart_angle; /* degrees between a face normal and its chart's normal; 0: 60 */
} mx_uvatlas_opts;

typedef struct mx_uvatlas_report {
    int charts;
    double utilisation;  /* fraction of the unit square covered by UV triangles */
    double stretch_mean; /* area stretch: 3D area / UV area at the common scale, >= 1 for a
                            projection (1 / cos of the face's tilt); area-weighted mean */
    double stretch_max;  /* largest over faces with a non-zero area */
    double seconds;      /* wall time of mx_uvatlas_build */
} mx_uvatlas_report;

/* Default options (1024 texels, gutter 2, 60 degrees). */
mx_uvatlas_opts mx_uvatlas_defaults(void);

/* Fills m->nuv, m->uv and m->face_uv (per-corner UVs in [0,1], v up) for a mesh without UVs;
 * fails if the mesh already has UVs, has an out-of-range index or a non-finite position, or if
 * the charts cannot be packed at the texture size. o and r may be NULL. On failure the mesh is
 * unchanged. */
int mx_uvatlas_build(mx_mesh *m, const mx_uvatlas_opts *o, mx_uvatlas_report *r, mx_status *st);

#endif
