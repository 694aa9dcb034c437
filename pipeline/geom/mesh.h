/* Triangle mesh as loaded from a file: positions, triangles, per-corner UVs and normals,
 * per-face material. The input's vertices, faces and UVs are kept exactly as they were
 * (normalisation for rendering works on a copy of the positions: see mx_mesh_normalized). */
#ifndef MX_MESH_H
#define MX_MESH_H

#include <stdint.h>

#include "../../runtime/status.h"

typedef struct mx_material {
    char name[128];
    char texture_path[1024]; /* diffuse / base-colour texture, "" if none */
} mx_material;

typedef struct mx_mesh {
    int nverts, nfaces;
    float *pos;        /* [nverts][3] */
    int32_t *faces;    /* [nfaces][3] vertex indices, counter-clockwise front faces */
    int nuv;           /* 0: no UVs */
    float *uv;         /* [nuv][2], v up (OBJ/OpenGL convention: v = 0 is the bottom row) */
    int32_t *face_uv;  /* [nfaces][3] indices into uv, or NULL */
    int nnrm;
    float *nrm;        /* [nnrm][3] */
    int32_t *face_nrm; /* [nfaces][3] indices into nrm, or NULL */
    int nmat;
    mx_material *mats; /* [nmat] */
    int32_t *face_mat; /* [nfaces] material index, or NULL (all material 0) */
    char source_path[1024];
} mx_mesh;

void mx_mesh_free(mx_mesh *m);

#endif
