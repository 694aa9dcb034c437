/* The table of the texturing options (options.h) and what is derived from it in the library:
 * the defaults of matex_options, the parsing of one value, the range check and --help. */
#include <ctype.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "../../runtime/backend.h"
#include "../../runtime/jsonw.h"
#include "../../runtime/numparse.h"
#include "options.h"
#include "texture.h"
#include "../geom/masks.h"

typedef float float2[2];
typedef float float3[3];
typedef const char *text;
typedef const char *paths[MATEX_MAX_STYLE_IMAGES];

/* The offset of a matex_options field, compiled only when the field has type T. */
#define FIELD(f, T) (offsetof(matex_options, f) + 0 * sizeof(_Generic(&((matex_options *)0)->f, T *: 1)))
_Static_assert(offsetof(matex_options, mesh_path) == 0, "offset 0 means 'no field' in twin and marks");

enum { TEX = MX_VERB_TEXTURE, ENH = MX_VERB_ENHANCE, TRA = MX_VERB_TRANSFER, BAT = MX_VERB_BATCH, ALL = TEX | ENH | TRA };

static const mx_option_spec TABLE[] = {
    {.name = "weights", .arg = "FILE", .type = MX_OPTION_CLI, .verbs = TEX | ENH, .scope = MX_SCOPE_RUN,
     .help = "matex weight file (matex convert); required"},
    {.name = "output", .short_name = 'o', .arg = "DIR", .type = MX_OPTION_TEXT, .field = FIELD(out_dir, text),
     .verbs = ALL, .scope = MX_SCOPE_RUN,
     .help = "output folder: texture.png/.exr, mesh.obj/.mtl, mesh.glb, report.json; required"},
    {.name = "strength", .arg = "S", .type = MX_OPTION_FLOAT, .field = FIELD(strength, float), .lo = 0, .lo_open = 1,
     .hi = 1, .def = "0.5", .verbs = ENH, .scope = MX_SCOPE_JOB, .help = "SDEdit strength (1 = repaint)"},
    {.name = "seed", .arg = "N", .type = MX_OPTION_U64, .field = FIELD(seed, uint64_t), .lo = 0, .hi = (double)UINT64_MAX,
     .def = "0", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB,
     .help = "noise seed; the same seed gives the same texture"},
    {.name = "steps", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(steps, int), .lo = 1, .hi = 200, .def = "10",
     .def_help = "10; 4 with --fast", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB, .help = "denoising steps"},
    {.name = "views", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(views, int), .lo = 2, .hi = 64, .def = "6",
     .verbs = TEX | TRA | BAT, .scope = MX_SCOPE_JOB, .help = "view budget, front and back included"},
    {.name = "views", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(views, int), .lo = 1, .hi = 64, .def = "6",
     .verbs = ENH, .scope = MX_SCOPE_JOB, .help = "view budget"},
    {.name = "candidates", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(candidates, int), .lo = 1, .hi = 4096,
     .def = "40", .verbs = ALL | BAT, .scope = MX_SCOPE_JOB, .help = "candidate cameras on a Fibonacci sphere"},
    {.name = "texture-size", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(texture_size, int), .lo = 16, .hi = 8192,
     .def = "1024", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB, .help = "texture side in texels"},
    {.name = "render-size", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(render_size, int), .lo = 16, .hi = 8192,
     .def = "1024", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB, .help = "side of the renders that are backprojected"},
    {.name = "size", .arg = "S", .type = MX_OPTION_INT, .field = FIELD(texture_size, int), .twin = FIELD(render_size, int),
     .lo = 16, .hi = 8192, .def = "1024", .verbs = TRA, .scope = MX_SCOPE_JOB, .help = "texture side and render side"},
    {.name = "image-size", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(image_size, int), .lo = 8, .hi = 2048,
     .multiple = 8, .def = "512", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB,
     .help = "side of one generated image; the weights also want a multiple of\n"
             "8 x 2^(UNet levels - 1): 64 for SD1.5, checked when they are open"},
    {.name = "image-size", .arg = "M", .type = MX_OPTION_INT, .field = FIELD(image_size, int),
     .marks = FIELD(through_model_image, int), .lo = 8, .hi = 2048, .multiple = 8, .def_help = "off", .verbs = TRA,
     .scope = MX_SCOPE_JOB,
     .help = "send each render through the texture job's model image (crop to\n"
             "the object, M x M, back): its resampling at the silhouettes"},
    /* enhance runs one view at a time: each view continues the ones before it (enhance.c) */
    {.name = "batch", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(batch, int), .lo = 1, .hi = 64, .def = "4",
     .verbs = TEX | BAT, .scope = MX_SCOPE_JOB, .help = "most views generated in one batch"},
    {.name = "negative", .arg = "TEXT", .type = MX_OPTION_TEXT, .field = FIELD(negative_prompt, text), .def = "",
     .def_help = "empty", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB, .help = "negative prompt"},
    {.name = "guidance", .arg = "G", .type = MX_OPTION_FLOAT, .field = FIELD(guidance, float), .lo = 0, .hi = 50,
     .def = "7.5", .def_help = "7.5; 1 with --fast: none, batch not doubled", .verbs = TEX | ENH | BAT,
     .scope = MX_SCOPE_JOB, .help = "classifier-free guidance scale"},
    {.name = "fast", .type = MX_OPTION_FLAG, .field = FIELD(fast, int), .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB,
     .help = "few-step path: LCM scheduler, TAESD encoder/decoder; needs a weight file\n"
             "made with convert --lcm-lora FILE --taesd DIR"},
    /* enhance has no grid, no inpainting control and one depth weight (enhance.c) */
    {.name = "grid-depth-weight", .arg = "W", .type = MX_OPTION_FLOAT, .field = FIELD(grid_depth_weight, float), .lo = 0,
     .hi = 2, .def = "1.0", .verbs = TEX | BAT, .scope = MX_SCOPE_JOB,
     .help = "depth control weight of the front+back grid"},
    {.name = "depth-weight", .arg = "A[,B]", .type = MX_OPTION_FLOAT2, .field = FIELD(depth_weight, float2), .lo = 0,
     .hi = 2, .def = "1.0,0.7", .verbs = TEX | BAT, .scope = MX_SCOPE_JOB,
     .help = "depth control weight of the first[,last] later view"},
    {.name = "depth-weight", .arg = "W", .type = MX_OPTION_FLOAT, .field = FIELD(depth_weight[0], float), .lo = 0,
     .hi = 2, .def = "1.0", .verbs = ENH, .scope = MX_SCOPE_JOB, .help = "depth control weight of every view"},
    {.name = "inpaint-weight", .arg = "A[,B]", .type = MX_OPTION_FLOAT2, .field = FIELD(inpaint_weight, float2), .lo = 0,
     .hi = 2, .def = "0.8,1.0", .verbs = TEX | BAT, .scope = MX_SCOPE_JOB,
     .help = "inpainting control weight of the first[,last] later view"},
    {.name = "frontal-threshold", .arg = "T", .type = MX_OPTION_FLOAT, .field = FIELD(frontal_threshold, float), .lo = 0,
     .hi = 1, .hi_open = 1, .def = "0.3", .verbs = ALL | BAT, .scope = MX_SCOPE_JOB,
     .help = "min |n.v| of a backprojected pixel"},
    {.name = "normals", .arg = "depth|geometric", .type = MX_OPTION_CHOICE, .field = FIELD(geometric_normals, int),
     .choices = "depth|geometric", .def = "depth", .verbs = ALL | BAT, .scope = MX_SCOPE_JOB,
     .help = "normal used by the frontal mask (depth: as the paper)"},
    {.name = "coverage-stop", .arg = "C", .type = MX_OPTION_FLOAT, .field = FIELD(coverage_stop, float), .lo = 0,
     .lo_open = 1, .hi = 1, .def = "0.995", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB,
     .help = "stop adding views at this painted fraction"},
    {.name = "front-back-words", .arg = "TEXT", .type = MX_OPTION_TEXT, .field = FIELD(front_back_words, text),
     .def = "front and back view of", .verbs = TEX | BAT, .scope = MX_SCOPE_JOB,
     .help = "prompt prefix of the grid"},
    {.name = "style-image", .arg = "FILE", .type = MX_OPTION_PATHS, .field = FIELD(style_images, paths),
     .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB,
     .help = "style image (PNG, JPEG, TIFF; IP-Adapter image guidance); several: their\n"
             "tokens are concatenated; needs convert --image-encoder DIR --ip-adapter FILE"},
    {.name = "style-scale", .arg = "S", .type = MX_OPTION_FLOAT, .field = FIELD(style_scale, float), .lo = 0, .hi = 2,
     .def = "0.6", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_JOB,
     .help = "weight of the style image's tokens (0: as without one)"},
    {.name = "front-render", .type = MX_OPTION_FLAG, .field = FIELD(front_render, int), .verbs = TEX | ENH | BAT,
     .scope = MX_SCOPE_JOB, .help = "also write front.png: the textured mesh from the front (a style image)"},
    {.name = "write", .arg = "angle-aware|first-wins", .type = MX_OPTION_CHOICE, .field = FIELD(first_wins, int),
     .choices = "angle-aware|first-wins", .def = "angle-aware", .verbs = TRA, .scope = MX_SCOPE_JOB,
     .help = "a later view that sees a texel with |n.v| higher by 0.15\n"
             "restarts it, or the first writer keeps it"},
    {.name = "background", .arg = "R,G,B", .type = MX_OPTION_FLOAT3, .field = FIELD(background, float3), .lo = 0,
     .hi = 1, .def = "0,0,0", .verbs = TRA, .scope = MX_SCOPE_JOB, .help = "colour behind the source in its renders (reaches the texture only\n"
             "through --image-size's resampling at the silhouettes)"},
    {.name = "up", .arg = "y|z", .type = MX_OPTION_CHOICE, .field = FIELD(z_up, int), .choices = "y|z", .def = "y",
     .verbs = ALL | BAT, .scope = MX_SCOPE_JOB, .help = "up axis of the mesh"},
    {.name = "threads", .arg = "N", .type = MX_OPTION_INT, .field = FIELD(threads, int), .lo = 0, .hi = 1024, .def = "0",
     .def_help = "0: all", .verbs = ALL | BAT, .scope = MX_SCOPE_MODELS, .help = "CPU threads"},
    {.name = "precision", .arg = "fp32|bf16|auto", .type = MX_OPTION_CHOICE, .field = FIELD(precision, int),
     .choices = "fp32|bf16|auto", .def = "auto", .def_help = "auto: bf16 where this CPU computes it faster, else fp32",
     .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_MODELS,
     .help = "arithmetic of the networks: bf16 products with fp32 sums\n(1.6-1.8x faster with AMX or on AMD), or fp32"},
    {.name = "device", .arg = "D", .type = MX_OPTION_TEXT, .field = FIELD(device, text),
     .choices = "cpu|cpu-strict|cuda", .def = "cpu", .verbs = TEX | ENH | BAT, .scope = MX_SCOPE_MODELS,
     .help = "cpu, cpu-strict (activations guarded, for tests) or cuda\n(in binaries built by `make cuda`)"},
    {.name = "force", .type = MX_OPTION_FLAG, .field = FIELD(force, int), .verbs = ALL, .scope = MX_SCOPE_RUN,
     .help = "replace an earlier output of matex (atomically; never other files)"},
    {.name = "quiet", .type = MX_OPTION_CLI, .verbs = ALL, .scope = MX_SCOPE_RUN, .help = "no progress on stderr"},
    {.name = "progress", .arg = "text|json", .type = MX_OPTION_CLI, .verbs = ALL, .scope = MX_SCOPE_RUN,
     .help = "text: progress lines on stderr (default); json: one JSON object per line\non stdout (README \"Progress stream\")"},
    {.name = "json", .type = MX_OPTION_CLI, .verbs = ALL, .scope = MX_SCOPE_RUN, .help = "print a JSON summary on stdout"},
    {.name = "help", .short_name = 'h', .type = MX_OPTION_CLI, .verbs = ALL, .scope = MX_SCOPE_RUN, .help = "this help"},
};

