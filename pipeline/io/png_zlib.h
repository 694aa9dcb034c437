/* An 8-bit PNG codec on zlib alone: matex reads and writes PNG with it, without OpenImageIO
 * (image_files.c). Decodes non-interlaced 8-bit grey, grey+alpha (widened to RGBA), RGB and
 * RGBA: every PNG this project writes and what most tools write; palette, 16-bit and interlaced
 * files are refused here (image_files.c hands them to the OpenImageIO adapter). Encodes 1, 3 or
 * 4 channels. Every length, CRC and size in the file is checked before use. */
#ifndef MX_PNG_ZLIB_H
#define MX_PNG_ZLIB_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#include "../../runtime/status.h"
#include "../geom/mesh_types.h"

/* The structure of the PNG in data[0..len), before any decoder sees it (both adapters call it):
 * the signature, every chunk's length and CRC up to IEND, one IHDR and first, at most
 * MX_IMAGE_MAX_SIDE a side, and no more rows than the IDAT bytes can hold (deflate expands at
 * most 1032:1: a few hundred bytes declaring 16k × 16k would have a decoder allocate gigabytes
 * before the data runs out). Bit depth, colour type and interlace are the decoder's to judge. */
int mx_png_check(const void *data, size_t len, const char *what, mx_status *st);

/* 1 when a PNG that mx_png_check accepted is of a kind mx_png_decode reads (8-bit, no palette,
 * not interlaced); 0 otherwise. */
int mx_png_zlib_reads(const void *data);

/* The PNG in data[0..len) as float [0,1] values; `what` names it in errors. */
int mx_png_decode(const void *data, size_t len, const char *what, mx_image *out, mx_status *st);

/* img as an 8-bit PNG in a malloc'ed buffer (*data, *len). */
int mx_png_encode(const mx_image *img, unsigned char **data, size_t *len, mx_status *st);

#ifdef __cplusplus
}
#endif

#endif
