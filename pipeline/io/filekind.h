/* What a file is, from its first bytes (magic numbers, as file(1) tells them), so that a mesh
 * path that names a folder, an image or another format is refused with what it really is,
 * before a reader fails on it with a message about its own format. */
#ifndef MX_FILEKIND_H
#define MX_FILEKIND_H

#include <stddef.h>
#include <stdint.h>

#include "../../runtime/status.h"

/* What the bytes head[0..n) of a file of file_size bytes are, as a phrase ("a PNG image",
 * "a PLY mesh", "text", "binary data"); *definite is 1 when a magic number says so (0 for the
 * guesses "text", "JSON text" and "binary data"). */
const char *mx_file_kind(const unsigned char *head, size_t n, uint64_t file_size, int *definite);

/* What the file at path is (mx_file_kind of its first 512 bytes); a folder ("is a directory,
 * not <what>") or an unreadable file is an error naming it. */
int mx_file_kind_of(const char *path, const char *what, const char **kind, int *definite, mx_status *st);

/* The mesh path is a readable file whose extension is a mesh format matex reads
 * (.obj .ply .off .stl .gltf .glb) and whose content is not clearly something else.
 * Otherwise one message naming the file, what it is and what was expected. */
int mx_mesh_check_file(const char *path, mx_status *st);

#endif