const mx_option_spec *mx_options_table(int *n) {
    *n = (int)(sizeof TABLE / sizeof TABLE[0]);
    return TABLE;
}

/* "image_size" and "image-size" name the same option. */
static int same_name(const char *a, const char *b) {
    for (; *a && *b; a++, b++)
        if (*a != *b && !(*a == '_' && *b == '-')) return 0;
    return *a == *b;
}

const mx_option_spec *mx_option_find(const char *name, unsigned verb) {
    int is_short = name[0] == '-' && name[1] && name[1] != '-' && !name[2];
    if (name[0] == '-') name += name[1] == '-' ? 2 : 1;
    for (size_t i = 0; i < sizeof TABLE / sizeof TABLE[0]; i++) {
        const mx_option_spec *s = &TABLE[i];
        if (!(s->verbs & verb)) continue;
        if (is_short ? s->short_name == name[0] : same_name(name, s->name)) return s;
    }
    return NULL;
}

static void *field(matex_options *o, size_t offset) { return (char *)o + offset; }
static const void *cfield(const matex_options *o, size_t offset) { return (const char *)o + offset; }

/* The valid values of an option, as the messages and --help state them. */
static void describe_range(const mx_option_spec *s, char *out, size_t cap) {
    switch (s->type) {
    case MX_OPTION_INT:
        if (s->multiple) snprintf(out, cap, "a multiple of %d in %.0f..%.0f", s->multiple, s->lo, s->hi);
        else snprintf(out, cap, "an integer in %.0f..%.0f", s->lo, s->hi);
        return;
    case MX_OPTION_U64: snprintf(out, cap, "an integer in 0..%llu", (unsigned long long)UINT64_MAX); return;
    case MX_OPTION_FLOAT:
    case MX_OPTION_FLOAT2:
    case MX_OPTION_FLOAT3:
        snprintf(out, cap, "%s in %c%g, %g%c",
                 s->type == MX_OPTION_FLOAT ? "a number" : s->type == MX_OPTION_FLOAT2 ? "one or two numbers (A or A,B)"
                                                                                  : "three numbers (R,G,B)",
                 s->lo_open ? '(' : '[', s->lo, s->hi, s->hi_open ? ')' : ']');
        return;
    case MX_OPTION_CHOICE: snprintf(out, cap, "one of %s", s->choices); return;
    case MX_OPTION_PATHS:
        snprintf(out, cap, "at most %d file names, none empty, none after the list's first NULL", MATEX_MAX_STYLE_IMAGES);
        return;
    default: snprintf(out, cap, "a text"); return;
    }
}

