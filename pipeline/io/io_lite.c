/* The images of the file adapter of `matex-lite` (io.h): PNG through png_zlib.c instead of
 * OpenImageIO; meshes (meshio.cpp, OpenMesh) and EXR output (exrio.cpp, OpenEXR) as in the full
 * build. JPEG, TIFF and the other formats OpenImageIO reads are refused with a clear message. */
#include "io.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "io_write.h"
#include "png_zlib.h"

enum { MAX_FILE = 1 << 30 }; /* a PNG of 16384² RGBA, stored uncompressed, is 1 GiB */

/* The whole regular file at path in a malloc'ed buffer. */
static int read_whole_file(const char *path, unsigned char **data, size_t *len, mx_status *st) {
    struct stat sb;
    *data = NULL;
    if (stat(path, &sb)) return mx_fail(st, MX_EINPUT, "%s: cannot open image: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: cannot open image: not a regular file", path);
    if (sb.st_size > MAX_FILE) return mx_fail(st, MX_EINPUT, "%s: image file larger than 1 GiB", path);
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open image: %s", path, strerror(errno));
    *len = (size_t)sb.st_size;
    *data = malloc(*len ? *len : 1);
    int ok = *data && fread(*data, 1, *len, f) == *len;
    fclose(f);
    if (!ok) {
        free(*data);
        *data = NULL;
        return mx_fail(st, MX_EINPUT, "%s: cannot read the image file", path);
    }
    return 0;
}

int mx_io_read_image(const char *path, mx_image *out, mx_status *st) {
    unsigned char *data;
    size_t len = 0;
    memset(out, 0, sizeof *out);
    if (read_whole_file(path, &data, &len, st)) return -1;
    int rc = mx_io_decode_image(data, len, path, out, st);
    free(data);
    return rc;
}

int mx_io_decode_image(const void *data, size_t len, const char *what, mx_image *out, mx_status *st) {
    return mx_png_decode(data, len, what, out, st);
}

int mx_io_encode_png(const mx_image *img, unsigned char **data, size_t *len, mx_status *st) {
    return mx_png_encode(img, data, len, st);
}

int mx_io_write_png(const char *path, const mx_image *img, mx_status *st) {
    unsigned char *png;
    size_t len;
    if (mx_png_encode(img, &png, &len, st)) return mx_fail_prefix(st, "%s", path);
    char tmp[4096];
    if (snprintf(tmp, sizeof tmp, "%s.tmp", path) >= (int)sizeof tmp) {
        free(png);
        return mx_fail(st, MX_EINPUT, "%s: path too long", path);
    }
    FILE *f = fopen(tmp, "wb");
    int ok = f && fwrite(png, 1, len, f) == len;
    if (f && fclose(f)) ok = 0;
    free(png);
    if (!ok) {
        remove(tmp);
        return mx_fail(st, MX_EIO, "%s: cannot write PNG: %s", path, strerror(errno));
    }
    return mx_io_rename_into_place(tmp, path, st);
}
