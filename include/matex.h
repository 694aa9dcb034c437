/* matex: text-to-texture for 3D meshes (Make-A-Texture), the embedding API.
 *
 * The `matex` command is built on these calls. Open a model set (a weight file made by
 * `matex convert`) once, then texture as many meshes as you like with it:
 *
 *     matex_error err;
 *     matex_options o;
 *     matex_options_default(&o);
 *     matex_models *m = matex_models_open("sd15.mxw", &o, &err);
 *     o.prompt = "a rustic wooden chair";
 *     o.mesh_path = "chair.obj";          // or o.mesh = &my_mesh (in memory)
 *     o.out_dir = "out/chair";            // and/or keep the results in memory:
 *     matex_result *r;
 *     if (matex_texture(m, &o, &r, &err)) fprintf(stderr, "%s\n", err.message);
 *     ... r->textures[0].pixels, r->mesh.uvs ...
 *     matex_result_free(r);
 *     matex_models_close(m);
 *
 * Build: `pkg-config --cflags --libs matex` (installed by `make install`). The core library
 * (`make core`: libmatex_core.a, libc + libm + pthreads only) has no file readers or writers
 * for meshes and images: pass meshes in memory and keep the results in memory there.
 *
 * Conventions: every call that can fail returns 0 on success and -1 on failure with one line
 * naming the file and the problem in err->message (err may be NULL). A failed or cancelled
 * run writes nothing. The library keeps no global state of its own (only the level of its
 * stderr log is process-wide); a model set may be used by one run at a time (runs on different
 * model sets may go on in parallel threads). */
#ifndef MATEX_H
#define MATEX_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define MATEX_VERSION_MAJOR 0
#define MATEX_VERSION_MINOR 1
#define MATEX_VERSION_PATCH 0
#define MATEX_VERSION "0.1.0"

/* The version of the library linked (may differ from MATEX_VERSION with shared builds). */
const char *matex_version(void);

/* ---- errors ---- */

enum {
    MATEX_OK = 0,
    MATEX_EINPUT = 1,    /* a bad or missing file or mesh */
    MATEX_EUSAGE = 2,    /* an option out of range, a missing argument */
    MATEX_EIO = 3,       /* a failed write */
    MATEX_ENOMEM = 4,    /* out of memory */
    MATEX_EINTERNAL = 5,
    MATEX_ECANCELLED = 6 /* the cancel flag was set or the progress callback returned non-zero */
};

typedef struct matex_error {
    int code;           /* MATEX_OK or one of MATEX_E* */
    char message[1024]; /* one line, "" when code is MATEX_OK */
} matex_error;

/* ---- model sets ---- */

typedef struct matex_models matex_models;

struct matex_options;
/* Opens a weight file (mmap) and binds tokenizer, CLIP, UNet, ControlNets, VAE and scheduler on
 * the device of o, with o's threads and precision (o may be NULL: defaults); every run with this
 * set computes there, whatever its own options say about those three. NULL on failure. */
matex_models *matex_models_open(const char *weights_path, const struct matex_options *o, matex_error *err);
void matex_models_close(matex_models *m);
/* 1 when the set loaded a network of this kind (a name of weights/networks.h: "unet",
 * "controlnet", "vae", "text_encoder", "taesd", "image_encoder", "ip_adapter"), else 0. */
int matex_models_has_network(const matex_models *m, const char *name);

/* ---- meshes and images in memory ---- */

typedef struct matex_image {
    int width, height, channels; /* channels: 1, 3 or 4 */
    float *pixels;               /* [height][width][channels], values in [0, 1], row 0 at the top */
} matex_image;

/* Style images a run may take (files and images in memory together). */
#define MATEX_MAX_STYLE_IMAGES 8

typedef struct matex_mesh {
    int nverts, nfaces;
    const float *positions;  /* [nverts][3] */
    const int32_t *faces;    /* [nfaces][3] vertex indices, counter-clockwise front faces */
    int nuvs;                /* 0: no UVs (a UV atlas is built) */
    const float *uvs;        /* [nuvs][2], v up (v = 0 is the bottom row of a texture) */
    const int32_t *face_uvs; /* [nfaces][3] indices into uvs (NULL when nuvs is 0) */
    const int32_t *face_materials; /* [nfaces] texture index of each face, or NULL (all 0) */
    int nmaterials;          /* textures the mesh uses (1 when face_materials is NULL) */
} matex_mesh;

/* ---- options ---- */

/* Of the networks' matrix products: fp32; bf16 products with fp32 sums wherever the CPU has them; or
 * auto (the default), bf16 only where this CPU computes them faster than fp32 (`matex --version` says
 * which: AMX, AMD's AVX512_BF16, Arm's BF16), else fp32. A CUDA context ignores it. */
enum { MATEX_PRECISION_FP32 = 0, MATEX_PRECISION_BF16 = 1, MATEX_PRECISION_AUTO = 2 };

typedef struct matex_progress {
    const char *stage;   /* "load", "grid", "views 3-4", "enhance view 2", "finish" */
    int step, steps;     /* denoising step (1-based) of the stage; 0, 0 for other events */
    int views_done;      /* views painted so far (front and back count as two) */
    int views_total;     /* the view budget */
    double coverage;     /* fraction of the mesh's texels (inside a face in UV space) painted so far */
    double seconds;      /* since the run started */
    const char *message; /* a readable line */
} matex_progress;

/* Called from the thread that runs; return non-zero to cancel the run. */
typedef int (*matex_progress_fn)(void *user, const matex_progress *p);

