#include "cli_batch_manifest.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../pipeline/texture/style.h"
#include "../../runtime/fileio.h"
#include "../../runtime/json.h"

#define MANIFEST_MAX_BYTES ((size_t)1 << 30)
#define JOB_MAX_TEXTS 64

static void job_error(mx_batch_job *j, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void job_error(mx_batch_job *j, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(j->error, sizeof j->error, fmt, ap);
    va_end(ap);
}

/* A copy of s owned by the job (NULL when out of room or memory). */
static const char *keep(mx_batch_job *j, const char *s) {
    if (j->ntexts == JOB_MAX_TEXTS || !(j->texts[j->ntexts] = strdup(s))) return NULL;
    return j->texts[j->ntexts++];
}

/* A JSON value as the command line writes it: a number, a string, [A, B] as "A,B", true as a
 * flag (*text NULL), false as absent (-1 in *absent). */
static int value_text(const mx_json *v, char *out, size_t cap, const char **text, int *absent) {
    *text = out;
    *absent = 0;
    switch (mx_json_kind(v)) {
    case MX_JSON_STR: return (size_t)snprintf(out, cap, "%s", mx_json_str(v)) < cap ? 0 : -1;
    case MX_JSON_NUM: snprintf(out, cap, "%.17g", mx_json_num(v)); return 0;
    case MX_JSON_BOOL:
        if (mx_json_bool(v)) *text = NULL;
        else *absent = 1;
        return 0;
    case MX_JSON_ARR: {
        size_t n = mx_json_len(v), at = 0;
        if (n < 1 || n > 3) return -1;
        for (size_t i = 0; i < n; i++) {
            if (mx_json_kind(mx_json_at(v, i)) != MX_JSON_NUM) return -1;
            at += (size_t)snprintf(out + at, cap - at, "%s%.9g", i ? "," : "", mx_json_num(mx_json_at(v, i)));
        }
        return 0;
    }
    default: return -1;
    }
}

/* Why a key that names an option is not a manifest key, in why[] ("" when it is one). */
static void not_a_key(const mx_option_spec *s, char *why, size_t cap) {
    if (s->scope == MX_SCOPE_MODELS)
        snprintf(why, cap, "is the model set's, one for the whole batch: give --%s to matex batch", s->name);
    else if (!strcmp(s->name, "force"))
        snprintf(why, cap, "is not a job key: batch skips a job whose folder is complete (remove the folder to run it again)");
    else if (s->scope == MX_SCOPE_RUN)
        snprintf(why, cap, "is not a job key: a job writes OUTROOT/NAME with the batch's weights");
    else why[0] = 0;
}

/* The default name: the mesh's file name without extension, reduced to [A-Za-z0-9._-]. */
static void default_name(const char *mesh, char *name, size_t cap) {
    const char *base = strrchr(mesh, '/') ? strrchr(mesh, '/') + 1 : mesh;
    snprintf(name, cap, "%s", base);
    char *dot = strrchr(name, '.');
    if (dot && dot != name) *dot = 0;
    for (char *p = name; *p; p++)
        if (!strchr("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-", *p)) *p = '_';
}

static int valid_name(const char *s) {
    if (!*s || *s == '.') return 0;
    return strspn(s, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-") == strlen(s);
}

/* A path of the manifest: relative ones are relative to its folder dir ("" when none). */
static int resolve(const char *dir, const char *rel, char *out, size_t cap) {
    int n = rel[0] == '/' || !*dir ? snprintf(out, cap, "%s", rel) : snprintf(out, cap, "%s/%s", dir, rel);
    return n < 0 || (size_t)n >= cap ? -1 : 0;
}

/* mesh, prompt, name and the output folder; dir: the manifest's folder ("" when none). */
static int job_head(mx_batch_job *j, const mx_json *obj, const char *dir, const char *outroot) {
    const char *mesh = mx_json_get_str(obj, "mesh", NULL), *prompt = mx_json_get_str(obj, "prompt", NULL);
    const char *name = mx_json_get_str(obj, "name", NULL);
    if (!mesh || !*mesh) return job_error(j, "no \"mesh\" (a string)"), -1;
    if (!prompt) return job_error(j, "no \"prompt\" (a string)"), -1;
    if (mx_json_get(obj, "name") && !name) return job_error(j, "\"name\" must be a string"), -1;
    if (name) snprintf(j->name, sizeof j->name, "%s", name);
    else default_name(mesh, j->name, sizeof j->name);
    if (!valid_name(j->name) || (name && strlen(name) >= sizeof j->name))
        return job_error(j, "name \"%s\" is not a folder name (letters, digits, '.', '_', '-')", j->name), -1;
    char path[4096], out[4096];
    int m = snprintf(out, sizeof out, "%s/%s", outroot, j->name);
    if (resolve(dir, mesh, path, sizeof path) || m < 0 || (size_t)m >= sizeof out) return job_error(j, "path too long"), -1;
    mx_cli_texture *c = &j->c;
    memset(c, 0, sizeof *c);
    matex_options_default(&c->o);
    c->verb = MX_VERB_TEXTURE;
    c->quiet = 1;
    if (!(c->o.mesh_path = keep(j, path)) || !(c->o.prompt = keep(j, prompt)) || !(c->o.out_dir = keep(j, out)))
        return job_error(j, "out of memory"), -1;
    return 0;
}

/* A path-list key (style_image): a string or an array of strings, each relative to the manifest's
 * folder; the line's list replaces the batch's (--theme). */
static int job_paths(mx_batch_job *j, const mx_option_spec *s, const char *key, const mx_json *v, const char *dir) {
    int is_arr = mx_json_kind(v) == MX_JSON_ARR;
    size_t n = is_arr ? mx_json_len(v) : 1;
    if (!is_arr && mx_json_kind(v) != MX_JSON_STR) return job_error(j, "\"%s\" takes a file name or an array of them", key), -1;
    mx_option_clear_paths(s, &j->c.o);
    for (size_t i = 0; i < n; i++) {
        const mx_json *e = is_arr ? mx_json_at(v, i) : v;
        char path[4096];
        const char *text;
        mx_status st;
        if (mx_json_kind(e) != MX_JSON_STR) return job_error(j, "\"%s\" takes a file name or an array of them", key), -1;
        if (resolve(dir, mx_json_str(e), path, sizeof path)) return job_error(j, "\"%s\": path too long", key), -1;
        if (!(text = keep(j, path))) return job_error(j, "too many options"), -1;
        if (mx_cli_texture_option(&j->c, key, text, &st)) return job_error(j, "\"%s\": %s", key, st.msg), -1;
    }
    return 0;
}

/* One key of the line into the job's options (the error names the key). */
static int job_key(mx_batch_job *j, const char *key, const mx_json *v, const char *dir) {
    char k[64], value[1024];
    snprintf(k, sizeof k, "%s", !strcmp(key, "negative_prompt") || !strcmp(key, "negative-prompt") ? "negative" : key);
    const mx_option_spec *s = mx_option_find(k, MX_VERB_TEXTURE);
    const char *text;
    int absent;
    mx_status st;
    if (!s) return job_error(j, "unknown key \"%s\"", key), -1;
    char why[160];
    not_a_key(s, why, sizeof why);
    if (why[0]) return job_error(j, "\"%s\" %s", key, why), -1;
    if (s->type == MX_OPTION_PATHS) return job_paths(j, s, key, v, dir);
    int is_flag = s->type == MX_OPTION_FLAG, is_bool = mx_json_kind(v) == MX_JSON_BOOL;
    if (is_flag != is_bool)
        return job_error(j, "\"%s\" takes %s", key, is_flag ? "true or false" : "a number, a text or an array of numbers"), -1;
    if (value_text(v, value, sizeof value, &text, &absent)) return job_error(j, "bad value for \"%s\"", key), -1;
    if (absent) return 0;
    if (text && !(text = keep(j, text))) return job_error(j, "too many options"), -1;
    if (mx_cli_texture_option(&j->c, k, text, &st)) return job_error(j, "\"%s\": %s", key, st.msg), -1;
    return 0;
}

/* The defaults, then every key of obj but mesh, prompt and name, then the checks of a whole job. */
static void job_keys(mx_batch_job *j, const mx_json *obj, const char *dir, const char *const *defaults, int ndefaults) {
    mx_status st;
    for (int i = 0; i < 2 * ndefaults && !j->error[0]; i += 2)
        if (mx_cli_texture_option(&j->c, defaults[i], defaults[i + 1], &st)) job_error(j, "%s", st.msg);
    for (size_t i = 0; i < mx_json_len(obj) && !j->error[0]; i++) {
        const char *key = mx_json_key(obj, i);
        if (strcmp(key, "mesh") && strcmp(key, "prompt") && strcmp(key, "name")) job_key(j, key, mx_json_at(obj, i), dir);
    }
    mx_cli_texture *c = &j->c;
    if (c->o.fast && !c->steps_given) c->o.steps = 4;
    if (c->o.fast && !c->guidance_given) c->o.guidance = 1.0f;
    if (!j->error[0] && (mx_options_check(&c->o, MX_VERB_TEXTURE, &st) || mx_style_check_inputs(&c->o, &st)))
        job_error(j, "%s", st.msg);
}

/* The whole line when `options` is set, else only what names the job (for the uniqueness check). */
static void parse_job(mx_batch_job *j, const char *text, size_t len, const char *dir, const char *const *defaults,
                      int ndefaults, const char *outroot, int options) {
    mx_status st;
    mx_json *obj = mx_json_parse(text, len, "line", &st);
    if (!obj) return job_error(j, "%s", st.msg);
    if (mx_json_kind(obj) != MX_JSON_OBJ) job_error(j, "not a JSON object");
    else if (!job_head(j, obj, dir, outroot) && options) job_keys(j, obj, dir, defaults, ndefaults);
    mx_json_free(obj);
}

int mx_batch_job_from_options(mx_batch_job *j, const char *text, size_t len, const char *mesh, const char *out_dir,
                              const char *const *style_images, int nstyle) {
    memset(j, 0, sizeof *j);
    mx_status st;
    mx_json *obj = NULL;
    if (!(j->texts = calloc(JOB_MAX_TEXTS, sizeof *j->texts))) job_error(j, "out of memory");
    else if (!(obj = mx_json_parse(text, len, "options", &st))) job_error(j, "%s", st.msg);
    else if (mx_json_kind(obj) != MX_JSON_OBJ) job_error(j, "options: not a JSON object");
    else if (mx_json_get(obj, "mesh") || mx_json_get(obj, "name") || mx_json_get(obj, "style_image") ||
             mx_json_get(obj, "style-image"))
        job_error(j, "\"%s\" is not an options key here: the mesh and style images are parts of the request, the job "
                     "is named by the server", mx_json_get(obj, "mesh") ? "mesh" : mx_json_get(obj, "name") ? "name" : "style_image");
    else if (!mx_json_get_str(obj, "prompt", NULL)) job_error(j, "no \"prompt\" (a string)");
    else {
        mx_cli_texture *c = &j->c;
        matex_options_default(&c->o);
        c->verb = MX_VERB_TEXTURE;
        c->quiet = 1;
        if (!(c->o.mesh_path = keep(j, mesh)) || !(c->o.prompt = keep(j, mx_json_get_str(obj, "prompt", ""))) ||
            !(c->o.out_dir = keep(j, out_dir)))
            job_error(j, "out of memory");
        for (int i = 0; i < nstyle && !j->error[0]; i++)
            if (mx_cli_texture_option(c, "style-image", style_images[i], &st)) job_error(j, "style_image: %s", st.msg);
        if (!j->error[0]) job_keys(j, obj, "", NULL, 0);
    }
    mx_json_free(obj);
    return j->error[0] ? -1 : 0;
}

void mx_batch_job_free(mx_batch_job *j) {
    for (int k = 0; k < j->ntexts; k++) free(j->texts[k]);
    free(j->texts);
    j->texts = NULL;
    j->ntexts = 0;
}

static int line_is_blank(const char *s, size_t n) {
    for (size_t i = 0; i < n; i++)
        if (!strchr(" \t\r", s[i])) return 0;
    return 1;
}

static void check_unique_names(mx_batch_manifest *m) {
    for (int i = 0; i < m->njobs; i++)
        for (int k = 0; k < i && !m->jobs[i].error[0]; k++)
            if (!m->jobs[k].error[0] && !strcmp(m->jobs[k].name, m->jobs[i].name))
                job_error(&m->jobs[i], "name \"%s\" is already used by line %d", m->jobs[i].name, m->jobs[k].line);
}

int mx_batch_manifest_read(mx_batch_manifest *m, const char *path, const char *const *defaults, int ndefaults,
                           const char *outroot, int shard, int nshards, mx_status *st) {
    memset(m, 0, sizeof *m);
    size_t len;
    char *text = mx_read_file(path, MANIFEST_MAX_BYTES, &len, st);
    if (!text) return -1;
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (slash) *slash = 0;
    else dir[0] = 0;
    size_t cap = 1;
    for (size_t i = 0; i < len; i++) cap += text[i] == '\n';
    m->jobs = calloc(cap, sizeof *m->jobs);
    if (!m->jobs) {
        free(text);
        return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    }
    int line = 0;
    for (size_t at = 0; at < len;) {
        size_t end = at;
        while (end < len && text[end] != '\n') end++;
        line++;
        if (!line_is_blank(text + at, end - at)) {
            mx_batch_job *j = &m->jobs[m->njobs];
            j->line = line;
            j->index = m->njobs++;
            j->texts = calloc(JOB_MAX_TEXTS, sizeof *j->texts);
            if (!j->texts) job_error(j, "out of memory");
            else parse_job(j, text + at, end - at, dir, defaults, ndefaults, outroot, j->index % nshards == shard);
        }
        at = end + 1;
    }
    free(text);
    check_unique_names(m);
    return 0;
}

void mx_batch_manifest_free(mx_batch_manifest *m) {
    for (int i = 0; i < m->njobs; i++) mx_batch_job_free(&m->jobs[i]);
    free(m->jobs);
    memset(m, 0, sizeof *m);
}
