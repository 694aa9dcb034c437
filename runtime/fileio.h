/* Reading small whole files (configs, vocabularies, reports) with size limits and errors
 * that name the file; joining paths; making folders. */
#ifndef MX_FILEIO_H
#define MX_FILEIO_H

#include <stddef.h>

#include "status.h"

/* The whole file as a malloc'ed, NUL-terminated buffer; *len (may be NULL) gets its length.
 * Files larger than max_bytes are refused. NULL with an error in st on failure. */
char *mx_read_file(const char *path, size_t max_bytes, size_t *len, mx_status *st);

/* out = dir + "/" + name; -1 with "DIR: path too long" (MX_EINPUT) when it does not fit in cap. */
int mx_path_join(char *out, size_t cap, const char *dir, const char *name, mx_status *st);

/* mkdir -p: path and every missing folder above it, each with `mode` (less the umask); folders
 * that exist are fine. */
int mx_make_folders(const char *path, unsigned mode, mx_status *st);

#endif
