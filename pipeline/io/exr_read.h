/* EXR input through OpenEXR, without OpenImageIO (exr_read.cpp). */
#ifndef MX_EXR_READ_H
#define MX_EXR_READ_H

#include "io.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The EXR in data[0..len) as float values, no conversion: channels R G B (A), else Y (A), else
 * the first four by name; a 2-channel image is widened to RGBA as io.h says. */
int mx_exr_decode(const void *data, size_t len, const char *what, mx_image *out, mx_status *st);

#ifdef __cplusplus
}
#endif

#endif
