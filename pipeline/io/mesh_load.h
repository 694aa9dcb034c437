/* Loading a mesh and its textures from files, by extension: the one entry point the stages
 * and tools use; it picks the reader (pipeline/io/io.h for .obj .ply .off .stl, gltf.h for
 * .gltf .glb) and hands the result to geometry's validation. */
#ifndef MX_MESH_LOAD_H
#define MX_MESH_LOAD_H

#include "../../runtime/status.h"
#include "../geom/mesh_types.h"

/* Loads any supported mesh, chosen by extension: .obj .ply .off .stl (pipeline/io/io.h),
 * .gltf .glb (pipeline/io/gltf.h), after mx_mesh_check_file (filekind.h) has refused a path
 * that is something else; then validates it (mx_mesh_validate, pipeline/geom/mesh.h). */
int mx_mesh_load(const char *path, mx_mesh *m, mx_status *st);

/* Decodes the base-colour texture of every material into tex[0..m->nmat) (an empty image,
 * data NULL, where a material has none or its file is missing: a warning, not an error).
 * texture_path is a file path, or "<file.gltf|glb>#image<N>" for an image stored inside a
 * glTF (buffer view or data: URI). Free each with mx_image_free. */
int mx_mesh_load_textures(const mx_mesh *m, mx_image *tex, mx_status *st);

#endif
