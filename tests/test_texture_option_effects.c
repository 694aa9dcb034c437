/* Every option a verb offers does something (issue 42): for each (verb, option) pair of the
 * options table (pipeline/texture/options.c), a tiny run (demo weights, one model set) with the
 * option moved off its base value must change the result — the textures, or what report.json
 * measured (views, their prompts and weights, coverage, the UV atlas) — and report.json must
 * name the verb and record the option's value under "options" (the report reproduces the run).
 * The pairs come from the table, so a new option is covered without editing this file; the
 * options that only say where or how a run computes are in `SIDE_ONLY` below, each with why. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../include/matex.h"
#include "../pipeline/texture/options.h"
#include "../runtime/buf.h"
#include "../runtime/json.h"
#include "util_test.h"

/* Options that legitimately leave the result and the measured report as they are. */
static const char *const SIDE_ONLY[] = {
    "weights", "output", "force", "quiet", "progress", "json", "help", /* where a run writes and what it prints */
    "threads",      /* the same texture on any thread count (test_texture_threads); report "threads" */
    "precision",    /* each value may compute as the default here (auto: fp32 or bf16); report "precision" */
    "device",       /* cpu-strict computes as cpu, with activation guards (test_ops_backend) */
    "front-render", /* writes front.png beside the texture (tests/cli_batch.sh checks it) */
};

/* Values the generic rule (alternate_value) cannot pick: an option whose effect needs another. */
typedef struct special_case {
    const char *name, *alt;            /* alt: the moved value (NULL: the generic one) */
    const char *needs, *needs_value;   /* another option set in both runs */
} special_case;

static const special_case SPECIAL[] = {
    {"batch", "1", NULL, NULL},           /* the base has fewer later views than the default batch of 4 */
    {"style-scale", NULL, "style-image", "STYLE"}, /* a scale without a style image weighs nothing */
    {"normals", NULL, "frontal-threshold", "0.8"},  /* the two normals differ by little: a cut they straddle */
    {"background", NULL, "image-size", "64"}, /* only the model image's resampling mixes it into texels */
};

/* A UV sphere (an ellipsoid of that height): curved, so that the normal, the frontal threshold
 * and the write policy matter (a cube's flat faces hide them). Transfer's destination is a round
 * sphere finer than its flattened source: another mesh than the source, as a transfer's is. */
enum { RINGS = 8, MAX_SEGMENTS = 16, MAX_VERTS = 2 + (RINGS - 1) * MAX_SEGMENTS, MAX_FACES = 2 * MAX_SEGMENTS * (RINGS - 1) };
typedef struct sphere {
    float pos[MAX_VERTS][3];
    int32_t faces[MAX_FACES][3];
    matex_mesh mesh;
} sphere;

static void make_sphere(sphere *s, int segments, float height) {
    int v = 0, f = 0;
    float poles[2][3] = {{0, height, 0}, {0, -height, 0}}; /* vertices 0 and 1 */
    memcpy(s->pos[v++], poles[0], sizeof poles[0]);
    memcpy(s->pos[v++], poles[1], sizeof poles[1]);
    for (int r = 1; r < RINGS; r++)
        for (int k = 0; k < segments; k++, v++) {
            double th = M_PI * r / RINGS, ph = 2 * M_PI * k / segments;
            s->pos[v][0] = (float)(sin(th) * cos(ph)), s->pos[v][1] = height * (float)cos(th), s->pos[v][2] = (float)(sin(th) * sin(ph));
        }
#define RING(r, k) (2 + ((r) - 1) * segments + (k) % segments)
    for (int k = 0; k < segments; k++) { /* outward, counter-clockwise */
        int32_t top[3] = {0, RING(1, k + 1), RING(1, k)}, bottom[3] = {1, RING(RINGS - 1, k), RING(RINGS - 1, k + 1)};
        memcpy(s->faces[f++], top, sizeof top);
        memcpy(s->faces[f++], bottom, sizeof bottom);
        for (int r = 1; r < RINGS - 1; r++) {
            int32_t a[3] = {RING(r, k), RING(r, k + 1), RING(r + 1, k)}, b[3] = {RING(r, k + 1), RING(r + 1, k + 1), RING(r + 1, k)};
            memcpy(s->faces[f++], a, sizeof a);
            memcpy(s->faces[f++], b, sizeof b);
        }
    }
#undef RING
    s->mesh = (matex_mesh){v, f, &s->pos[0][0], &s->faces[0][0], 0, NULL, NULL, NULL, 1};
}

