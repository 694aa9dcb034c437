/* Zip archives in memory, as the PKWARE APPNOTE lays them out: the end of central directory
 * record (and its zip64 form), the central directory entries (with the zip64 extra field) and
 * the local headers. mx_zip_read lists the entries of a mapped archive, every size and offset
 * checked against it; an entry's data is left as stored: method 0 (stored) is the bytes
 * themselves, method 8 (deflate) is for the caller to inflate (runtime links no zlib).
 * Readers: weights/torchzip.c (PyTorch checkpoints, stored entries only) and
 * tools/matex/serve/serve_zip.c (a mesh with its side files). */
#ifndef MX_ZIP_H
#define MX_ZIP_H

#include <stddef.h>
#include <stdint.h>

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

#endif
