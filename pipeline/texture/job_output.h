/* The end of a job: the fill of unreached texels, the output folder and the in-memory result
 * (job_output.c). Internal to pipeline/texture. */
#ifndef MX_JOB_OUTPUT_H
#define MX_JOB_OUTPUT_H

#include "../geom/image.h"
#include "texture.h"

/* mx_job (job.h) as its stages see it. */
typedef struct mx_job mx_job;

/* Fills unreached texels (harmonic fill across UV seams inside the charts, mx_uv_fill_harmonic;
 * gutter dilation) of every layer. */
int mx_job_fill_textures(mx_job *j, mx_image *tex, mx_status *st);
/* Fills unreached texels, writes the output folder (staged, then moved into place) when
 * o->pub.out_dir is set, and fills res (may be NULL): with o->keep_outputs it takes the textures
 * (their data is moved: textures[l] is left empty), the mesh and the report. Fails without writing
 * anything once the run is cancelled; nothing can fail after the folder is published. */
int mx_job_finish(mx_job *j, mx_image *textures, mx_texture_result *res, mx_status *st);
#endif
