/* The checks before any work and the stop at any moment (issue 12): mx_texture_opts_check
 * refuses every impossible option with its valid range; the output folder is checked and
 * staged first (mx_outdir: a file, a non-empty folder without force, an atomic replacement with
 * force); a cancel flag set before or during a run (from another thread, at many moments) ends
 * it with MX_ECANCEL and leaves neither the output folder nor its staging folder. */
#include <dirent.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../pipeline/texture/options.h"
#include "../pipeline/texture/outdir.h"
#include "../pipeline/texture/texture.h"
#include "../runtime/log.h"
#include "util_test.h"

static void base_opts(mx_texture_opts *o, const char *weights, const char *out) {
    mx_texture_opts_default(o);
    o->pub.mesh_path = "mesh.obj";
    o->pub.prompt = "a chair";
    o->weights_path = weights;
    o->pub.out_dir = out;
}

/* One impossible value: refused as a usage error whose message holds `want`. */
static void expect_refused(const mx_texture_opts *o, unsigned mode, const char *want) {
    mx_status st;
    mx_status_clear(&st);
    int rc = mx_texture_opts_check(o, mode, &st);
    CHECK(rc == -1 && st.code == MX_EUSAGE);
    if (!strstr(st.msg, want)) {
        fprintf(stderr, "message '%s' lacks '%s'\n", st.msg, want);
        mx_test_failures++;
    }
}

static void test_options(void) {
    mx_texture_opts o;
    mx_status st;
    base_opts(&o, "w.mxw", "out");
    CHECK(mx_texture_opts_check(&o, MX_VERB_TEXTURE, &st) == 0);
#define REFUSE(field, value, want)                                                                                     \
    do {                                                                                                               \
        base_opts(&o, "w.mxw", "out");                                                                                 \
        o.field = value;                                                                                               \
        expect_refused(&o, MX_VERB_TEXTURE, want);                                                             \
    } while (0)
    /* ranges: the option table's (test_table checks every bound) */
    REFUSE(pub.frontal_threshold, 1.5f, "--frontal-threshold must be a number in [0, 1), not '1.5'");
    REFUSE(pub.guidance, (float)NAN, "--guidance must be a number in [0, 50]");
    REFUSE(pub.depth_weight[1], -1.0f, "--depth-weight must be one or two numbers (A or A,B) in [0, 2], not '1,-1'");
    REFUSE(pub.steps, 0, "--steps must be an integer in 1..200, not '0'");
    REFUSE(pub.views, 1, "--views must be an integer in 2..64, not '1'");
    REFUSE(pub.image_size, 100, "--image-size must be a multiple of 8 in 8..2048, not '100'");
    REFUSE(pub.geometric_normals, 7, "--normals must be one of depth|geometric");
    REFUSE(pub.precision, 5, "--precision");
    REFUSE(pub.device, "tpu", "--device");
    /* what the run is given */
    REFUSE(pub.prompt, "", "the prompt is empty");
    REFUSE(pub.prompt, " \t ", "the prompt is empty");
    REFUSE(pub.prompt, NULL, "no prompt");
    REFUSE(pub.out_dir, "", "no output folder");
    REFUSE(weights_path, NULL, "--weights");
#undef REFUSE
    /* enhance: the prompt may be empty and one view is enough */
    base_opts(&o, "w.mxw", "out");
    o.pub.prompt = "";
    o.pub.views = 1;
    CHECK(mx_texture_opts_check(&o, MX_VERB_ENHANCE, &st) == 0);
    expect_refused(&o, MX_VERB_TEXTURE, "--views must be an integer in 2..64, not '1'");
    o.pub.views = 2;
    expect_refused(&o, MX_VERB_TEXTURE, "the prompt is empty");
    /* transfer: a source, no weights, no prompt */
    base_opts(&o, NULL, "out");
    o.pub.prompt = NULL;
    expect_refused(&o, MX_VERB_TRANSFER, "no source mesh");
    o.pub.source_path = "src.glb";
    CHECK(mx_texture_opts_check(&o, MX_VERB_TRANSFER, &st) == 0);
    /* mx_texture_run refuses before touching anything */
    base_opts(&o, "w.mxw", "out_never");
    o.pub.coverage_stop = 2;
    CHECK(mx_texture_run(&o, NULL, &st) == -1 && st.code == MX_EUSAGE);
}

