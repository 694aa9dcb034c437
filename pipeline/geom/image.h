/* Float images, interleaved (HWC), row 0 at the top. Colour images hold sRGB-encoded
 * values in [0, 1] as read from 8-bit files (no linearisation). */
#ifndef MX_IMAGE_H
#define MX_IMAGE_H

#include "../../runtime/status.h"
#include "mesh_types.h"

int mx_image_alloc(mx_image *img, int w, int h, int c, mx_status *st);

#endif