static int refuse(const mx_option_spec *s, const char *value, mx_status *st) {
    char range[160];
    describe_range(s, range, sizeof range);
    return mx_fail(st, MX_EUSAGE, "--%s must be %s, not '%s'", s->name, range, value);
}

static int float_ok(const mx_option_spec *s, float v) {
    return isfinite(v) && (s->lo_open ? v > s->lo : v >= s->lo) && (s->hi_open ? v < s->hi : v <= s->hi);
}

/* The index of `value` among "a|b|c", or -1. */
static int choice_index(const char *choices, const char *value) {
    size_t n = strlen(value);
    int i = 0;
    for (const char *p = choices; *p; i++) {
        const char *bar = strchr(p, '|');
        size_t len = bar ? (size_t)(bar - p) : strlen(p);
        if (len == n && !strncmp(p, value, n)) return i;
        if (!bar) break;
        p = bar + 1;
    }
    return -1;
}

/* Is the option's value in o within its range? (value: the text to quote, NULL: the value's own.) */
static int check_one(const mx_option_spec *s, const matex_options *o, const char *value, mx_status *st) {
    char own[96];
    const void *f = cfield(o, s->field);
    int ok = 1;
    switch (s->type) {
    case MX_OPTION_INT: {
        int v = *(const int *)f;
        ok = v >= s->lo && v <= s->hi && (!s->multiple || v % s->multiple == 0);
        snprintf(own, sizeof own, "%d", v);
        break;
    }
    case MX_OPTION_FLOAT: ok = float_ok(s, *(const float *)f); snprintf(own, sizeof own, "%g", *(const float *)f); break;
    case MX_OPTION_FLOAT2:
    case MX_OPTION_FLOAT3: {
        const float *v = f;
        int n = s->type == MX_OPTION_FLOAT2 ? 2 : 3;
        for (int i = 0; i < n; i++) ok = ok && float_ok(s, v[i]);
        if (n == 2) snprintf(own, sizeof own, "%g,%g", v[0], v[1]);
        else snprintf(own, sizeof own, "%g,%g,%g", v[0], v[1], v[2]);
        break;
    }
    case MX_OPTION_CHOICE: {
        int v = *(const int *)f, n = 1;
        for (const char *p = s->choices; *p; p++) n += *p == '|';
        ok = v >= 0 && v < n;
        snprintf(own, sizeof own, "%d", v);
        break;
    }
    case MX_OPTION_PATHS: { /* a list ends at its first NULL: nothing may follow it */
        const char *const *v = f;
        int end = 0;
        for (int i = 0; i < MATEX_MAX_STYLE_IMAGES; i++) {
            ok = ok && !(end && v[i]) && !(v[i] && !*v[i]);
            end |= !v[i];
        }
        snprintf(own, sizeof own, "%.80s", v[0] ? v[0] : "");
        break;
    }
    case MX_OPTION_TEXT: { /* NULL: the default ("" for a text, "cpu" for the device) */
        const char *t = *(const char *const *)f;
        ok = !t || !s->choices || choice_index(s->choices, t) >= 0;
        snprintf(own, sizeof own, "%.80s", t ? t : "");
        break;
    }
    default: break;
    }
    return ok ? 0 : refuse(s, value ? value : own, st);
}

