/* The mesh part a client sends to `matex serve` (`matex batch --server`, serve_client.c). A mesh
 * that is one file goes as it is; a mesh with side files goes as a zip of them all (docs/SERVE.md,
 * unpacked by serve_zip.c), each stored (runtime/zip.h's mx_zip_write) under its path relative
 * to the mesh's folder, as the mesh names it. A .gltf always goes as a zip: the server takes a
 * .gltf only inside one. The side files are those the mesh readers open (pipeline/io): an OBJ's
 * `mtllib` files (the rest of the line, relative to the OBJ) and their `map_Kd` textures (the
 * line's last word, relative to the .mtl); the buffer and image `uri`s of a glTF, .gltf or .glb
 * (%XX decoded; data: and remote URIs are not files). A .mtl or texture that is not there is left out, as a local run
 * ignores it; a missing buffer is an error, as it is for a local run. A side file outside the
 * mesh's folder (an absolute path, a '..' that climbs out, a link that leads out) is refused
 * rather than sent: a mesh someone else made must not send the user's other files to a server.
 * A name the server would refuse in a zip (serve_zip.h) is refused here, before the upload. */
#ifndef MX_SERVE_UPLOAD_H
#define MX_SERVE_UPLOAD_H

#include <stdio.h>

#include "../../../runtime/status.h"

/* *zip: NULL when the mesh at mesh_path goes as it is, else a temporary file (tmpfile(): gone
 * once closed) holding the zip of the mesh and its side files, at its start. */
int mx_serve_upload_zip(const char *mesh_path, FILE **zip, mx_status *st);

#endif
