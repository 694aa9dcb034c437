/* Same seed, same bytes: the embedding API (include/matex.h) textures a cube in memory with the
 * demo weights (MATEX_DEMO_WEIGHTS) on model sets of 1 and 3 threads, in fp32, in bf16 (where the CPU
 * has it) and in the default (auto), and the textures and UVs must be identical byte for byte.
 * Uses nothing but the public API, so `make test-arm64` runs it on the core library under qemu. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../include/matex.h"
#include "util_test.h"

static const float CUBE_POS[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                     {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
static const int32_t CUBE_FACES[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                                          {3, 6, 2}, {3, 7, 6}, {0, 4, 7}, {0, 7, 3}, {1, 2, 6}, {1, 6, 5}};
static const matex_mesh CUBE = {8, 12, &CUBE_POS[0][0], &CUBE_FACES[0][0], 0, NULL, NULL, NULL, 1};

/* The cube textured at seed 5 on a model set of `threads` threads; NULL on failure. */
static matex_result *texture_cube(const char *weights, int threads, int precision) {
    matex_options o;
    matex_options_default(&o);
    o.mesh = &CUBE;
    o.prompt = "a wooden crate";
    /* small enough for qemu: one step, front and back and two more views */
    o.steps = 1;
    o.views = 4;
    o.image_size = 64;
    o.texture_size = o.render_size = 96;
    o.candidates = 8;
    o.seed = 5;
    o.threads = threads;
    if (precision >= 0) o.precision = precision;
    matex_error err;
    matex_models *m = matex_models_open(weights, &o, &err);
    matex_result *r = NULL;
    if (!m || matex_texture(m, &o, &r, &err)) fprintf(stderr, "test_texture_threads: %s\n", err.message);
    matex_models_close(m);
    return r;
}

static int same_result(const matex_result *a, const matex_result *b) {
    if (a->ntextures != b->ntextures || a->mesh.nuvs != b->mesh.nuvs) return 0;
    if (memcmp(a->mesh.uvs, b->mesh.uvs, (size_t)a->mesh.nuvs * 2 * sizeof(float))) return 0;
    for (int t = 0; t < a->ntextures; t++) {
        const matex_image *x = &a->textures[t], *y = &b->textures[t];
        if (x->width != y->width || x->height != y->height || x->channels != y->channels) return 0;
        if (memcmp(x->pixels, y->pixels, (size_t)x->width * x->height * x->channels * sizeof(float))) return 0;
    }
    return 1;
}

static void check_threads(const char *weights, int precision, const char *label) {
    matex_result *one = texture_cube(weights, 1, precision), *three = texture_cube(weights, 3, precision);
    CHECK(one && three);
    if (one && three) {
        int same = same_result(one, three);
        printf("%s: cube, seed 5, 1 vs 3 threads: %s (%d views, coverage %.3f)\n", label,
               same ? "identical textures and UVs" : "DIFFER", one->views, one->coverage);
        CHECK(same);
        CHECK(one->views > 0);
    }
    matex_result_free(one);
    matex_result_free(three);
}

int main(void) {
    const char *weights = getenv("MATEX_DEMO_WEIGHTS");
    if (!weights || access(weights, R_OK)) {
        printf("no demo weights (MATEX_DEMO_WEIGHTS; make test builds them)\n");
        return MX_TEST_SKIP;
    }
    check_threads(weights, MATEX_PRECISION_FP32, "fp32");
    check_threads(weights, MATEX_PRECISION_BF16, "bf16 (where the CPU has it)");
    check_threads(weights, -1, "default precision (auto)");
    return mx_test_finish("test_texture_threads");
}