/* "A,B,C" into v[n] (n = 2 also takes "A": B = A); -1 on anything else. */
static int parse_floats(const char *text, float *v, int n) {
    char buf[128];
    if (strlen(text) >= sizeof buf) return -1;
    snprintf(buf, sizeof buf, "%s", text);
    int k = 0;
    for (char *p = buf; p; k++) {
        char *comma = strchr(p, ',');
        if (comma) *comma = 0;
        if (k == n || mx_parse_float(p, &v[k])) return -1;
        p = comma ? comma + 1 : NULL;
    }
    if (n == 2 && k == 1) v[1] = v[0];
    else if (k != n) return -1;
    return 0;
}

/* The next value of a path list: the first free slot; an empty value or a full list is refused. */
static int append_path(const mx_option_spec *s, const char **list, const char *value, mx_status *st) {
    if (!*value) return mx_fail(st, MX_EUSAGE, "--%s must be a file name, not ''", s->name);
    for (int i = 0; i < MATEX_MAX_STYLE_IMAGES; i++)
        if (!list[i]) return list[i] = value, 0;
    return mx_fail(st, MX_EUSAGE, "--%s may be given at most %d times ('%s' is one more)", s->name,
                   MATEX_MAX_STYLE_IMAGES, value);
}

int mx_option_set(const mx_option_spec *s, matex_options *o, const char *value, mx_status *st) {
    void *f = field(o, s->field);
    int bad = 0;
    switch (s->type) {
    case MX_OPTION_FLAG: *(int *)f = 1; return 0;
    case MX_OPTION_CLI: return 0;
    case MX_OPTION_TEXT: *(const char **)f = value; break;
    case MX_OPTION_PATHS: return append_path(s, f, value, st);
    case MX_OPTION_INT: bad = mx_parse_int(value, -2147483647L, 2147483647L, f); break;
    case MX_OPTION_U64: bad = mx_parse_u64(value, f); break;
    case MX_OPTION_FLOAT: bad = mx_parse_float(value, f); break;
    case MX_OPTION_FLOAT2: bad = parse_floats(value, f, 2); break;
    case MX_OPTION_FLOAT3: bad = parse_floats(value, f, 3); break;
    case MX_OPTION_CHOICE: {
        int i = choice_index(s->choices, value);
        bad = i < 0;
        if (bad) break;
        *(int *)f = i;
        break;
    }
    }
    if (bad || check_one(s, o, value, st)) return bad ? refuse(s, value, st) : -1;
    if (s->twin) *(int *)field(o, s->twin) = *(const int *)f;
    if (s->marks) *(int *)field(o, s->marks) = 1;
    return 0;
}

