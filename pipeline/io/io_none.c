/* The file I/O adapter of the core build (`make core`): no third-party format libraries, so
 * mesh files other than glTF/GLB, image files and PNG/EXR output are refused with a clear
 * message. Meshes and results pass through memory there (include/matex.h). */
#include "io.h"

#include <string.h>

static int no_file_io(const char *what, mx_status *st) {
    return mx_fail(st, MX_EINPUT, "%s: this build has no file I/O adapter (make core): pass meshes and images in memory",
                   what);
}

int mx_io_read_mesh(const char *path, mx_mesh *out, mx_status *st) {
    memset(out, 0, sizeof *out);
    return no_file_io(path, st);
}

int mx_io_read_image(const char *path, mx_image *out, mx_status *st) {
    memset(out, 0, sizeof *out);
    return no_file_io(path, st);
}

int mx_io_decode_image(const void *data, size_t len, const char *what, mx_image *out, mx_status *st) {
    (void)data;
    (void)len;
    memset(out, 0, sizeof *out);
    return no_file_io(what, st);
}

int mx_io_write_png(const char *path, const mx_image *img, mx_status *st) {
    (void)img;
    return no_file_io(path, st);
}

int mx_io_encode_png(const mx_image *img, unsigned char **data, size_t *len, mx_status *st) {
    (void)img;
    *data = NULL;
    *len = 0;
    return no_file_io("PNG", st);
}

int mx_io_write_exr(const char *path, const mx_image *img, int threads, mx_status *st) {
    (void)img, (void)threads;
    return no_file_io(path, st);
}
