/* UV atlas for meshes without UVs (docs/DESIGN.md §2 step 1): charts grown over faces whose normals
 * stay within a cone, each projected onto its plane (and cut until no triangle folds over or
 * overlaps another), small charts merged into neighbours, then all charts packed by their
 * outlines (tetris-like skyline) into the unit square at one common scale, so the texel density
 * is uniform, with a gutter of empty texels between charts. Deterministic: the same mesh and
 * options always give the same atlas. */
#ifndef MX_UVATLAS_H
#define MX_UVATLAS_H

#include "../../runtime/status.h"
#include "mesh.h"

typedef struct mx_uvatlas_opts {
    int texture_size;      /* texels per side the atlas is laid out for; 0: 1024 */
    int gutter;            /* empty texels guaranteed between two charts (conservatively
                              rasterised at texture_size); 0: 2. Charts may touch the border. */
    float max_chart_angle; /* degrees, in (0, 75]: a chart grows over faces within this angle of
                              its mean normal; no face is projected at more than this + 10
                              degrees, so area stretch <= 1 / cos(angle + 10). 0: 60 */
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

/* Fills m->nuv, m->uv and m->face_uv (per-corner UVs in [0,1], v up; malloc'ed, freed by
 * mx_mesh_free) for a mesh without UVs. Vertices with identical positions are treated as one
 * (triangle soups get proper charts). Fails if the mesh already has UVs, has an out-of-range
 * index or a non-finite position, or if the charts cannot be packed at the texture size; the
 * mesh is then unchanged and st->msg reads "<source_path or 'mesh'>: uv atlas: <problem>".
 * o and r may be NULL. */
int mx_uvatlas_build(mx_mesh *m, const mx_uvatlas_opts *o, mx_uvatlas_report *r, mx_status *st);

/* For a mesh with UVs on some faces only (pipeline/geom/uvatlas_faces.c): the faces without
 * UVs (a corner index -1) of each material get an atlas of their own, appended to m->uv, and a
 * texture of their own: they keep their material when none of its faces had UVs, else they move
 * to a new material "<name>_atlas" (m->mats, m->face_mat grow). A warning names each material.
 * *faces_done: faces laid out; r (may be NULL): charts summed, utilisation and mean stretch
 * averaged over the atlases, seconds summed. */
int mx_uvatlas_complete(mx_mesh *m, const mx_uvatlas_opts *o, mx_uvatlas_report *r, int *faces_done,
                        mx_status *st);

#endif
