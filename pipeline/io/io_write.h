/* What every image writer of the I/O adapters shares (io_write.c): the check that an image can
 * be written, its 8-bit code values, and the rename of a finished "<path>.tmp" into place. */
#ifndef MX_IO_WRITE_H
#define MX_IO_WRITE_H

#ifdef __cplusplus
extern "C" {
#endif

#include "../../runtime/status.h"
#include "../geom/mesh_types.h"

/* 0 when img holds pixels of 1, 3 or 4 channels; else fails naming `what`. */
int mx_io_check_writable(const mx_image *img, const char *what, mx_status *st);

/* The image's values clamped to [0,1] (NaN as 0) and rounded to 8-bit codes, h*w*c bytes,
 * malloc'ed; NULL when out of memory. */
unsigned char *mx_io_to_8bit(const mx_image *img);

/* Renames tmp to path; on failure removes tmp and fails naming path. */
int mx_io_rename_into_place(const char *tmp, const char *path, mx_status *st);

#ifdef __cplusplus
}
#endif

#endif