void mx_option_clear_paths(const mx_option_spec *s, matex_options *o) {
    if (s->type == MX_OPTION_PATHS) memset(field(o, s->field), 0, sizeof(paths));
}

void matex_options_default(matex_options *o) {
    memset(o, 0, sizeof *o);
    for (size_t i = 0; i < sizeof TABLE / sizeof TABLE[0]; i++)
        if (TABLE[i].def) mx_option_set(&TABLE[i], o, TABLE[i].def, NULL); /* the table's own values parse */
}

/* A device this binary has (the table checked the name). */
static int check_device(const char *name, mx_status *st) {
    mx_backend_kind kind;
    if (!name || mx_backend_parse(name, &kind, st)) return name ? -1 : 0;
    if (!mx_backend_compiled(kind))
        return mx_fail(st, MX_EUSAGE, "--device %s: this matex was built without that backend (`make cuda` builds one with cuda)", name);
    return 0;
}

int mx_option_check(const mx_option_spec *s, const matex_options *o, mx_status *st) { return check_one(s, o, NULL, st); }

int mx_options_check(const matex_options *o, unsigned verb, mx_status *st) {
    for (size_t i = 0; i < sizeof TABLE / sizeof TABLE[0]; i++) {
        const mx_option_spec *s = &TABLE[i];
        if ((s->verbs & verb) && s->type != MX_OPTION_CLI && !s->marks && check_one(s, o, NULL, st)) return -1;
    }
    if (o->through_model_image && check_one(mx_option_find("image-size", MX_VERB_TRANSFER), o, NULL, st)) return -1;
    if (o->fast && verb == MX_VERB_TRANSFER) return mx_fail(st, MX_EUSAGE, "--fast is for texture and enhance");
    return verb == MX_VERB_TRANSFER ? 0 : check_device(o->device, st);
}