/* The option table (options.c) is what every front end and matex_options_default derive from:
 * each default must parse and pass its own check; each numeric bound must be accepted and the
 * value just past it refused with a message naming the option, the value and the valid values. */
static void test_table(void) {
    int n;
    const mx_option_spec *t = mx_options_table(&n);
    matex_options o;
    mx_status st;
    matex_options_default(&o);
    for (unsigned verb = MX_VERB_TEXTURE; verb <= MX_VERB_BATCH; verb <<= 1)
        CHECK(mx_options_check(&o, verb, &st) == 0);
    for (int i = 0; i < n; i++) {
        const mx_option_spec *s = &t[i];
        if (s->def) CHECK(mx_option_set(s, &o, s->def, &st) == 0);
        if (s->type != MX_OPTION_INT) continue;
        char v[64], msg_want[200];
        int step = s->multiple ? s->multiple : 1;
        snprintf(v, sizeof v, "%.0f", s->lo);
        CHECK(mx_option_set(s, &o, v, &st) == 0);
        snprintf(v, sizeof v, "%.0f", s->hi);
        CHECK(mx_option_set(s, &o, v, &st) == 0);
        snprintf(v, sizeof v, "%.0f", s->hi + step);
        snprintf(msg_want, sizeof msg_want, "--%s must be ", s->name);
        CHECK(mx_option_set(s, &o, v, &st) == -1 && st.code == MX_EUSAGE && strstr(st.msg, msg_want) && strstr(st.msg, v));
        snprintf(v, sizeof v, "%.0f", s->lo - step);
        CHECK(mx_option_set(s, &o, v, &st) == -1 && strstr(st.msg, msg_want));
        matex_options_default(&o);
    }
    /* names: dashes or underscores, short names, per verb */
    CHECK(mx_option_find("image_size", MX_VERB_TEXTURE) == mx_option_find("--image-size", MX_VERB_TEXTURE));
    CHECK(mx_option_find("-o", MX_VERB_TRANSFER) != NULL && mx_option_find("-o", MX_VERB_TRANSFER)->short_name == 'o');
    CHECK(mx_option_find("strength", MX_VERB_TEXTURE) == NULL && mx_option_find("strength", MX_VERB_ENHANCE) != NULL);
    CHECK(mx_option_find("background", MX_VERB_TEXTURE) == NULL && mx_option_find("bogus", MX_VERB_TEXTURE) == NULL);
    CHECK(mx_option_find("image-size", MX_VERB_TRANSFER)->marks != 0); /* transfer's: through the model image */
    /* values: the messages say the valid values (issue 24 item 12) */
    const mx_option_spec *seed = mx_option_find("seed", MX_VERB_TEXTURE), *bg = mx_option_find("background", MX_VERB_TRANSFER);
    CHECK(mx_option_set(seed, &o, "-1", &st) == -1 && strstr(st.msg, "--seed must be an integer in 0..18446744073709551615, not '-1'"));
    CHECK(mx_option_set(seed, &o, "18446744073709551615", &st) == 0 && o.seed == UINT64_MAX);
    CHECK(mx_option_set(bg, &o, "255,0,0", &st) == -1 && strstr(st.msg, "three numbers (R,G,B) in [0, 1], not '255,0,0'"));
    CHECK(mx_option_set(bg, &o, "1,0.5,0", &st) == 0 && o.background[0] == 1.0f && o.background[1] == 0.5f);
    CHECK(mx_option_set(bg, &o, "1,0.5", &st) == -1 && mx_option_set(bg, &o, "1,0.5,0,0", &st) == -1);
    const mx_option_spec *dw = mx_option_find("depth-weight", MX_VERB_TEXTURE);
    CHECK(mx_option_set(dw, &o, "0.9", &st) == 0 && o.depth_weight[0] == 0.9f && o.depth_weight[1] == 0.9f);
    CHECK(mx_option_set(mx_option_find("normals", MX_VERB_TEXTURE), &o, "geometric", &st) == 0 && o.geometric_normals == 1);
    CHECK(mx_option_set(mx_option_find("normals", MX_VERB_TEXTURE), &o, "flat", &st) == -1 &&
          strstr(st.msg, "one of depth|geometric"));
    CHECK(mx_option_set(mx_option_find("size", MX_VERB_TRANSFER), &o, "256", &st) == 0 && o.texture_size == 256 &&
          o.render_size == 256);
    /* views: at least front and back, but for enhance */
    matex_options_default(&o);
    o.views = 1;
    CHECK(mx_options_check(&o, MX_VERB_TEXTURE, &st) == -1 && strstr(st.msg, "--views must be an integer in 2..64, not '1'"));
    CHECK(mx_options_check(&o, MX_VERB_ENHANCE, &st) == 0);
    o.views = 6;
    o.device = "tpu";
    CHECK(mx_options_check(&o, MX_VERB_TEXTURE, &st) == -1 && strstr(st.msg, "--device"));
    /* the image size against the networks: a multiple of their step, from one step up */
    CHECK(mx_options_check_image_size(512, 64, &st) == 0 && mx_options_check_image_size(64, 64, &st) == 0);
    CHECK(mx_options_check_image_size(520, 64, &st) == -1 && strstr(st.msg, "multiple of 64 (64, 128, ..."));
    CHECK(mx_options_check_image_size(8, 16, &st) == -1 && st.code == MX_EUSAGE);
}

