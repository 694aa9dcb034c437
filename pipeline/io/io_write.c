/* Helpers shared by the image writers (io_write.h). */
#include "io_write.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

int mx_io_check_writable(const mx_image *img, const char *what, mx_status *st) {
    if (!img || !img->data || img->w <= 0 || img->h <= 0 || (img->c != 1 && img->c != 3 && img->c != 4))
        return mx_fail(st, MX_EINPUT, "%s: nothing to write (empty image or %d channels)", what, img ? img->c : 0);
    return 0;
}

unsigned char *mx_io_to_8bit(const mx_image *img) {
    size_t n = (size_t)img->w * img->h * img->c;
    unsigned char *px = malloc(n);
    if (!px) return NULL;
    for (size_t i = 0; i < n; i++) {
        float v = img->data[i];
        v = v != v ? 0.f : v < 0.f ? 0.f : v > 1.f ? 1.f : v;
        px[i] = (unsigned char)lrintf(v * 255.f);
    }
    return px;
}

int mx_io_rename_into_place(const char *tmp, const char *path, mx_status *st) {
    if (rename(tmp, path) != 0) {
        remove(tmp);
        return mx_fail(st, MX_EIO, "%s: cannot rename the temporary file into place", path);
    }
    return 0;
}
