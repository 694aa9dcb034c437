/* mx_image allocation (pipeline/geom/image.h). */
#include "image.h"

#include <stdint.h>
#include <stdlib.h>

int mx_image_alloc(mx_image *img, int w, int h, int c, mx_status *st) {
    img->w = img->h = img->c = 0;
    img->data = NULL;
    if (w <= 0 || h <= 0 || (c != 1 && c != 3 && c != 4) || (size_t)w * (size_t)h > SIZE_MAX / 16 / (size_t)c)
        return mx_fail(st, MX_EINPUT, "image: bad size %dx%dx%d", w, h, c);
    img->data = calloc((size_t)w * (size_t)h * (size_t)c, sizeof(float));
    if (!img->data) return mx_fail(st, MX_ENOMEM, "image: out of memory for %dx%dx%d", w, h, c);
    img->w = w;
    img->h = h;
    img->c = c;
    return 0;
}