static int exists(const char *path) {
    struct stat sb;
    return stat(path, &sb) == 0;
}

/* Nothing named "<dir>.partial-*" or "<dir>.old-*" beside dir. */
static int no_staging(const char *dir) {
    char parent[1024], base[256];
    snprintf(parent, sizeof parent, "%s", dir);
    char *slash = strrchr(parent, '/');
    snprintf(base, sizeof base, "%s.", slash + 1);
    *slash = 0;
    DIR *d = opendir(parent);
    if (!d) return 0;
    struct dirent *e;
    int clean = 1;
    while ((e = readdir(d)) != NULL)
        if (!strncmp(e->d_name, base, strlen(base))) clean = 0;
    closedir(d);
    return clean;
}

static int count_entries(const char *dir) {
    DIR *d = opendir(dir);
    if (!d) return -1;
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)) != NULL) n += strcmp(e->d_name, ".") && strcmp(e->d_name, "..");
    closedir(d);
    return n;
}

static void touch(const char *path) {
    FILE *f = fopen(path, "w");
    if (f) fclose(f);
}

/* One triangle with UVs and a 16x16 texture: what mx_outdir_commit writes. */
typedef struct {
    float pos[9], uv[6];
    int32_t face[3];
    mx_mesh m;
    mx_image tex;
} tiny_output;

static void tiny_output_init(tiny_output *t, mx_status *st) {
    *t = (tiny_output){.pos = {0, 0, 0, 1, 0, 0, 0, 1, 0}, .uv = {0, 0, 1, 0, 0, 1}, .face = {0, 1, 2}};
    t->m = (mx_mesh){.nverts = 3, .nfaces = 1, .pos = t->pos, .faces = t->face, .nuv = 3, .uv = t->uv, .face_uv = t->face};
    CHECK(mx_image_alloc(&t->tex, 16, 16, 3, st) == 0);
}

/* --force replaces only matex's own output: never a folder of user files, the current folder, or
 * one holding an input (issue 24: `-o . --force` deleted a user's folder). */