int mx_options_check_image_size(int image_size, int step, mx_status *st) {
    if (step > 0 && (image_size < step || image_size % step))
        return mx_fail(st, MX_EUSAGE,
                       "--image-size must be a multiple of %d (%d, %d, ..., 512, ...) for these weights (an image of side "
                       "S has a latent of S/8, which the UNet halves at each of its levels), not %d",
                       step, step, 2 * step, image_size);
    return 0;
}

/* The i-th value of "a|b|c" into out. */
static void choice_name(const char *choices, int index, char *out, size_t cap) {
    const char *p = choices;
    for (int i = 0; i < index && strchr(p, '|'); i++) p = strchr(p, '|') + 1;
    const char *bar = strchr(p, '|');
    snprintf(out, cap, "%.*s", bar ? (int)(bar - p) : (int)strlen(p), p);
}

/* One option's value as a member of report.json, named as a batch manifest key ("image_size"). */
static void report_one(const mx_option_spec *s, const matex_options *o, mx_jw *w) {
    char key[64], text[64];
    snprintf(key, sizeof key, "%s", s->name);
    for (char *c = key; *c; c++) *c = *c == '-' ? '_' : *c;
    const void *f = cfield(o, s->field);
    switch (s->type) {
    case MX_OPTION_FLAG: mx_jw_bool(w, key, *(const int *)f); return;
    case MX_OPTION_INT: mx_jw_int(w, key, *(const int *)f); return;
    case MX_OPTION_U64: { /* a JSON integer while a reader's int64 holds it, else its digits */
        uint64_t v = *(const uint64_t *)f;
        snprintf(text, sizeof text, "%llu", (unsigned long long)v);
        if (v <= (uint64_t)INT64_MAX) mx_jw_int(w, key, (long long)v);
        else mx_jw_str(w, key, text);
        return;
    }
    case MX_OPTION_FLOAT: mx_jw_num(w, key, *(const float *)f); return;
    case MX_OPTION_FLOAT2:
    case MX_OPTION_FLOAT3:
        mx_jw_begin_arr(w, key);
        for (int i = 0; i < (s->type == MX_OPTION_FLOAT2 ? 2 : 3); i++) mx_jw_num(w, NULL, ((const float *)f)[i]);
        mx_jw_end_arr(w);
        return;
    case MX_OPTION_TEXT: {
        const char *t = *(const char *const *)f;
        mx_jw_str(w, key, t ? t : s->def ? s->def : "");
        return;
    }
    case MX_OPTION_PATHS:
        mx_jw_begin_arr(w, key);
        for (int i = 0; i < MATEX_MAX_STYLE_IMAGES && ((const char *const *)f)[i]; i++)
            mx_jw_str(w, NULL, ((const char *const *)f)[i]);
        mx_jw_end_arr(w);
        return;
    case MX_OPTION_CHOICE: choice_name(s->choices, *(const int *)f, text, sizeof text); mx_jw_str(w, key, text); return;
    case MX_OPTION_CLI: return;
    }
}

