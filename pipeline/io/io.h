/* The file I/O adapter: the only code that touches third-party file-format libraries
 * (OpenMesh for PLY/OFF/STL, OpenEXR, zlib for PNG; OpenImageIO for other images, opened on
 * first use: image_files.c).
 * Implemented in C++ (pipeline/io, .cpp files) behind this C interface; it depends only on
 * runtime/ (status, log) and the types-only header pipeline/geom/mesh_types.h, never on
 * pipeline/geom's code, so it links after libmx_geom.
 *
 * Most callers want the higher-level entry points instead:
 *   mx_mesh_load / mx_mesh_load_textures (pipeline/io/mesh_load.h): any mesh by extension,
 *     .obj .ply .off .stl through this adapter, .gltf .glb through pipeline/io/gltf.h;
 *   mx_write_outputs (pipeline/io/export.h): the output folder of a texturing run.
 *
 * Conventions: every function returns 0 or -1 with st filled (code MX_EINPUT for a bad or
 * missing file, MX_EIO for a failed write, MX_ENOMEM); outputs are zeroed on failure and own
 * their memory (free with mx_mesh_free / mx_image_free, i.e. free() of each array).
 * Writers write to "<path>.tmp" and rename, so a failed write leaves no partial file. */
#ifndef MX_IO_H
#define MX_IO_H

#include <stddef.h>

/* The runtime and geometry headers have no C++ guards of their own. */
#ifdef __cplusplus
extern "C" {
#endif

#include "../../runtime/status.h"
#include "../geom/mesh_types.h"

/* Images larger than this a side are refused, read or written, by every adapter: 16k × 16k
 * covers every texture matex produces or reads. */
#define MX_IMAGE_MAX_SIDE 16384

/* ---- meshes ---- */

/* Reads an .obj, .ply, .off or .stl file (chosen by extension, case-insensitive).
 * - vertices and faces are kept in file order; polygons are fan-triangulated in place
 *   (a face of n corners becomes n-2 consecutive triangles), so nfaces counts triangles;
 * - OBJ: per-corner UVs (vt) and normals (vn) with the file's own index lists, so seams are
 *   kept exactly (uv/face_uv as stored, v up); `usemtl` groups give face_mat and materials;
 *   `mtllib` is read for each material's map_Kd (resolved relative to the .mtl; a missing
 *   .mtl or texture file is a warning, texture_path is then ""); negative (relative) indices
 *   are supported; faces without vt in a file with vt get UV index -1 (documented "no UV");
 *   if no face has vt, nuv = 0 and face_uv = NULL (same for normals);
 * - PLY/OFF/STL via OpenMesh (STL's unshared corners are welded by OpenMesh); per-vertex
 *   texcoords of a PLY become per-corner UVs (face_uv = faces);
 * - validation: no faces, indices out of range, NaN/Inf positions -> error naming the file
 *   and the line or element. Degenerate faces are kept (see mx_mesh_topology). */
int mx_io_read_mesh(const char *path, mx_mesh *out, mx_status *st);

/* ---- images ---- */

/* Reads 8-bit PNG and EXR (matex's own readers) or anything OpenImageIO reads (JPEG, TIFF, 16-bit
 * PNG ...: libmatex_oiio.so, loaded then) into float [0,1] values (EXR: as stored), channels kept
 * (gray 1, RGB 3, RGBA 4; 2-channel gray+alpha is widened to RGBA; more than 4 are cut to 4),
 * no colour conversion (8-bit sRGB code values / 255). Row 0 is the top row. */
int mx_io_read_image(const char *path, mx_image *out, mx_status *st);

/* The same from bytes in memory (an image embedded in a GLB or a data: URI).
 * `what` names the source in error messages (e.g. "truck.glb image 0"). */
int mx_io_decode_image(const void *data, size_t len, const char *what, mx_image *out,
                       mx_status *st);

/* Writes an 8-bit PNG (values clamped to [0,1], rounded). c = 1, 3 or 4. */
int mx_io_write_png(const char *path, const mx_image *img, mx_status *st);

/* Encodes an 8-bit PNG into a malloc'ed buffer (*data, *len), e.g. for embedding in a GLB. */
int mx_io_encode_png(const mx_image *img, unsigned char **data, size_t *len, mx_status *st);

/* Writes a float (32-bit) EXR with channels Y, RGB or RGBA (c = 1, 3, 4), ZIP compression,
 * values as given (no clamping, no colour conversion). threads > 1: its blocks are compressed on
 * that many of OpenEXR's threads (its one process-wide pool, grown to that size by the first such
 * call); the file's bytes are the same for any count. */
int mx_io_write_exr(const char *path, const mx_image *img, int threads, mx_status *st);

#ifdef __cplusplus
}
#endif

#endif
