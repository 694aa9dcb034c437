/* The embedding API (include/matex.h) with the demo weights (MATEX_DEMO_WEIGHTS): one model
 * set reused by several runs, a mesh in memory and the same mesh from a file give the same
 * texture, results in memory written later equal a run's output folder, progress events,
 * cancellation by flag and by callback (nothing written), bad input, style images (refused ones,
 * one in memory), enhance in memory, transfer. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../include/matex.h"
#include "../runtime/fileio.h"
#include "util_test.h"

static const float CUBE_POS[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                     {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
static const int32_t CUBE_FACES[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                                          {3, 6, 2}, {3, 7, 6}, {0, 4, 7}, {0, 7, 3}, {1, 2, 6}, {1, 6, 5}};
static const matex_mesh CUBE = {8, 12, &CUBE_POS[0][0], &CUBE_FACES[0][0], 0, NULL, NULL, NULL, 1};

static void small_options(matex_options *o) {
    matex_options_default(o);
    o->prompt = "a wooden crate";
    o->steps = 2;
    o->image_size = 64;
    o->texture_size = 128;
    o->render_size = 128;
    o->candidates = 12;
    o->threads = 2;
    o->seed = 3;
}

static void write_cube_obj(const char *path) {
    FILE *f = fopen(path, "w");
    if (!f) return;
    for (int v = 0; v < 8; v++) fprintf(f, "v %g %g %g\n", CUBE_POS[v][0], CUBE_POS[v][1], CUBE_POS[v][2]);
    for (int t = 0; t < 12; t++) fprintf(f, "f %d %d %d\n", CUBE_FACES[t][0] + 1, CUBE_FACES[t][1] + 1, CUBE_FACES[t][2] + 1);
    fclose(f);
}

static int exists(const char *dir, const char *name) {
    char p[2048];
    snprintf(p, sizeof p, "%s%s%s", dir, name ? "/" : "", name ? name : "");
    struct stat sb;
    return stat(p, &sb) == 0;
}

static int same_file(const char *dir_a, const char *dir_b, const char *name) {
    char a[2048], b[2048];
    snprintf(a, sizeof a, "%s/%s", dir_a, name);
    snprintf(b, sizeof b, "%s/%s", dir_b, name);
    size_t la, lb;
    char *x = mx_read_file(a, (size_t)1 << 28, &la, NULL), *y = mx_read_file(b, (size_t)1 << 28, &lb, NULL);
    int eq = x && y && la == lb && !memcmp(x, y, la);
    free(x);
    free(y);
    return eq;
}

typedef struct progress_log {
    int events, steps, last_views, stop_at_step;
} progress_log;

static int on_progress(void *user, const matex_progress *p) {
    progress_log *l = user;
    l->events++;
    l->steps += p->steps > 0;
    l->last_views = p->views_done;
    return l->stop_at_step && p->step >= l->stop_at_step;
}

/* In memory vs from a file, one model set; results kept, then written. */
static void test_memory_and_file(matex_models *m, const char *tmp) {
    char obj[1024], out_file[1024], out_mem[1024];
    snprintf(obj, sizeof obj, "%s/cube.obj", tmp);
    snprintf(out_file, sizeof out_file, "%s/from_file", tmp);
    snprintf(out_mem, sizeof out_mem, "%s/from_memory", tmp);
    write_cube_obj(obj);
    matex_options o;
    matex_error err;
    small_options(&o);
    o.mesh = &CUBE;
    progress_log log = {0};
    o.progress = on_progress;
    o.progress_user = &log;
    matex_result *r = NULL;
    CHECK(matex_texture(m, &o, &r, &err) == 0 && r);
    if (!r) {
        fprintf(stderr, "%s\n", err.message);
        return;
    }
    printf("cube in memory: %d views, coverage %.4f, %d progress events (%d steps), %d UVs\n", r->views, r->coverage,
           log.events, log.steps, r->mesh.nuvs);
    CHECK(r->ntextures == 1 && r->textures[0].width == 128 && r->textures[0].channels == 3);
    CHECK(r->mesh.nfaces == 12 && r->mesh.nuvs > 0 && r->mesh.face_uvs);
    CHECK(r->coverage > 0.9);
    CHECK(log.steps >= 2 * 2 && log.last_views == r->views);
    CHECK(strstr(r->report_json, "mesh in memory") != NULL);
    CHECK(matex_result_write(r, out_mem, 0, &err) == 0);
    matex_result_free(r);

    small_options(&o);
    o.mesh_path = obj;
    o.out_dir = out_file;
    CHECK(matex_texture(m, &o, NULL, &err) == 0);
    int same = same_file(out_file, out_mem, "texture.exr") && same_file(out_file, out_mem, "mesh.glb");
    printf("mesh in memory, written later == mesh file, written by the run: %s\n", same ? "identical" : "DIFFERENT");
    CHECK(same);
}

