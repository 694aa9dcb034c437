/* What the mesh harnesses do with a mesh that loaded: the checks and derived data every
 * pipeline computes first (validation, topology, normalised copy, face normals). */
#ifndef MX_FUZZ_MESH_COMMON_H
#define MX_FUZZ_MESH_COMMON_H

#include <stdlib.h>

#include "../../pipeline/geom/mesh.h"

static inline void fuzz_use_mesh(const mx_mesh *m) {
    mx_status st;
    if (mx_mesh_validate(m, &st)) return;
    mx_mesh_topology t;
    int32_t *comp = malloc(sizeof(int32_t) * (size_t)m->nfaces);
    if (comp) mx_mesh_topology_compute(m, 1, &t, comp, &st);
    free(comp);
    float *pos = NULL, *nrm = NULL;
    if (!mx_mesh_normalized(m, MX_UP_Z, &pos, NULL, NULL, &st) && !mx_mesh_face_normals(m, pos, &nrm, &st)) free(nrm);
    free(pos);
}

#endif
