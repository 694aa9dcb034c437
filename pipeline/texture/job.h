/* A texturing job: what the stages of `matex texture`, `matex enhance` and `matex transfer` share —
 * the options, the output folder, the mesh with its normalised positions and UV layers, the bake
 * (texture accumulation and T^B), and each concern's state: generation (job_generate.h), views
 * (job_views.h), report (job_report.h); the end (job_output.h). Internal to pipeline/texture. */
#ifndef MX_JOB_H
#define MX_JOB_H

#include <stdint.h>

#include "../geom/uvatlas.h"
#include "job_generate.h"
#include "job_output.h"
#include "job_report.h"
#include "job_views.h"
#include "outdir.h"
#include "texture.h"

/* model_needs of mx_job_open for a job without networks (transfer). */
#define MX_JOB_NO_MODELS (-1)
/* The grey of texels nothing painted yet, in renders and control images. */
extern const float mx_job_grey[3];

typedef struct mx_job {
    const mx_texture_opts *o;
    unsigned verb; /* MX_VERB_TEXTURE, _ENHANCE or _TRANSFER: the report names it and its options */
    mx_outdir out; /* opened (checked, staging folder created) before anything else */
    mx_job_gen gen;
    mx_mesh mesh;
    float *pos;  /* normalised positions for rendering: (R p - center) * scale */
    float center[3], scale;
    int nlayers; /* textures: one per material keeping its own UVs, else 1 */
    int atlas_built;
    mx_uvatlas_report atlas;
    int keep_unreached; /* enhance: texels no view reached keep their colour (mx_job_finish does not fill) */
    int write_flags;    /* backprojection policy: MX_BACKPROJECT_OVERWRITE (angle-aware) or 0 (first wins), from o->pub.first_wins */
    mx_bake bake;
    int bake_ready;
    mx_job_sched sched;
    mx_job_rep rep;
} mx_job;

/* Output folder when o->pub.out_dir is set (checked, staging folder created), context and models
 * (o->models with its context, else loaded from o->weights_path; needs: MX_MODELS_NEED_*, or
 * MX_JOB_NO_MODELS), mesh (a copy of o->mesh, else loaded from o->pub.mesh_path) and its normalised
 * copy, bake sized tex_size with nlayers layers, candidate cache and the report's header. verb:
 * MX_VERB_* (enhance keeps the mesh's UVs, which it needs). mx_job_close removes the staging
 * folder of a run that did not finish. */
int mx_job_open(mx_job *j, const mx_texture_opts *o, int model_needs, unsigned verb, mx_status *st);
void mx_job_close(mx_job *j);

/* The context of a run (device, threads, precision of o), as a job or a model set makes it. */
int mx_job_ctx_create(mx_ctx *c, const mx_texture_opts *o, mx_status *st);

#endif
