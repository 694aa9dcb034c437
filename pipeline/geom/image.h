/* Float images, interleaved (HWC), row 0 at the top. Colour images hold sRGB-encoded
 * values in [0, 1] as read from 8-bit files (no linearisation). */
#ifndef MX_IMAGE_H
#define MX_IMAGE_H

#include "../../runtime/status.h"

typedef struct mx_image {
    int w, h, c; /* c = 1, 3 or 4 */
    float *data; /* [h][w][c] */
} mx_image;

int mx_image_alloc(mx_image *img, int w, int h, int c, mx_status *st);
void mx_image_free(mx_image *img);

#endif