static void test_cancel(matex_models *m, const char *tmp) {
    char out[1024];
    snprintf(out, sizeof out, "%s/cancelled", tmp);
    matex_options o;
    matex_error err;
    small_options(&o);
    o.mesh = &CUBE;
    o.out_dir = out;
    volatile sig_atomic_t flag = 1;
    o.cancel = &flag;
    CHECK(matex_texture(m, &o, NULL, &err) != 0 && err.code == MATEX_ECANCELLED);
    printf("cancel flag set: %s (code %d)\n", err.message, err.code);
    progress_log log = {0, 0, 0, 1};
    o.cancel = NULL;
    o.progress = on_progress;
    o.progress_user = &log;
    CHECK(matex_texture(m, &o, NULL, &err) != 0 && err.code == MATEX_ECANCELLED);
    printf("progress callback stops at step 1: %s (code %d, %d steps seen)\n", err.message, err.code, log.steps);
    CHECK(log.steps == 1);
    CHECK(!exists(out, NULL));
}

static void test_bad_input(matex_models *m) {
    matex_error err;
    CHECK(matex_models_open("/nonexistent/w.mxw", NULL, &err) == NULL && strstr(err.message, "/nonexistent/w.mxw"));
    printf("missing weights: %s\n", err.message);
    int32_t bad_faces[3] = {0, 1, 9};
    matex_mesh bad = {3, 1, &CUBE_POS[0][0], bad_faces, 0, NULL, NULL, NULL, 1};
    matex_options o;
    small_options(&o);
    o.mesh = &bad;
    matex_result *r = NULL;
    CHECK(matex_texture(m, &o, &r, &err) != 0 && err.code == MATEX_EINPUT && !r);
    CHECK(strstr(err.message, "mesh in memory") != NULL);
    printf("bad mesh in memory: %s\n", err.message);
    small_options(&o);
    o.mesh = &CUBE;
    o.steps = 0;
    CHECK(matex_texture(m, &o, &r, &err) != 0 && err.code == MATEX_EUSAGE);
    printf("steps 0: %s\n", err.message);
    o.steps = 1;
    CHECK(matex_texture(m, &o, NULL, &err) != 0 && err.code == MATEX_EUSAGE); /* neither folder nor result */
}

/* Style images refused before any work: nothing is written. */
static void test_style_refused(matex_models *m, const char *tmp) {
    matex_options o;
    matex_error err;
    char out[1200], text[1200];
    small_options(&o);
    o.mesh = &CUBE;
    snprintf(out, sizeof out, "%s/style_out", tmp);
    o.out_dir = out;
    snprintf(text, sizeof text, "%s/style.png", tmp);
    FILE *f = fopen(text, "w");
    if (f) {
        fputs("not a picture\n", f);
        fclose(f);
    }
    o.style_images[0] = text;
    CHECK(matex_texture(m, &o, NULL, &err) != 0 && err.code == MATEX_EINPUT && strstr(err.message, text) &&
          strstr(err.message, "not an image"));
    CHECK(!exists(out, NULL));
    o.style_images[0] = NULL;
    float px[3] = {1, 0, 0};
    matex_image red = {1, 1, 3, px};
    o.style_pixels = &red;
    o.n_style_pixels = 1;
    o.style_scale = 3.0f;
    CHECK(matex_texture(m, &o, NULL, &err) != 0 && err.code == MATEX_EUSAGE && strstr(err.message, "--style-scale"));
    o.style_scale = 0.6f;
    red.channels = 2;
    CHECK(matex_enhance(m, &o, NULL, &err) != 0 && err.code == MATEX_EUSAGE && strstr(err.message, "style image 0 in memory"));
    CHECK(!exists(out, NULL));
}

/* A style image in memory (the demo weights hold a tiny encoder and adapter): it changes the texture,
 * at scale 0 the texture is the one without it, bit for bit; the report records it. */
static void test_style_in_memory(matex_models *m) {
    float px[8 * 8 * 3];
    for (int i = 0; i < 8 * 8 * 3; i++) px[i] = (float)((i * 37) % 11) / 10.0f; /* a coloured pattern */
    matex_image pattern = {8, 8, 3, px};
    matex_options o;
    matex_error err;
    matex_result *plain = NULL, *styled = NULL, *zero = NULL;
    small_options(&o);
    o.mesh = &CUBE;
    CHECK(matex_texture(m, &o, &plain, &err) == 0);
    o.style_pixels = &pattern;
    o.n_style_pixels = 1;
    CHECK(matex_texture(m, &o, &styled, &err) == 0);
    o.style_scale = 0.0f;
    CHECK(matex_texture(m, &o, &zero, &err) == 0);
    if (plain && styled && zero) {
        const matex_image *a = &plain->textures[0], *b = &styled->textures[0], *c = &zero->textures[0];
        size_t bytes = sizeof(float) * (size_t)a->width * a->height * a->channels;
        CHECK(b->width == a->width && c->width == a->width);
        CHECK(memcmp(a->pixels, b->pixels, bytes) != 0);
        CHECK(memcmp(a->pixels, c->pixels, bytes) == 0);
        CHECK(strstr(styled->report_json, "\"style_images\":[{\"source\":\"memory\"") != NULL &&
              strstr(styled->report_json, "\"style_scale\":0.6,") != NULL && strstr(zero->report_json, "\"style_scale\":0,"));
        CHECK(!strstr(plain->report_json, "style_images"));
    }
    matex_result_free(plain);
    matex_result_free(styled);
    matex_result_free(zero);
}