/* What the runs of one verb share: the base options and the inputs. */
typedef struct verb_setup {
    unsigned verb;
    matex_options base;
    const char *style_path; /* a PNG for --style-image */
} verb_setup;

static void tiny_options(matex_options *o) {
    matex_options_default(o);
    o->prompt = "a wooden crate";
    o->steps = 2;
    o->views = 4;
    o->image_size = 64;
    o->texture_size = 32;
    o->render_size = 32;
    o->candidates = 8;
    o->threads = 2;
    o->seed = 3;
    o->verbose = 0;
}

static int is_side_only(const char *name) {
    for (size_t i = 0; i < sizeof SIDE_ONLY / sizeof SIDE_ONLY[0]; i++)
        if (!strcmp(SIDE_ONLY[i], name)) return 1;
    return 0;
}

static const special_case *special(const char *name) {
    for (size_t i = 0; i < sizeof SPECIAL / sizeof SPECIAL[0]; i++)
        if (!strcmp(SPECIAL[i].name, name)) return &SPECIAL[i];
    return NULL;
}

static const void *field_of(const matex_options *o, const mx_option_spec *s) { return (const char *)o + s->field; }

/* Half way from v to the bound of s farther from it (a move the option cannot hide in a corner). */
static float halfway_to_farther_bound(const mx_option_spec *s, float v) {
    return (float)(s->hi - v > v - s->lo ? (v + s->hi) / 2 : (v + s->lo) / 2);
}

/* A value of s other than its value in o, as on the command line (component: which number of an
 * A,B pair moves). NULL for a flag. */
static const char *alternate_value(const mx_option_spec *s, const matex_options *o, int component, char *buf, size_t cap) {
    const special_case *sc = special(s->name);
    if (sc && sc->alt) return sc->alt;
    const void *f = field_of(o, s);
    switch (s->type) {
    case MX_OPTION_INT: {
        int v = *(const int *)f;
        snprintf(buf, cap, "%d", 2 * v <= s->hi ? 2 * v : v / 2);
        return buf;
    }
    case MX_OPTION_U64: snprintf(buf, cap, "%llu", (unsigned long long)(*(const uint64_t *)f + 1)); return buf;
    case MX_OPTION_FLOAT: {
        float v = *(const float *)f;
        snprintf(buf, cap, "%g", halfway_to_farther_bound(s, v));
        return buf;
    }
    case MX_OPTION_FLOAT2:
    case MX_OPTION_FLOAT3: {
        const float *v = f;
        int n = s->type == MX_OPTION_FLOAT2 ? 2 : 3;
        buf[0] = 0;
        for (int i = 0; i < n; i++) {
            float x = i == component ? halfway_to_farther_bound(s, v[i]) : v[i];
            snprintf(buf + strlen(buf), cap - strlen(buf), "%s%g", i ? "," : "", x);
        }
        return buf;
    }
    case MX_OPTION_CHOICE: {
        int n = 1, next = *(const int *)f + 1;
        for (const char *p = s->choices; *p; p++) n += *p == '|';
        const char *p = s->choices;
        for (int i = 0; i < next % n; i++) p = strchr(p, '|') + 1;
        snprintf(buf, cap, "%.*s", (int)strcspn(p, "|"), p);
        return buf;
    }
    case MX_OPTION_TEXT: return "hello";
    case MX_OPTION_PATHS: return "STYLE";
    default: return NULL;
    }
}

/* What a run produced, as text: the textures' pixels and the measured parts of report.json. */
static void append_json(mx_buf *b, const mx_json *j) {
    switch (mx_json_kind(j)) {
    case MX_JSON_OBJ:
        mx_buf_printf(b, "{");
        for (size_t i = 0; i < mx_json_len(j); i++) {
            const char *k = mx_json_key(j, i);
            size_t n = strlen(k);
            if (!strcmp(k, "seconds") || (n > 2 && !strcmp(k + n - 2, "_s"))) continue; /* timings */
            mx_buf_printf(b, "%s:", k);
            append_json(b, mx_json_at(j, i));
        }
        mx_buf_printf(b, "}");
        return;
    case MX_JSON_ARR:
        mx_buf_printf(b, "[");
        for (size_t i = 0; i < mx_json_len(j); i++) append_json(b, mx_json_at(j, i));
        mx_buf_printf(b, "]");
        return;
    case MX_JSON_STR: mx_buf_printf(b, "'%s',", mx_json_str(j)); return;
    case MX_JSON_NUM: mx_buf_printf(b, "%.9g,", mx_json_num(j)); return;
    case MX_JSON_BOOL: mx_buf_printf(b, "%d,", mx_json_bool(j)); return;
    default: mx_buf_printf(b, "null,"); return;
    }
}

