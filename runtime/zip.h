/* Zip archives, as the PKWARE APPNOTE lays them out: the end of central directory record (and
 * its zip64 form), the central directory entries (with the zip64 extra field) and the local
 * headers. mx_zip_read lists the entries of a mapped archive, every size and offset checked
 * against it; an entry's data is left as stored: method 0 (stored) is the bytes themselves,
 * method 8 (deflate) is for the caller to inflate (runtime links no zlib).
 * Readers: weights/torchzip.c (PyTorch checkpoints, stored entries only) and
 * tools/matex/serve/serve_zip.c (a mesh with its side files). mx_zip_write writes the smallest
 * archive any reader takes (stored entries, no zip64) from files on disk; its writer:
 * tools/matex/serve/serve_upload.c (a mesh with its side files, sent to a server). */
#ifndef MX_ZIP_H
#define MX_ZIP_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "status.h"

typedef struct mx_zip_entry {
    const char *name;    /* inside the central directory, not NUL-terminated */
    size_t name_len;
    unsigned method;     /* 0 stored, 8 deflate, ... */
    unsigned flags;      /* general purpose bits (bit 0: encrypted) */
    int is_link;         /* made on Unix with a symbolic link's mode */
    uint32_t crc;        /* CRC-32 of the uncompressed data */
    const uint8_t *data; /* csize bytes inside the archive */
    uint64_t csize, usize;
} mx_zip_entry;

/* Whether the first bytes are a zip local header ("PK\3\4"). */
int mx_zip_is_zip(const void *head, size_t n);

/* The entries of the archive map[0..len) (path names it in messages): *entries (free()) and *n.
 * More than max_entries is an error. */
int mx_zip_read(const uint8_t *map, size_t len, const char *path, uint64_t max_entries, mx_zip_entry **entries,
                size_t *n, mx_status *st);

/* One file of an archive being written: its name inside ('/'-separated, relative) and the file
 * its bytes are read from. */
typedef struct mx_zip_source {
    const char *name;
    const char *path;
} mx_zip_source;

/* Writes the files src[0..n) to out (what names it in messages) as a zip: each entry stored
 * (method 0), a regular file (mode 0644, made on Unix), dated 1980-01-01 so that the same files
 * give the same bytes, its CRC-32 and size in its local header (written after the data: out must
 * be seekable, e.g. tmpfile()) and in the central directory. No zip64: a file or archive of
 * 4 GiB or more, or more than 65535 files, is refused. On failure out holds a partial archive. */
int mx_zip_write(FILE *out, const mx_zip_source *src, size_t n, const char *what, mx_status *st);

#endif