/* Every field's default and valid range are those of the option of the same name (texture_size:
 * --texture-size, z_up: --up z, ...) that `matex texture --help` lists: one table
 * (pipeline/texture/options.c) gives both; matex_options_default sets the defaults, and a run
 * refuses a value out of range (MATEX_EUSAGE naming the option) before any work. */
typedef struct matex_options {
    /* the mesh: a file (.obj .ply .off .stl .gltf .glb), or a mesh in memory (copied) */
    const char *mesh_path;
    const matex_mesh *mesh;
    const matex_image *mesh_textures; /* enhance with a mesh in memory: [nmaterials] textures */
    const char *prompt;
    const char *negative_prompt;  /* NULL: "" */
    const char *out_dir;          /* write the output folder (texture.png/.exr, mesh.obj/.mtl/.glb,
                                     report.json); NULL: results in memory only */
    int force;                    /* replace an earlier output of matex in out_dir (atomically; a folder
                                     without its marker .matex-output, or holding other files, is refused); 0: refuse */
    uint64_t seed;                /* the same seed gives the same texture */
    int steps;                    /* denoising steps */
    int views;                    /* view budget, front and back included */
    int candidates;               /* candidate cameras */
    int texture_size;             /* texture side in texels */
    int render_size;              /* side of the renders that are backprojected */
    int image_size;               /* side of a generated image (a multiple of 64 for SD1.5) */
    int batch;                    /* most views generated in one batch */
    float guidance;               /* classifier-free guidance scale */
    float grid_depth_weight;      /* depth control weight of the grid */
    float depth_weight[2];        /* depth control weight of the first, last later view (enhance: [0], every view) */
    float inpaint_weight[2];      /* inpainting control weight of the first, last later view */
    float frontal_threshold;      /* min |n.v| of a backprojected pixel */
    float coverage_stop;          /* stop adding views at this painted fraction */
    float strength;               /* enhance: SDEdit strength */
    int fast;                     /* few-step path (LCM + TAESD; the weight file must hold both);
                                     set steps 4 and guidance 1 with it, as `matex texture --fast` does */
    int geometric_normals;        /* 0: normals from depth (the paper) */
    int z_up;                     /* 0: the mesh is y-up */
    const char *front_back_words; /* prompt prefix of the grid */
    /* image guidance (IP-Adapter; the weight file must hold image_encoder.* and ip_adapter.*, made by
       `matex convert ... --image-encoder DIR --ip-adapter FILE`): every style image is encoded once per
       run, and its image tokens (concatenated over the images) steer every view at style_scale */
    const char *style_images[MATEX_MAX_STYLE_IMAGES]; /* files (PNG, JPEG, TIFF); the first NULL ends the list */
    const matex_image *style_pixels; /* [n_style_pixels] images in memory (1, 3 or 4 channels; alpha
                                        ignored), after the files */
    int n_style_pixels;
    float style_scale;            /* weight of the image tokens (0: the same texture as without them) */
    int front_render;             /* also write front.png: the textured mesh from the front, image_size
                                     pixels (what `matex batch --theme-from-first` passes on) */
    /* transfer (matex_transfer): the texture of source_path moves onto the mesh */
    const char *source_path;      /* the textured mesh */
    float background[3];          /* colour behind the source in its renders */
    int first_wins;               /* 0: a later view restarts texels it sees more frontally (|n.v| higher by
                                     0.15); 1: the first writer keeps them */
    int through_model_image;      /* 1: each render goes through an image_size model image (crop, resize, back) */
    /* read by matex_models_open (a run uses those of its model set): */
    int threads;                  /* 0: all CPUs */
    int precision;                /* MATEX_PRECISION_AUTO (default), _BF16 or _FP32 (see the enum) */
    const char *device;           /* "cpu" (default), "cpu-strict", "cuda" (a `make cuda` build) */
    int verbose;                  /* 1: progress lines on stderr */
    matex_progress_fn progress;   /* NULL: none */
    void *progress_user;
    volatile sig_atomic_t *cancel; /* a flag set non-zero (e.g. by a signal handler) stops the run */
} matex_options;

void matex_options_default(matex_options *o);

/* ---- runs ---- */

typedef struct matex_result {
    double coverage;       /* fraction of the mesh's texels (inside a face in UV space) painted by views */
    int views;             /* views generated */
    double seconds;
    matex_mesh mesh;       /* the textured mesh: positions and faces as given, UVs (an atlas when
                              the input had none), face_materials picks the texture */
    int ntextures;
    matex_image *textures; /* [ntextures], RGB */
    const char *report_json; /* views, poses, prompts, weights, coverage, time per stage */
} matex_result;

/* Textures a mesh (Make-A-Texture). *result (result may be NULL) is set on success. */
int matex_texture(matex_models *m, const matex_options *o, matex_result **result, matex_error *err);
/* Enhances the texture of a textured mesh (SDEdit over views). */
int matex_enhance(matex_models *m, const matex_options *o, matex_result **result, matex_error *err);
/* Moves the texture of o->source_path (a textured mesh) onto o->mesh_path or o->mesh (its UVs, or an
 * atlas): the views texture would choose render the source, each render is backprojected onto the
 * mesh. No networks run: m may be NULL (a context with o's threads is made for the run); prompt,
 * sampler and weight options are unused. Both meshes share pose and units. */
int matex_transfer(matex_models *m, const matex_options *o, matex_result **result, matex_error *err);
/* Writes a result's output folder as out_dir does (force: replace an earlier output of matex). */
int matex_result_write(const matex_result *r, const char *out_dir, int force, matex_error *err);
void matex_result_free(matex_result *r);

#ifdef __cplusplus
}
#endif

#endif