static void test_outdir_force_refusals(const char *tmp, const char *done) {
    char user[600], note[700], cwd[4096], input[700];
    mx_outdir od;
    mx_status st;
    snprintf(user, sizeof user, "%s/user", tmp);
    snprintf(note, sizeof note, "%s/notes.txt", user);
    mkdir(user, 0777);
    touch(note);
    CHECK(mx_outdir_open(&od, user, 1, NULL, 0, &st) == -1 && strstr(st.msg, "not written by matex"));
    CHECK(exists(note) && no_staging(user));
    /* a user's file added to matex's output is not replaced either */
    snprintf(input, sizeof input, "%s/mine.obj", done);
    touch(input);
    CHECK(mx_outdir_open(&od, done, 1, NULL, 0, &st) == -1 && strstr(st.msg, "mine.obj, which matex did not write"));
    CHECK(exists(input) && no_staging(done));
    /* nor a folder holding an input, even one matex wrote */
    const char *inputs[] = {NULL, input};
    CHECK(mx_outdir_open(&od, done, 1, inputs, 2, &st) == -1 && strstr(st.msg, "holds the input"));
    remove(input);
    snprintf(input, sizeof input, "%s/mesh.obj", done);
    CHECK(mx_outdir_open(&od, done, 1, (const char *[]){input}, 1, &st) == -1 && strstr(st.msg, "holds the input"));
    /* nor the current folder */
    CHECK(getcwd(cwd, sizeof cwd) != NULL && chdir(done) == 0);
    CHECK(mx_outdir_open(&od, ".", 1, NULL, 0, &st) == -1 && strstr(st.msg, "current folder"));
    CHECK(chdir(cwd) == 0 && exists(input) && no_staging(done));
}

static void test_outdir(const char *tmp) {
    char file[600], full[600], old[700], staged[4400], marker[700];
    mx_outdir od;
    mx_status st;
    snprintf(file, sizeof file, "%s/a_file", tmp);
    touch(file);
    CHECK(mx_outdir_open(&od, file, 1, NULL, 0, &st) == -1 && strstr(st.msg, "not a folder"));
    snprintf(full, sizeof full, "%s/full", tmp);
    snprintf(old, sizeof old, "%s/old.png", full);
    snprintf(marker, sizeof marker, "%s/" MX_OUTDIR_MARKER, full);
    tiny_output t;
    tiny_output_init(&t, &st);
    /* matex's own output: the marker lists its files */
    CHECK(mx_outdir_open(&od, full, 0, NULL, 0, &st) == 0);
    snprintf(staged, sizeof staged, "%s/old.png", od.stage);
    touch(staged);
    CHECK(mx_outdir_commit(&od, &t.m, &t.tex, 1, "{}", NULL, &st) == 0);
    CHECK(exists(old) && exists(marker) && count_entries(full) == 8); /* six outputs, old.png, the marker */
    CHECK(mx_outdir_open(&od, full, 0, NULL, 0, &st) == -1 && strstr(st.msg, "--force"));
    CHECK(exists(old) && no_staging(full));
    /* with force: staged at once, discarded on failure, swapped in on commit */
    CHECK(mx_outdir_open(&od, full, 1, NULL, 0, &st) == 0 && exists(od.stage));
    mx_outdir_discard(&od);
    CHECK(!exists(od.stage) && exists(old));
    CHECK(mx_outdir_open(&od, full, 1, NULL, 0, &st) == 0);
    snprintf(staged, sizeof staged, "%s/new.txt", od.stage);
    touch(staged);
    volatile sig_atomic_t stop = 1;
    CHECK(mx_outdir_commit(&od, &t.m, &t.tex, 1, "{}", &stop, &st) == -1 && st.code == MX_ECANCEL);
    CHECK(exists(old) && no_staging(full)); /* interrupted before the swap: the old folder stays */
    CHECK(mx_outdir_open(&od, full, 1, NULL, 0, &st) == 0);
    stop = 0;
    CHECK(mx_outdir_commit(&od, &t.m, &t.tex, 1, "{}", &stop, &st) == 0);
    CHECK(!exists(old) && count_entries(full) == 7 && no_staging(full));
    test_outdir_force_refusals(tmp, full);
    /* two runs into one folder: the second is refused while the first holds it (issue 24 item 12) */
    mx_outdir first, second;
    char lock[700];
    snprintf(lock, sizeof lock, "%s/busy.matex-lock", tmp);
    snprintf(full, sizeof full, "%s/busy", tmp);
    CHECK(mx_outdir_open(&first, full, 0, NULL, 0, &st) == 0 && exists(lock));
    CHECK(mx_outdir_open(&second, full, 0, NULL, 0, &st) == -1 && strstr(st.msg, "another matex run is writing"));
    CHECK(exists(first.stage)); /* the refused run touched nothing of the first's */
    mx_outdir_discard(&first);
    CHECK(!exists(lock) && no_staging(full));
    CHECK(mx_outdir_open(&second, full, 0, NULL, 0, &st) == 0);
    CHECK(mx_outdir_commit(&second, &t.m, &t.tex, 1, "{}", NULL, &st) == 0 && !exists(lock) && no_staging(full));
    char stage[4200], lockname[4200];
    CHECK(mx_outdir_names(full, stage, lockname) == 0 && !strcmp(lockname, lock) && strstr(stage, ".partial-"));
    mx_image_free(&t.tex);
}

