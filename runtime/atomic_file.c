#include "atomic_file.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

int mx_atomic_open(mx_atomic_file *af, const char *path, mx_status *st) {
    memset(af, 0, sizeof *af);
    af->path = path;
    size_t cap = strlen(path) + 16;
    af->tmp = malloc(cap);
    if (!af->tmp) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    snprintf(af->tmp, cap, "%s.tmp.XXXXXX", path);
    int fd = mkstemp(af->tmp);
    if (fd >= 0) fchmod(fd, 0644); /* mkstemp makes 0600; outputs are ordinary shared files */
    af->fp = fd >= 0 ? fdopen(fd, "wb") : NULL;
    if (!af->fp) {
        int err = errno;
        if (fd >= 0) {
            close(fd);
            unlink(af->tmp);
        }
        free(af->tmp);
        af->tmp = NULL;
        return mx_fail(st, MX_EIO, "%s: cannot create a temporary file next to it: %s", path, strerror(err));
    }
    setvbuf(af->fp, NULL, _IOFBF, 1 << 20);
    return 0;
}

int mx_atomic_close(mx_atomic_file *af, int ok, mx_status *st) {
    if (!af->fp) return -1;
    ok &= !ferror(af->fp);
    ok &= fclose(af->fp) == 0;
    af->fp = NULL;
    int rc = 0;
    if (!ok || rename(af->tmp, af->path) != 0) {
        rc = mx_fail(st, MX_EIO, "%s: write failed: %s", af->path, errno ? strerror(errno) : "I/O error");
        unlink(af->tmp);
    }
    free(af->tmp);
    af->tmp = NULL;
    return rc;
}

int mx_atomic_write(const char *path, const void *data, size_t len, mx_status *st) {
    mx_atomic_file af;
    if (mx_atomic_open(&af, path, st)) return -1;
    return mx_atomic_close(&af, len == 0 || fwrite(data, 1, len, af.fp) == len, st);
}
