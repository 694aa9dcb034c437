/* Writing a file so that nobody ever sees a partial one: the bytes go to a fresh
 * "<path>.tmp.XXXXXX" next to it (mode 0644) and are renamed over path only when everything
 * was written; on any failure the temporary file is removed. */
#ifndef MX_ATOMIC_FILE_H
#define MX_ATOMIC_FILE_H

#include <stddef.h>
#include <stdio.h>

#include "status.h"

typedef struct mx_atomic_file {
    FILE *fp; /* write here */
    char *tmp;
    const char *path;
} mx_atomic_file;

int mx_atomic_open(mx_atomic_file *af, const char *path, mx_status *st);
/* ok = 0 when the caller's writes failed: the file is dropped. Returns 0 when path now holds
 * the complete file, else -1 with a message naming path. */
int mx_atomic_close(mx_atomic_file *af, int ok, mx_status *st);
/* The whole job for a buffer in memory. */
int mx_atomic_write(const char *path, const void *data, size_t len, mx_status *st);

#endif
