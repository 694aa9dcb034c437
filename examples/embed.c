/* Embedding matex: one model set, two runs. A cube built in memory is textured with the
 * results kept in memory; then, when given, a mesh file is textured into a folder with
 * progress lines. Ctrl-C stops a run cleanly (nothing is written).
 *   cc embed.c $(pkg-config --cflags --libs matex) -o embed
 *   ./embed [--quick] WEIGHTS.mxw [MESH OUT_DIR]      (--quick: tiny sizes, for test weights) */
#include <matex.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

static volatile sig_atomic_t stop;
static void on_sigint(int sig) { (void)sig; stop = 1; }

static int print_progress(void *user, const matex_progress *p) {
    (void)user;
    if (p->steps == 0) printf("  [%6.2fs] %-10s %s\n", p->seconds, p->stage, p->message);
    return 0; /* non-zero would cancel the run */
}

/* A unit cube: 8 corners, 12 counter-clockwise triangles, no UVs (matex builds an atlas). */
static const float cube_pos[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                     {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
static const int32_t cube_faces[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                                          {3, 6, 2}, {3, 7, 6}, {0, 4, 7}, {0, 7, 3}, {1, 2, 6}, {1, 6, 5}};

int main(int argc, char **argv) {
    int quick = argc > 1 && !strcmp(argv[1], "--quick");
    argv += quick;
    argc -= quick;
    if (argc != 2 && argc != 4) {
        fprintf(stderr, "usage: embed [--quick] WEIGHTS.mxw [MESH OUT_DIR]\n");
        return 2;
    }
    printf("matex %s\n", matex_version());
    signal(SIGINT, on_sigint);
    matex_options o;
    matex_options_default(&o);
    o.cancel = &stop;
    matex_error err;
    matex_models *models = matex_models_open(argv[1], &o, &err); /* once, for every run */
    if (!models) {
        fprintf(stderr, "embed: %s\n", err.message);
        return 1;
    }
    if (quick) {
        o.steps = 1;
        o.image_size = 64;
        o.texture_size = o.render_size = 128;
        o.candidates = 12;
    }

    /* 1. a mesh in memory, results in memory */
    matex_mesh cube = {8, 12, &cube_pos[0][0], &cube_faces[0][0], 0, NULL, NULL, NULL, 1};
    o.mesh = &cube;
    o.prompt = "a wooden crate";
    matex_result *r = NULL;
    if (matex_texture(models, &o, &r, &err)) {
        fprintf(stderr, "embed: cube: %s\n", err.message);
        matex_models_close(models);
        return 1;
    }
    const matex_image *t = &r->textures[0];
    double sum = 0;
    for (long i = 0; i < (long)t->width * t->height * t->channels; i++) sum += t->pixels[i];
    printf("cube: %d views, coverage %.3f, texture %dx%dx%d (mean %.3f), %d UVs, report %zu bytes\n", r->views,
           r->coverage, t->width, t->height, t->channels, sum / ((double)t->width * t->height * t->channels),
           r->mesh.nuvs, strlen(r->report_json));
    matex_result_free(r);

    /* 2. a mesh file, written to a folder, with progress */
    int rc = 0;
    if (argc == 4) {
        o.mesh = NULL;
        o.mesh_path = argv[2];
        o.out_dir = argv[3];
        o.prompt = "a weathered bronze statue";
        o.progress = print_progress;
        if (matex_texture(models, &o, NULL, &err)) {
            fprintf(stderr, "embed: %s\n", err.message);
            rc = err.code == MATEX_ECANCELLED ? 130 : 1;
        } else {
            printf("%s: written\n", argv[3]);
        }
    }
    matex_models_close(models);
    return rc;
}
