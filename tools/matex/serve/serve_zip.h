/* A mesh part sent as a .zip: one mesh (OBJ, PLY, STL, OFF, GLB or glTF) with its side files
 * (an OBJ's .mtl and textures, a glTF's .bin and images), unpacked into the job's own folder.
 * Read with runtime/zip.h, deflate inflated with zlib; no HTTP library, so the fuzzer
 * (tests/fuzz/fuzz_serve_request.c) links it. Every entry is checked before anything is
 * written: its name (relative, '/'-separated, no '.' or '..' component, no backslash, colon or
 * control byte, at most MX_SERVE_ZIP_NAME_MAX bytes), no link, no encryption, stored or deflate;
 * the archive: at most MX_SERVE_ZIP_MAX_ENTRIES entries, MX_SERVE_ZIP_MAX_BYTES uncompressed in
 * all, no entry over 1 MiB that inflates more than MX_SERVE_ZIP_MAX_RATIO times (zip bombs), and
 * exactly one mesh file. An entry's data must inflate to exactly its declared size and CRC.
 * Entries under __MACOSX/ (the resource forks macOS's archiver adds) are skipped. */
#ifndef MX_SERVE_ZIP_H
#define MX_SERVE_ZIP_H

#include <stddef.h>
#include <stdint.h>

#include "../../../runtime/zip.h"
#include "serve_request.h"

#define MX_SERVE_ZIP_MAX_ENTRIES 256
#define MX_SERVE_ZIP_MAX_BYTES ((uint64_t)1 << 30)
#define MX_SERVE_ZIP_MAX_RATIO 100
#define MX_SERVE_ZIP_NAME_MAX 255
/* The folder of the job that holds the unpacked archive, and the file naming its mesh (the mesh's
 * path inside the job folder: MX_SERVE_ZIP_DIR "/" NAME). */
#define MX_SERVE_ZIP_DIR "mesh"
#define MX_SERVE_ZIP_MESH_FILE "mesh_path"

/* A checked archive: its entries, and the mesh's index among them. */
typedef struct mx_serve_zip {
    mx_zip_entry *entries;
    size_t n;
    size_t mesh;
} mx_serve_zip;

/* Whether name (NUL-terminated) is a name an entry may have (see above). */
int mx_serve_zip_name_valid(const char *name);
/* Reads and checks the archive map[0..len): 0, or 400 "bad_zip" / 413 "too_large" in e.
 * mx_serve_zip_free frees z either way. */
int mx_serve_zip_check(const uint8_t *map, size_t len, mx_serve_zip *z, mx_serve_error *e);
void mx_serve_zip_free(mx_serve_zip *z);
/* Entry i's data, inflated and checked, written to fd (-1: checked only). */
int mx_serve_zip_unpack(const mx_serve_zip *z, size_t i, int fd, mx_serve_error *e);
/* Unpacks the archive at zip_path into job_dir/MX_SERVE_ZIP_DIR (made here) and writes
 * job_dir/MX_SERVE_ZIP_MESH_FILE; the mesh's path into mesh (cap bytes). */
int mx_serve_zip_extract(const char *zip_path, const char *job_dir, char *mesh, size_t cap, mx_serve_error *e);

#endif