static const char *const MEASURED[] = {"views", "coverage", "candidate_coverage", "views_generated", "psnr_db",
                                        "uv_atlas", "candidate_visible_texels", "mesh_texels"};

typedef struct outcome {
    mx_buf result;  /* textures and measured report, as text */
    mx_buf options; /* the report's "options" */
    int ok;
} outcome;

static void outcome_free(outcome *r) {
    mx_buf_free(&r->result);
    mx_buf_free(&r->options);
}

static int run_verb(matex_models *m, const verb_setup *vs, const matex_options *o, outcome *out) {
    memset(out, 0, sizeof *out);
    matex_result *r = NULL;
    matex_error err;
    int rc = vs->verb == MX_VERB_TEXTURE   ? matex_texture(m, o, &r, &err)
             : vs->verb == MX_VERB_ENHANCE ? matex_enhance(m, o, &r, &err)
                                           : matex_transfer(NULL, o, &r, &err);
    if (rc) {
        fprintf(stderr, "%s: %s\n", mx_options_verb_name(vs->verb), err.message);
        return -1;
    }
    for (int t = 0; t < r->ntextures; t++) {
        const matex_image *im = &r->textures[t];
        size_t n = (size_t)im->width * im->height * im->channels;
        mx_buf_printf(&out->result, "texture %dx%dx%d:", im->width, im->height, im->channels);
        for (size_t i = 0; i < n; i++) mx_buf_printf(&out->result, "%08x", (unsigned)(im->pixels[i] * 1e6f));
    }
    mx_status st;
    mx_json *rep = mx_json_parse(r->report_json, strlen(r->report_json), "report.json", &st);
    if (rep) {
        for (size_t i = 0; i < sizeof MEASURED / sizeof MEASURED[0]; i++) {
            const mx_json *v = mx_json_get(rep, MEASURED[i]);
            mx_buf_printf(&out->result, "%s=", MEASURED[i]);
            if (v) append_json(&out->result, v);
        }
        const mx_json *opts = mx_json_get(rep, "options");
        if (opts) append_json(&out->options, opts);
        out->ok = opts && !strcmp(mx_json_get_str(rep, "verb", ""), mx_options_verb_name(vs->verb));
        if (!out->ok) fprintf(stderr, "report.json lacks \"verb\": \"%s\" or \"options\"\n", mx_options_verb_name(vs->verb));
        mx_json_free(rep);
    }
    matex_result_free(r);
    return rep && !out->result.oom && !out->options.oom ? 0 : -1;
}

/* Sets option `name` (a table name) in o; "STYLE" stands for the setup's style image. */
static int set_option(const verb_setup *vs, matex_options *o, const char *name, const char *value) {
    const mx_option_spec *s = mx_option_find(name, vs->verb);
    mx_status st;
    if (value && !strcmp(value, "STYLE")) value = vs->style_path;
    if (!s || mx_option_set(s, o, value, &st)) {
        fprintf(stderr, "cannot set --%s %s: %s\n", name, value ? value : "", s ? st.msg : "no such option");
        return -1;
    }
    return 0;
}

/* One (verb, option[, component]) pair: the moved option changes the result or the measured
 * report, and the report's options record it. plain: the outcome of the verb's base options, the
 * run compared with unless the option needs another set too. */
