/* The Make-A-Texture method (paper §3, docs/DESIGN.md §2) as one call: `matex texture`,
 * `matex enhance` and `matex transfer` (transfer.c; mx_transfer_run, below, shares the run's
 * options, result and checks).
 *
 * texture: load mesh (atlas if it has no UVs) -> front+back grid with depth control ->
 * backproject -> automatic view selection (Alg. 1) with depth + inpainting control, views
 * overlapping by at most MX_VIEW_GROUP_OVERLAP (views.h) generated in one batch -> backproject into the
 * untextured texels -> UV fill -> export (PNG, EXR, OBJ/MTL, GLB, report.json).
 * enhance: the same views over an already textured mesh; each view's render is VAE-encoded,
 * noised to `strength` (SDEdit), denoised under the prompt and backprojected.
 *
 * Control-weight schedule (overridable): the grid uses w_D = grid_depth_weight and no
 * inpainting; the k-th of the n later views (k = 0..n-1, t = k/(n-1), t = 0 when n = 1) uses
 * w_D = depth_weight[0] + t (depth_weight[1] - depth_weight[0])   (by default decreasing)
 * w_I = inpaint_weight[0] + t (inpaint_weight[1] - inpaint_weight[0]) (by default increasing):
 * early views paint large new regions and follow the shape; late views fill small gaps and
 * must match what is already painted. */
#ifndef MX_TEXTURE_H
#define MX_TEXTURE_H

#include <signal.h>
#include <stdint.h>

#include "../../include/matex.h"
#include "../../runtime/backend.h"

#include "../../runtime/status.h"
#include "../geom/image.h"
#include "../geom/mesh.h"
#include "options.h" /* MX_VERB_*: the verb a run checks its options for */

struct mx_models;

/* A progress event: after each denoising step (step/steps set) and at each progress line. */
typedef struct mx_texture_progress {
    const char *stage;   /* "load", "grid", "views 3-4", "enhance view 2", "finish" */
    int step, steps;     /* denoising step (1-based) of the stage's diffusion call; 0, 0 outside one */
    int views_done;      /* views backprojected so far (front and back count as two) */
    int views_total;     /* the view budget */
    double coverage;     /* fraction of the mesh's texels (inside a face in UV space) painted so far */
    double seconds;      /* since the run started */
    const char *message; /* the progress line (the CLI prints it unless quiet) */
} mx_texture_progress;
/* Returns non-zero to cancel the run. */
typedef int (*mx_texture_progress_fn)(void *user, const mx_texture_progress *p);

/* A run's options: the public options (include/matex.h: every option a user sets, with the
 * defaults and ranges of the option table, pipeline/texture/options.h) and what only the library
 * gives a run. */
typedef struct mx_texture_opts {
    matex_options pub;           /* pub.mesh and pub.progress are the API's: the run reads `mesh`, `progress` */
    const char *weights_path;    /* loaded for this run when `models` is NULL */
    const struct mx_models *models; /* a model set opened once (mx_models_load), reused by many runs */
    const mx_mesh *mesh;         /* a mesh in memory (validated, then copied), or NULL: pub.mesh_path */
    const mx_image *mesh_textures; /* enhance, mesh in memory: one texture per material, or NULL */
    int keep_outputs;            /* the result takes the textured mesh, textures and report */
    mx_texture_progress_fn progress; /* NULL: none */
    void *progress_user;
} mx_texture_opts;

/* pub's choices in the pipeline's terms. */
int mx_texture_opts_normals(const mx_texture_opts *o);           /* MX_NORMAL_GEOMETRIC or _FROM_DEPTH */
mx_up_axis mx_texture_opts_up(const mx_texture_opts *o);
mx_precision mx_texture_opts_precision(const mx_texture_opts *o); /* auto resolved for this CPU */
/* A MATEX_PRECISION_* value as the precision a CPU context computes in (auto resolved). */
mx_precision mx_precision_of_option(int matex_precision);
mx_backend_kind mx_texture_opts_device(const mx_texture_opts *o); /* a checked name (cpu when NULL) */
const char *mx_texture_opts_device_name(const mx_texture_opts *o);

void mx_texture_opts_default(mx_texture_opts *o);

/* Checks every option before any work (MX_EUSAGE, the message names the option, its value and
 * the valid range): pub against the option table (mx_options_check), then what the run is given
 * (mesh, weights or model set, prompt, output), for the verb that runs (MX_VERB_TEXTURE, _ENHANCE or
 * _TRANSFER: options.h). mx_texture_run, mx_enhance_run and mx_transfer_run call it first. */
int mx_texture_opts_check(const mx_texture_opts *o, unsigned verb, mx_status *st);

typedef struct mx_texture_result {
    double coverage;   /* fraction of the mesh's texels (inside a face in UV space) painted by views */
    double candidate_coverage; /* fraction of the texels some candidate view sees painted (coverage_stop's measure) */
    int views;         /* views generated (front and back count as two) */
    double seconds;
    /* with keep_outputs: the mesh as exported (its UVs are the atlas when the input had none) */
    mx_mesh mesh;
    int ntex;            /* textures: 1, or one per material (mesh.face_mat picks) */
    mx_image *textures;  /* [ntex], RGB in [0, 1], row 0 at the top (v = 1) */
    char *report_json;
    /* Room a caller asks for (set before the run, kept by it): view_bytes per texture, zeroed,
     * reserved before the output folder is published so that nothing fails after it. */
    size_t view_bytes;
    void *views_room;
} mx_texture_result;

/* Both fill *res (when not NULL) on success; free it with mx_texture_result_free. */
int mx_texture_run(const mx_texture_opts *o, mx_texture_result *res, mx_status *st);
int mx_enhance_run(const mx_texture_opts *o, mx_texture_result *res, mx_status *st);
/* `matex transfer` (pipeline/texture/transfer.c): the texture of o->source_path moves onto
 * o->mesh_path (its UVs, or an atlas): the job's views (front, back, then Alg. 1 over the
 * candidates) render the source with its texture, each render is backprojected onto the
 * destination where both meshes are seen, then the job's fill and export. No networks: the
 * weights, prompt and sampler options are unused. Both meshes share pose and units. */
int mx_transfer_run(const mx_texture_opts *o, mx_texture_result *res, mx_status *st);
void mx_texture_result_free(mx_texture_result *res);

#endif
