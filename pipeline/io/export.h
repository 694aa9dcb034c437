/* Exporters: OBJ + MTL, GLB 2.0 with embedded PNG textures, and the output folder of a run.
 * Every file is written to "<name>.tmp" and renamed, so a failure leaves no partial file. */
#ifndef MX_EXPORT_H
#define MX_EXPORT_H

#include "../../runtime/status.h"
#include "../geom/mesh_types.h"

/* Writes an OBJ (v, vt, vn, f with the mesh's own per-corner indices, usemtl per material)
 * and, when texture_files is given, "<obj path without .obj>.mtl" with one material per
 * entry: texture_files[i] (a file name relative to the OBJ folder, or NULL) is map_Kd of
 * material i. ntex = number of entries; faces of material k >= ntex use material 0. */
int mx_export_obj(const char *path, const mx_mesh *m, const char *const *texture_files, int ntex,
                  mx_status *st);

/* Writes a GLB 2.0 file: one mesh, one primitive per material, POSITION (with min/max),
 * NORMAL (given or from face normals), TEXCOORD_0 (v flipped to glTF's top-left origin),
 * unsigned-int indices; textures[i] embedded as PNG is the baseColorTexture of material i
 * (ntex entries; textures may be NULL or an entry may have data == NULL: no texture).
 * Vertices are split per distinct (position, uv, normal) corner, as glTF requires. */
int mx_export_glb(const char *path, const mx_mesh *m, const mx_image *textures, int ntex,
                  mx_status *st);

/* Writes the output folder (created if missing) of a texturing run:
 *   ntex == 1: texture.png (8-bit) and texture.exr (float), every face on one material;
 *   ntex > 1 (several materials keep their own UVs: textures[i] belongs to material i):
 *   texture_<material>.png and texture_<material>.exr per material with a texture (the name
 *   reduced to [A-Za-z0-9_-], the index added when two materials give the same name);
 *   mesh.obj + mesh.mtl, mesh.glb (textures embedded), report.json (report_json verbatim,
 *   or "{}" when NULL). */
int mx_write_outputs(const char *dir, const mx_mesh *m, const mx_image *textures, int ntex,
                     const char *report_json, mx_status *st);
/* mx_write_outputs in its two parts, for a caller whose report states how long the files took:
 * every file but report.json (the folder created if missing; the EXR compressed on `threads`,
 * mx_io_write_exr), then report.json. */
int mx_write_output_files(const char *dir, const mx_mesh *m, const mx_image *textures, int ntex, int threads,
                          mx_status *st);
int mx_write_report(const char *dir, const char *report_json, mx_status *st);

#endif
