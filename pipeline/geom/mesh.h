/* Mesh utilities over mx_mesh (mesh_types.h): copy, validation, bbox, normalised copy for
 * rendering, face normals, topology (loading from a file: pipeline/io/mesh_load.h). The input's
 * vertices, faces and UVs are kept exactly as they were (normalisation works on a copy). */
#ifndef MX_MESH_H
#define MX_MESH_H

#include <stdint.h>

#include "../../runtime/status.h"
#include "mesh_types.h"

/* A deep copy of src into dst (dst's arrays are its own; free with mx_mesh_free). */
int mx_mesh_clone(const mx_mesh *src, mx_mesh *dst, mx_status *st);

/* Positions beyond this magnitude are refused: the bounding box, normals and areas of the
 * geometry stages square and sum coordinates in float (3e38 overflowed into an atlas of
 * infinite size). 1e15 is far beyond any real unit (a light-day is 2.6e13 m). */
#define MX_MESH_MAX_COORD 1e15

/* Empty mesh, NaN/Inf or out-of-range positions, vertex/UV/normal/material indices out of
 * range -> error naming m->source_path. UV index -1 (a face without vt in an OBJ) is allowed. */
int mx_mesh_validate(const mx_mesh *m, mx_status *st);

/* Up axis of the input: y (glTF/OBJ default) or z (CAD, scans). Rendering works y-up. */
typedef enum { MX_UP_Y = 0, MX_UP_Z = 1 } mx_up_axis;

/* Axis-aligned bounding box of the positions as stored. */
void mx_mesh_bbox(const mx_mesh *m, float lo[3], float hi[3]);

/* A malloc'ed copy of the positions [nverts][3] for rendering: rotated z-up -> y-up when
 * up == MX_UP_Z ((x, y, z) -> (x, z, -y)), bbox centred at the origin, scaled so that the
 * farthest vertex lies on the unit sphere. center/scale (may be NULL) give the transform
 * p' = (R p - center) * scale. The mesh itself is not changed. */
int mx_mesh_normalized(const mx_mesh *m, mx_up_axis up, float **pos_out, float center[3],
                       float *scale, mx_status *st);
/* The same transform with a given center and scale (those of another mesh, to place two
 * meshes that share pose and units in one frame). */
int mx_mesh_placed(const mx_mesh *m, mx_up_axis up, const float center[3], float scale, float **pos_out,
                   mx_status *st);

/* Unit face normals [nfaces][3] (counter-clockwise = front) of the given positions
 * (m->pos or a normalised copy); zero vector for a degenerate face. */
int mx_mesh_face_normals(const mx_mesh *m, const float *pos, float **nrm_out, mx_status *st);

/* canon[v] (nverts entries) = the smallest vertex index with an equal position (-0 = +0): the
 * vertices glTF and OBJ files duplicate along UV seams, and triangle soups, become one. */
int mx_mesh_weld_map(const mx_mesh *m, int32_t *canon, mx_status *st);

/* One face edge between vertex ids lo < hi (after canon); corner = 3 * face + k: the edge from
 * the face's corner k to corner k + 1 (mod 3). */
typedef struct mx_mesh_edge {
    int32_t lo, hi, corner;
} mx_mesh_edge;

/* The edge adjacency of every face, under canon (a weld map, or the identity): all face edges
 * but collapsed ones (lo == hi), sorted by (lo, hi, corner), so that the faces sharing an edge
 * are one run. *out is malloc'ed (free it), *n its length. */
int mx_mesh_sorted_edges(const mx_mesh *m, const int32_t *canon, mx_mesh_edge **out, size_t *n, mx_status *st);
/* The end of the run of edges equal to e[i] (same lo and hi): e[i..end) share one edge. */
size_t mx_mesh_edge_run(const mx_mesh_edge *e, size_t n, size_t i);

/* Edge connectivity. With weld = 1, vertices with bit-identical positions count as one
 * (glTF duplicates vertices along UV seams); with weld = 0 the raw indices are used. */
typedef struct mx_mesh_topology {
    int edges;             /* distinct undirected edges */
    int boundary_edges;    /* used by exactly one face */
    int nonmanifold_edges; /* used by more than two faces */
    int watertight;        /* no boundary and no non-manifold edge */
    int components;        /* faces connected through shared vertices */
    int degenerate_faces;  /* repeated vertex index or zero area */
} mx_mesh_topology;

/* face_comp (may be NULL): component id per face [nfaces], ids 0.. in order of first face. */
int mx_mesh_topology_compute(const mx_mesh *m, int weld, mx_mesh_topology *t, int32_t *face_comp,
                             mx_status *st);

#endif