static void check_pair(matex_models *m, const verb_setup *vs, const mx_option_spec *s, int component, const outcome *plain) {
    matex_options base = vs->base, moved;
    const special_case *sc = special(s->name);
    int own_base = sc && sc->needs;
    if (own_base && set_option(vs, &base, sc->needs, sc->needs_value)) {
        mx_test_failures++;
        return;
    }
    moved = base;
    char buf[128];
    const char *alt = alternate_value(s, &base, component, buf, sizeof buf);
    if (set_option(vs, &moved, s->name, alt)) {
        mx_test_failures++;
        return;
    }
    outcome own = {0}, b = {0};
    const outcome *a = own_base ? &own : plain;
    int ran = (!own_base || !run_verb(m, vs, &base, &own)) && !run_verb(m, vs, &moved, &b);
    int changes = ran && (a->result.len != b.result.len || memcmp(a->result.p, b.result.p, a->result.len));
    int recorded = ran && a->ok && b.ok && (a->options.len != b.options.len || memcmp(a->options.p, b.options.p, a->options.len));
    printf("%-8s --%s %s: %s, %s\n", mx_options_verb_name(vs->verb), s->name, alt ? alt : "", changes ? "changes the result" : "CHANGES NOTHING",
           recorded ? "recorded in report.json" : "NOT RECORDED in report.json");
    CHECK(changes && recorded);
    outcome_free(&own);
    outcome_free(&b);
}

static void check_verb(matex_models *m, const verb_setup *vs) {
    int n;
    const mx_option_spec *t = mx_options_table(&n);
    outcome plain = {0};
    if (run_verb(m, vs, &vs->base, &plain)) {
        mx_test_failures++;
        outcome_free(&plain);
        return;
    }
    for (int i = 0; i < n; i++) {
        const mx_option_spec *s = &t[i];
        if (!(s->verbs & vs->verb) || is_side_only(s->name)) continue;
        check_pair(m, vs, s, 0, &plain);
        if (s->type == MX_OPTION_FLOAT2 || s->type == MX_OPTION_FLOAT3) check_pair(m, vs, s, 1, &plain);
    }
    outcome_free(&plain);
}

/* Every exception names an option of the table (the list cannot outlive its options). */
static void check_side_only_exist(void) {
    for (size_t i = 0; i < sizeof SIDE_ONLY / sizeof SIDE_ONLY[0]; i++)
        CHECK(mx_option_find(SIDE_ONLY[i], MX_VERB_TEXTURE | MX_VERB_ENHANCE | MX_VERB_TRANSFER) != NULL);
}

int main(void) {
    const char *weights = getenv("MATEX_DEMO_FAST_WEIGHTS"); /* the demo set with LCM + TAESD: --fast runs */
    if (!weights || access(weights, R_OK)) {
        printf("no demo weights (MATEX_DEMO_FAST_WEIGHTS; make test builds them)\n");
        return MX_TEST_SKIP;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    check_side_only_exist();
    char tmp[] = "/tmp/matex_test_option_effects.XXXXXX", src_dir[128], src[160], style[160];
    if (!mkdtemp(tmp)) return 1;
    snprintf(src_dir, sizeof src_dir, "%s/src", tmp);
    snprintf(src, sizeof src, "%s/mesh.obj", src_dir);
    snprintf(style, sizeof style, "%s/texture.png", src_dir);
    matex_error err;
    verb_setup tex = {.verb = MX_VERB_TEXTURE, .style_path = style};
    tiny_options(&tex.base);
    static sphere coarse, fine;
    make_sphere(&coarse, 12, 0.6f);
    make_sphere(&fine, MAX_SEGMENTS, 1.0f);
    tex.base.mesh = &coarse.mesh;
    matex_models *m = matex_models_open(weights, &tex.base, &err);
    matex_result *textured = NULL;
    /* the textured sphere: enhance's input, transfer's source, and a PNG for --style-image */
    if (!m || matex_texture(m, &tex.base, &textured, &err) || matex_result_write(textured, src_dir, 0, &err)) {
        fprintf(stderr, "setup: %s\n", err.message);
        return 1;
    }
    verb_setup enh = tex, tra = tex;
    enh.verb = MX_VERB_ENHANCE;
    enh.base.mesh = &textured->mesh;
    enh.base.mesh_textures = textured->textures;
    tra.verb = MX_VERB_TRANSFER;
    tra.base.source_path = src;
    tra.base.mesh = &fine.mesh;
    check_verb(m, &tex);
    check_verb(m, &enh);
    check_verb(m, &tra);
    matex_result_free(textured);
    matex_models_close(m);
    char cmd[256];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp);
    if (system(cmd)) fprintf(stderr, "could not remove %s\n", tmp);
    return mx_test_finish("test_texture_option_effects");
}