/* Enhance of the cube textured in memory, its texture passed in memory. */
static void test_enhance_in_memory(matex_models *m) {
    matex_options o;
    matex_error err;
    small_options(&o);
    o.mesh = &CUBE;
    matex_result *first = NULL, *second = NULL;
    if (matex_texture(m, &o, &first, &err)) {
        CHECK(!"texture for enhance");
        return;
    }
    o.mesh = &first->mesh;
    o.mesh_textures = first->textures;
    o.strength = 0.5f;
    o.views = 3;
    CHECK(matex_enhance(m, &o, &second, &err) == 0 && second);
    if (second) {
        printf("enhance in memory: %d views, coverage %.4f\n", second->views, second->coverage);
        CHECK(second->views == 3 && second->textures[0].width == 128);
    } else {
        fprintf(stderr, "%s\n", err.message);
    }
    matex_result_free(first);
    matex_result_free(second);
}

/* matex_transfer: the texture of a textured cube (a run's output) onto the same cube, no model
 * set; its options are checked like the others'. */
static void test_transfer(matex_models *m, const char *tmp) {
    matex_options o;
    matex_error err;
    char src_dir[600], src[700];
    snprintf(src_dir, sizeof src_dir, "%s/transfer_src", tmp);
    snprintf(src, sizeof src, "%s/mesh.obj", src_dir);
    small_options(&o);
    o.mesh = &CUBE;
    o.out_dir = src_dir;
    CHECK(matex_texture(m, &o, NULL, &err) == 0);
    matex_options_default(&o);
    o.source_path = src;
    o.mesh_path = src;
    o.texture_size = o.render_size = 128;
    o.candidates = 12;
    o.background[1] = 1.0f; /* green behind the source */
    matex_result *r = NULL;
    CHECK(matex_transfer(NULL, &o, &r, &err) == 0 && r);
    if (r) {
        printf("transfer in memory: %d views, coverage %.4f\n", r->views, r->coverage);
        CHECK(r->views >= 2 && r->ntextures == 1 && r->textures[0].width == 128 && r->coverage > 0.5);
        CHECK(strstr(r->report_json, "psnr") != NULL); /* onto its own UVs: the report measures it */
    } else {
        fprintf(stderr, "%s\n", err.message);
    }
    matex_result_free(r);
    o.background[1] = 2.0f;
    CHECK(matex_transfer(NULL, &o, &r, &err) == -1 && err.code == MATEX_EUSAGE && !r);
    CHECK(strstr(err.message, "--background must be three numbers (R,G,B) in [0, 1]") != NULL);
    o.background[1] = 0.0f;
    o.source_path = NULL;
    CHECK(matex_transfer(NULL, &o, &r, &err) == -1 && err.code == MATEX_EUSAGE);
    /* texture and enhance need a model set; their image size must suit its networks */
    small_options(&o);
    o.mesh = &CUBE;
    CHECK(matex_texture(NULL, &o, &r, &err) == -1 && err.code == MATEX_EUSAGE);
    o.image_size = 72;
    CHECK(matex_texture(m, &o, &r, &err) == -1 && err.code == MATEX_EUSAGE && strstr(err.message, "--image-size must be a multiple of"));
    printf("image size 72: %s\n", err.message);
}

int main(void) {
    const char *weights = getenv("MATEX_DEMO_WEIGHTS");
    if (!weights || access(weights, R_OK)) {
        printf("no demo weights (MATEX_DEMO_WEIGHTS; make test builds them)\n");
        return MX_TEST_SKIP;
    }
    printf("matex_version() %s, MATEX_VERSION %s\n", matex_version(), MATEX_VERSION);
    CHECK(!strcmp(matex_version(), MATEX_VERSION));
    char tmp[] = "/tmp/matex_test_api.XXXXXX";
    if (!mkdtemp(tmp)) return 1;
    matex_error err;
    matex_options mo;
    small_options(&mo);
    matex_models *m = matex_models_open(weights, &mo, &err);
    CHECK(m != NULL);
    if (m) {
        test_memory_and_file(m, tmp);
        test_cancel(m, tmp);
        test_bad_input(m);
        test_style_refused(m, tmp);
        test_style_in_memory(m);
        test_enhance_in_memory(m);
        test_transfer(m, tmp);
        matex_models_close(m);
    } else {
        fprintf(stderr, "%s\n", err.message);
    }
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp);
    if (system(cmd)) fprintf(stderr, "could not remove %s\n", tmp);
    return mx_test_finish("test_texture_api");
}
