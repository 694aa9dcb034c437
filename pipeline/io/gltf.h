/* glTF 2.0 import (.gltf with .bin/image files or data: URIs, and .glb), using runtime/json.h.
 * Every mesh primitive (mode TRIANGLES, or TRIANGLE_STRIP/FAN expanded) reachable from the
 * default scene's nodes (all root nodes when there is no scene) is transformed to world space
 * by its node hierarchy (matrix, or translation * rotation * scale) and appended to one
 * mx_mesh: positions, indices (or implicit 0..n-1), TEXCOORD_0 (v flipped to v up), NORMAL
 * (rotated by the inverse transpose), one material per glTF material (+ a "default" one for
 * primitives without), face_mat. Primitives without TEXCOORD_0 in a mesh where others have
 * it get UV index -1 on their corners. Faces whose node transform has a negative determinant
 * are flipped to stay counter-clockwise. A material's texture_path is its baseColorTexture:
 * the image file (resolved relative to the .gltf) or "<path>#image<N>" for an embedded image.
 * Every accessor, buffer view and buffer offset/count/stride is checked against the data. */
#ifndef MX_GLTF_H
#define MX_GLTF_H

#include "../../runtime/status.h"
#include "../geom/mesh_types.h"

int mx_gltf_load(const char *path, mx_mesh *m, mx_status *st);

/* The file name a relative file URI of a glTF stands for, %XX escapes decoded: the name the
 * reader opens in the document's folder (also what `matex batch --server` sends beside it).
 * 0, or -1 when it does not fit in cap bytes. */
int mx_gltf_uri_name(const char *uri, char *out, size_t cap);

/* Decodes image `index` of the glTF file at `path` (a file uri, a data: URI, or a buffer
 * view of a .glb / .gltf buffer) through the image adapter. */
int mx_gltf_read_image(const char *path, int index, mx_image *img, mx_status *st);

#endif