void mx_options_report(const matex_options *o, unsigned verb, mx_jw *w) {
    mx_jw_begin_obj(w, "options");
    for (size_t i = 0; i < sizeof TABLE / sizeof TABLE[0]; i++) {
        const mx_option_spec *s = &TABLE[i];
        int off = s->marks && !*(const int *)cfield(o, s->marks); /* transfer's --image-size when not given */
        if ((s->verbs & verb) && s->scope == MX_SCOPE_JOB && !off) report_one(s, o, w);
    }
    mx_jw_end_obj(w);
}

const char *mx_options_verb_name(unsigned verb) {
    return verb == MX_VERB_ENHANCE    ? "enhance"
           : verb == MX_VERB_TRANSFER ? "transfer"
           : verb == MX_VERB_BATCH    ? "batch"
                                      : "texture";
}

#define HELP_COLUMN 27 /* where the text of an option starts */
#define HELP_WIDTH 110 /* a line that would pass it goes on below */

/* One help line: "  --name ARG" padded to the text column, then the text ("\n" in it continues on
 * an indented line), then the default and the valid values, on a line of their own when long. */
static void help_line(FILE *f, const mx_option_spec *s) {
    char head[64];
    if (s->short_name) snprintf(head, sizeof head, "-%c, --%s%s%s", s->short_name, s->name, s->arg ? " " : "", s->arg ? s->arg : "");
    else snprintf(head, sizeof head, "--%s%s%s", s->name, s->arg ? " " : "", s->arg ? s->arg : "");
    int col = fprintf(f, "  %-*s", HELP_COLUMN - 4, head);
    col += fprintf(f, "  ");
    for (const char *p = s->help; *p; p++) {
        if (*p == '\n') col = fprintf(f, "\n%*s", HELP_COLUMN, "") - 1;
        else col += fputc(*p, f) != EOF;
    }
    const char *def = s->def_help ? s->def_help : s->def;
    int numeric = s->type == MX_OPTION_INT || s->type == MX_OPTION_FLOAT || s->type == MX_OPTION_FLOAT2 || s->type == MX_OPTION_FLOAT3;
    char range[160] = "", tail[320];
    if (numeric) describe_range(s, range, sizeof range);
    const char *quote = s->type == MX_OPTION_TEXT && !s->choices && def && *def && !s->def_help ? "\"" : "";
    int n = def || numeric ? snprintf(tail, sizeof tail, "(%s%s%s%s%s%s)", def ? "default " : "", quote, def ? def : "",
                                      quote, def && numeric ? "; " : "", range)
                           : 0;
    if (n && col + 1 + n > HELP_WIDTH) fprintf(f, "\n%*s%s", HELP_COLUMN, "", tail);
    else if (n) fprintf(f, " %s", tail);
    fputc('\n', f);
}

