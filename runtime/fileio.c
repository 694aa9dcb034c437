#include "fileio.h"

#include <errno.h>
#include <sys/stat.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

char *mx_read_file(const char *path, size_t max_bytes, size_t *len, mx_status *st) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
        return NULL;
    }
    char *buf = NULL;
    long n = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    if (n < 0 || fseek(f, 0, SEEK_SET) != 0) {
        mx_fail(st, MX_EINPUT, "%s: cannot determine the file size", path);
    } else if ((unsigned long)n > max_bytes) {
        mx_fail(st, MX_EINPUT, "%s: larger than %zu bytes", path, max_bytes);
    } else if (!(buf = malloc((size_t)n + 1))) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    } else if (fread(buf, 1, (size_t)n, f) != (size_t)n) {
        mx_fail(st, MX_EIO, "%s: read error", path);
        free(buf);
        buf = NULL;
    } else {
        buf[n] = 0;
        if (len) *len = (size_t)n;
    }
    fclose(f);
    return buf;
}

int mx_path_join(char *out, size_t cap, const char *dir, const char *name, mx_status *st) {
    int n = snprintf(out, cap, "%s/%s", dir, name);
    if (n < 0 || (size_t)n >= cap) return mx_fail(st, MX_EINPUT, "%s: path too long", dir);
    return 0;
}

int mx_make_folders(const char *path, unsigned mode, mx_status *st) {
    char p[4096];
    if ((size_t)snprintf(p, sizeof p, "%s", path) >= sizeof p) return mx_fail(st, MX_EINPUT, "%s: path too long", path);
    for (char *s = p + 1;; s++) {
        if (*s != '/' && *s) continue;
        char c = *s;
        *s = 0;
        if (mkdir(p, (mode_t)mode) && errno != EEXIST)
            return mx_fail(st, MX_EIO, "%s: cannot create folder: %s", p, strerror(errno));
        *s = c;
        if (!c) return 0;
    }
}
