/* Table of contents of a matex weight file, for `matex info`. */
#ifndef MX_WFINFO_H
#define MX_WFINFO_H

#include <stdio.h>

#include "../runtime/status.h"

/* 1 when the file at path starts with the weight-file magic (contents not validated). */
int mx_wf_is_weightfile(const char *path);
/* Opens and validates the file, then prints a summary per network (tensor count, parameters,
 * bytes per dtype), the metadata keys with their sizes and provenance, and one line per
 * tensor (name, dtype, shape, bytes). */
int mx_wf_print_info(const char *path, FILE *out, mx_status *st);

#endif