void mx_options_help(FILE *f, unsigned verb) {
    for (size_t i = 0; i < sizeof TABLE / sizeof TABLE[0]; i++)
        if (TABLE[i].verbs & verb) help_line(f, &TABLE[i]);
}

/* ---- a run's options (texture.h): pub by the table, then what the library gives the run ---- */

int mx_texture_opts_normals(const mx_texture_opts *o) {
    return o->pub.geometric_normals ? MX_NORMAL_GEOMETRIC : MX_NORMAL_FROM_DEPTH;
}

mx_up_axis mx_texture_opts_up(const mx_texture_opts *o) { return o->pub.z_up ? MX_UP_Z : MX_UP_Y; }

mx_precision mx_precision_of_option(int matex_precision) {
    if (matex_precision == MATEX_PRECISION_AUTO) return mx_cpu_faster_precision();
    return matex_precision == MATEX_PRECISION_FP32 ? MX_PREC_FP32 : MX_PREC_BF16;
}

mx_precision mx_texture_opts_precision(const mx_texture_opts *o) { return mx_precision_of_option(o->pub.precision); }

mx_backend_kind mx_texture_opts_device(const mx_texture_opts *o) {
    mx_backend_kind kind = MX_BACKEND_CPU;
    if (o->pub.device) mx_backend_parse(o->pub.device, &kind, NULL);
    return kind;
}

const char *mx_texture_opts_device_name(const mx_texture_opts *o) { return mx_backend_name(mx_texture_opts_device(o)); }

void mx_texture_opts_default(mx_texture_opts *o) {
    memset(o, 0, sizeof *o);
    matex_options_default(&o->pub);
    o->pub.verbose = 1;
}

static int blank(const char *s) {
    while (*s && isspace((unsigned char)*s)) s++;
    return *s == 0;
}

static int check_given(const mx_texture_opts *o, unsigned verb, mx_status *st) {
    const matex_options *p = &o->pub;
    /* the embedding API may give the mesh in memory, an opened model set, and keep the results */
    if (!o->mesh && (!p->mesh_path || !*p->mesh_path)) return mx_fail(st, MX_EUSAGE, "no mesh given");
    if (!o->keep_outputs && (!p->out_dir || !*p->out_dir))
        return mx_fail(st, MX_EUSAGE, "no output folder given (-o)");
    if (verb == MX_VERB_TRANSFER)
        return !p->source_path || !*p->source_path ? mx_fail(st, MX_EUSAGE, "no source mesh given") : 0;
    if (!o->models && (!o->weights_path || !*o->weights_path))
        return mx_fail(st, MX_EUSAGE, "no weight file given (--weights)");
    if (!p->prompt) return mx_fail(st, MX_EUSAGE, "no prompt given");
    if (verb == MX_VERB_TEXTURE && blank(p->prompt))
        return mx_fail(st, MX_EUSAGE, "the prompt is empty: describe the texture, e.g. \"a rustic wooden chair\"");
    return 0;
}

int mx_texture_opts_check(const mx_texture_opts *o, unsigned verb, mx_status *st) {
    return mx_options_check(&o->pub, verb, st) || check_given(o, verb, st) ? -1 : 0;
}
