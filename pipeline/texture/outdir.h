/* Writing a run's output folder so that a failure leaves nothing half-written: the files are
 * written into "<dir>.partial-<pid>", then moved into <dir> (created when missing; files of
 * the same names in an existing <dir> are replaced), and the staging folder is removed. */
#ifndef MX_OUTDIR_H
#define MX_OUTDIR_H

#include "../../runtime/status.h"
#include "../geom/image.h"
#include "../geom/mesh.h"

int mx_outdir_write(const char *dir, const mx_mesh *m, const mx_image *textures, int ntex, const char *report_json,
                    mx_status *st);

#endif
