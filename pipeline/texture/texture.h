/* The Make-A-Texture method (paper §3, docs/DESIGN.md §2) as one call: `matex texture` and
 * `matex enhance`.
 *
 * texture: load mesh (atlas if it has no UVs) -> front+back grid with depth control ->
 * backproject -> automatic view selection (Alg. 1) with depth + inpainting control, views
 * whose untextured texels do not overlap generated in one batch -> backproject into the
 * untextured texels -> UV fill -> export (PNG, EXR, OBJ/MTL, GLB, report.json).
 * enhance: the same views over an already textured mesh; each view's render is VAE-encoded,
 * noised to `strength` (SDEdit), denoised under the prompt and backprojected.
 *
 * Control-weight schedule (overridable): the grid uses w_D = grid_depth_weight (1.0) and no
 * inpainting; the k-th of the n later views (k = 0..n-1, t = k/(n-1), t = 0 when n = 1) uses
 * w_D = depth_weight[0] + t (depth_weight[1] - depth_weight[0])   (default 1.0 -> 0.7)
 * w_I = inpaint_weight[0] + t (inpaint_weight[1] - inpaint_weight[0]) (default 0.8 -> 1.0):
 * early views paint large new regions and follow the shape; late views fill small gaps and
 * must match what is already painted. */
#ifndef MX_TEXTURE_H
#define MX_TEXTURE_H

#include <signal.h>
#include <stdint.h>

#include "../../runtime/backend.h"

#include "../../runtime/status.h"
#include "../geom/image.h"
#include "../geom/mesh.h"

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

typedef struct mx_texture_opts {
    const char *mesh_path;       /* the mesh file, or NULL when `mesh` is given */
    const mx_mesh *mesh;         /* a mesh in memory (validated, then copied), or NULL */
    const mx_image *mesh_textures; /* enhance, mesh in memory: one texture per material, or NULL */
    const char *prompt;
    const char *negative_prompt; /* "" by default */
    const char *weights_path;    /* loaded for this run when `models` is NULL */
    const struct mx_models *models; /* a model set opened once (mx_models_load), reused by many runs */
    const char *out_dir;         /* the output folder; NULL: results only in memory (keep_outputs) */
    int keep_outputs;            /* the result takes the textured mesh, textures and report */
    mx_texture_progress_fn progress; /* NULL: none */
    void *progress_user;
    uint64_t seed;           /* 0 */
    int steps;               /* 10 */
    int views;               /* view budget, front and back included: 6 */
    int candidates;          /* candidate cameras on the Fibonacci lattice: 40 */
    int tex_size;            /* texture side: 1024 */
    int render_size;         /* side of the renders that are backprojected: 1024 */
    int image_size;          /* side of one model image: 512 (latent 64) */
    int max_batch;           /* most views generated in one batch: 4 */
    float guidance;          /* 7.5 */
    float grid_depth_weight; /* 1.0 */
    float depth_weight[2];   /* first, last later view: 1.0, 0.7 */
    float inpaint_weight[2]; /* first, last later view: 0.8, 1.0 */
    float frontal_threshold; /* |n.v| needed to backproject a pixel: 0.3 */
    int normal_source;       /* MX_NORMAL_FROM_DEPTH (paper) or MX_NORMAL_GEOMETRIC */
    float coverage_stop;     /* stop when this fraction of candidate-visible texels is painted (the
                                candidate coverage): 0.995 */
    mx_up_axis up;
    int threads;             /* 0: all CPUs */
    mx_backend_kind device;  /* where the networks run: cpu (default), cpu-strict, cuda */
    mx_precision precision;  /* of the networks' matrix products: bf16 (used where the CPU has it) */
    int quiet;
    float strength;          /* enhance: SDEdit strength in (0, 1]: 0.5 */
    const char *grid_word;   /* "front and back view of" */
    /* NULL, or a flag another context (a signal handler) sets to non-zero to stop the run: it is
     * checked between stages and between denoising steps; the run then fails with MX_ECANCEL
     * ("interrupted") and leaves no output folder and no staging folder behind. */
    volatile sig_atomic_t *cancel;
    int force;               /* replace an existing non-empty output folder (atomically) */
    const char *source_path; /* transfer: the textured mesh whose texture moves onto mesh_path */
    int fast;                /* few-step path: LCM scheduler + TAESD encoder/decoder; the weight file must
                                hold a merged LCM-LoRA (unet.lcm_lora) and taesd.* (texture, enhance) */
    int first_wins;          /* texture, transfer: 0 = angle-aware writes (default; a later view repaints
                                texels it sees with |n.v| higher by 0.15), 1 = the first writer keeps them */
    float background[3];     /* transfer: colour behind the source in its renders (0, 0, 0) */
    int through_model_image; /* transfer: each render goes through the model image (crop, image_size, back) */
} mx_texture_opts;

void mx_texture_opts_default(mx_texture_opts *o);

typedef enum { MX_TEXTURE_MODE_TEXTURE, MX_TEXTURE_MODE_ENHANCE, MX_TEXTURE_MODE_TRANSFER } mx_texture_mode;

/* Checks every option before any work (MX_EUSAGE, the message names the option, its value and
 * the valid range). mx_texture_run and mx_enhance_run call it first; front ends (the CLI, the
 * public API) call it too, to refuse bad options at once. */
int mx_texture_opts_check(const mx_texture_opts *o, mx_texture_mode mode, mx_status *st);

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
