/* The OpenImageIO adapter, libmatex_oiio.so (pipeline/io/imageio.cpp): the image formats matex
 * does not read itself (JPEG, TIFF, BMP, HDR, palette/16-bit/interlaced PNG ...). Debian's
 * OpenImageIO brings ~250 libraries (1.3 s and 134 MB at start-up), so it is not linked into
 * matex: image_files.c opens this library with dlopen() the first time a file needs it.
 * Where it is found (image_files.c): beside the running program or in ../lib of it (matex: build/
 * in the tree, PREFIX/lib once installed), else by dlopen's search: LD_LIBRARY_PATH, the RUNPATH
 * of the program that links libmatex_io (matex.pc adds PREFIX/lib), the system's paths.
 * Both functions follow io.h's conventions (0 or -1 with st filled; out owns malloc'ed pixels). */
#ifndef MX_OIIO_ADAPTER_H
#define MX_OIIO_ADAPTER_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#include "../../runtime/status.h"
#include "../geom/mesh_types.h"

#define MX_OIIO_LIBRARY "libmatex_oiio.so"

/* Reads the file at path with OpenImageIO's reader of `format` (an extension: "jpg", "tif"). */
typedef int mx_oiio_read_fn(const char *path, const char *format, mx_image *out, mx_status *st);
#define MX_OIIO_READ "mx_oiio_read"

/* Decodes data[0..len) (an image held in memory) with the reader of `format` ("png", "jpg");
 * `what` names the source in errors. A PNG must have passed mx_png_check first. */
typedef int mx_oiio_decode_fn(const void *data, size_t len, const char *format, const char *what, mx_image *out,
                              mx_status *st);
#define MX_OIIO_DECODE "mx_oiio_decode"

#ifdef __cplusplus
}
#endif

#endif
