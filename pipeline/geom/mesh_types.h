/* The plain data types shared by pipeline/geom and the file I/O adapter (pipeline/io), with
 * their release functions: nothing here calls geometry code, so the adapter can use them
 * without depending on libmx_geom. */
#ifndef MX_MESH_TYPES_H
#define MX_MESH_TYPES_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct mx_material {
    char name[128];
    char texture_path[1024]; /* diffuse / base-colour texture, "" if none */
} mx_material;

/* Triangle mesh as loaded from a file: positions, triangles, per-corner UVs and normals,
 * per-face material. Every array is malloc'ed and owned (mx_mesh_free). */
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

/* Float images, interleaved (HWC), row 0 at the top. Colour images hold sRGB-encoded values in
 * [0, 1] as read from 8-bit files (no linearisation). data is malloc'ed (mx_image_free). */
typedef struct mx_image {
    int w, h, c; /* c = 1, 3 or 4 */
    float *data; /* [h][w][c] */
} mx_image;

static inline void mx_mesh_free(mx_mesh *m) {
    if (!m) return;
    free(m->pos);
    free(m->faces);
    free(m->uv);
    free(m->face_uv);
    free(m->nrm);
    free(m->face_nrm);
    free(m->mats);
    free(m->face_mat);
    memset(m, 0, sizeof *m);
}

static inline void mx_image_free(mx_image *img) {
    if (!img) return;
    free(img->data);
    img->data = NULL;
    img->w = img->h = img->c = 0;
}

#endif