typedef struct {
    volatile sig_atomic_t *flag;
    long delay_us;
} stopper;

static void *stop_later(void *arg) {
    const stopper *s = arg;
    struct timespec ts = {s->delay_us / 1000000, (s->delay_us % 1000000) * 1000};
    nanosleep(&ts, NULL);
    *s->flag = 1;
    return NULL;
}

static void test_cancel(const char *weights, const char *tmp) {
    char mesh[1024], out[1024];
    if (!mx_test_need(mesh, sizeof mesh, "assets/fedora_hat/fedora.obj")) return;
    /* -1: set before the run; LONG_MAX: never */
    static const long delays_us[] = {-1, 0, 50000, 200000, 500000, 900000, 1400000, LONG_MAX};
    int stopped = 0, n = (int)(sizeof delays_us / sizeof *delays_us);
    for (int i = 0; i < n; i++) {
        snprintf(out, sizeof out, "%s/cancel%d", tmp, i);
        volatile sig_atomic_t flag = delays_us[i] < 0; /* set before the run */
        mx_texture_opts o;
        base_opts(&o, weights, out);
        o.pub.mesh_path = mesh;
        o.pub.steps = 2, o.pub.candidates = 12, o.pub.texture_size = 512, o.pub.render_size = 256, o.pub.image_size = 64;
        o.pub.verbose = 0, o.pub.cancel = &flag;
        stopper s = {&flag, delays_us[i]};
        pthread_t th;
        int threaded = delays_us[i] >= 0 && delays_us[i] < LONG_MAX && pthread_create(&th, NULL, stop_later, &s) == 0;
        mx_status st;
        mx_status_clear(&st);
        int rc = mx_texture_run(&o, NULL, &st);
        if (threaded) pthread_join(th, NULL);
        if (delays_us[i] == LONG_MAX) printf("never cancelled: %s\n", rc ? st.msg : "finished");
        else printf("cancel after %ld us: %s\n", delays_us[i], rc ? st.msg : "finished first");
        if (rc) {
            stopped++;
            CHECK(st.code == MX_ECANCEL && !strcmp(st.msg, "interrupted"));
            CHECK(!exists(out));
        } else {
            CHECK(count_entries(out) == 7); /* six outputs and the marker */
        }
        CHECK(no_staging(out));
    }
    CHECK(stopped >= 2 && stopped < n); /* at least the flag set before and at the start; not the last */
}

int main(void) {
    mx_log_set_level(MX_LOG_ERROR);
    char tmp[] = "/tmp/matex_opts_XXXXXX";
    if (!mkdtemp(tmp)) return 1;
    test_options();
    test_table();
    test_outdir(tmp);
    const char *weights = getenv("MATEX_DEMO_WEIGHTS");
    if (weights && access(weights, R_OK) == 0) test_cancel(weights, tmp);
    else fprintf(stderr, "MATEX_DEMO_WEIGHTS not set: the cancel test did not run\n"), mx_test_failures++;
    char cmd[256];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmp);
    if (mx_test_failures == 0 && system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmp);
    return mx_test_finish("test_texture_options");
}
