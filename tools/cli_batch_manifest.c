#include "cli_batch_manifest.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../runtime/fileio.h"
#include "../runtime/json.h"

#define MANIFEST_MAX_BYTES ((size_t)1 << 30)
#define JOB_MAX_ARGS 64

/* The texture options a manifest line may set (batch-wide ones, such as --threads, it may not). */
static const char *const JOB_OPTIONS[] = {
    "seed",   "steps",    "views",         "candidates",     "texture-size", "render-size",
    "image-size", "batch", "negative",     "guidance",       "grid-depth-weight", "depth-weight",
    "inpaint-weight", "frontal-threshold", "normals", "coverage-stop", "front-back-words", "up",
};

static void job_error(mx_batch_job *j, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void job_error(mx_batch_job *j, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(j->error, sizeof j->error, fmt, ap);
    va_end(ap);
}

static int add_arg(mx_batch_job *j, const char *s) {
    if (j->nargs == JOB_MAX_ARGS) return -1;
    if (!(j->args[j->nargs] = strdup(s))) return -1;
    j->nargs++;
    return 0;
}

/* "--image-size" from "image_size" / "image-size" when it is a job option, else "". */
static void option_flag(const char *key, char flag[64]) {
    char k[48];
    snprintf(k, sizeof k, "%s", key);
    for (char *p = k; *p; p++)
        if (*p == '_') *p = '-';
    if (!strcmp(k, "negative-prompt")) snprintf(k, sizeof k, "negative");
    flag[0] = 0;
    for (size_t i = 0; i < sizeof JOB_OPTIONS / sizeof JOB_OPTIONS[0]; i++)
        if (!strcmp(k, JOB_OPTIONS[i])) snprintf(flag, 64, "--%s", k);
}

/* A JSON value as the command line writes it: a number, a string, or [A, B] as "A,B". */
static int value_text(const mx_json *v, char *out, size_t cap) {
    switch (mx_json_kind(v)) {
    case MX_JSON_STR: return (size_t)snprintf(out, cap, "%s", mx_json_str(v)) < cap ? 0 : -1;
    case MX_JSON_NUM: snprintf(out, cap, "%.17g", mx_json_num(v)); return 0;
    case MX_JSON_ARR:
        if (mx_json_len(v) != 2 || mx_json_kind(mx_json_at(v, 0)) != MX_JSON_NUM ||
            mx_json_kind(mx_json_at(v, 1)) != MX_JSON_NUM)
            return -1;
        snprintf(out, cap, "%.9g,%.9g", mx_json_num(mx_json_at(v, 0)), mx_json_num(mx_json_at(v, 1)));
        return 0;
    default: return -1;
    }
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

/* mesh, prompt, name and the fixed arguments; dir: the manifest's folder ("" when none). */
static int job_head(mx_batch_job *j, const mx_json *obj, const char *dir, const char *weights, const char *outroot) {
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
    int n = mesh[0] == '/' || !*dir ? snprintf(path, sizeof path, "%s", mesh) : snprintf(path, sizeof path, "%s/%s", dir, mesh);
    int m = snprintf(out, sizeof out, "%s/%s", outroot, j->name);
    if (n < 0 || (size_t)n >= sizeof path || m < 0 || (size_t)m >= sizeof out) return job_error(j, "path too long"), -1;
    if (add_arg(j, "batch") || add_arg(j, path) || add_arg(j, prompt) || add_arg(j, "--weights") ||
        add_arg(j, weights) || add_arg(j, "-o") || add_arg(j, out) || add_arg(j, "--quiet"))
        return job_error(j, "out of memory"), -1;
    return 0;
}

static void parse_usage(FILE *f) { (void)f; }

/* One option through the command-line parser, alone, so that a bad value names its key. */
static int check_option(const char *flag, const char *value) {
    char *argv[] = {"batch", "m", "p", "--weights", "w", "-o", "o", (char *)flag, (char *)value};
    mx_cli_texture scratch;
    return mx_cli_texture_parse(&scratch, 9, argv, 0, parse_usage) >= 0 ? -1 : 0;
}

/* The whole line when `options` is set, else only what names the job (for the uniqueness check). */
static void parse_job(mx_batch_job *j, const char *text, size_t len, const char *dir, const char *weights,
                      const char *outroot, int options) {
    mx_status st;
    mx_json *obj = mx_json_parse(text, len, "line", &st);
    if (!obj) return job_error(j, "%s", st.msg);
    if (mx_json_kind(obj) != MX_JSON_OBJ) {
        job_error(j, "not a JSON object");
    } else if (!job_head(j, obj, dir, weights, outroot) && options) {
        for (size_t i = 0; i < mx_json_len(obj) && !j->error[0]; i++) {
            const char *key = mx_json_key(obj, i);
            char flag[64], value[1024];
            if (!strcmp(key, "mesh") || !strcmp(key, "prompt") || !strcmp(key, "name")) continue;
            option_flag(key, flag);
            if (!flag[0]) job_error(j, "unknown key \"%s\"", key);
            else if (value_text(mx_json_at(obj, i), value, sizeof value)) job_error(j, "bad value for \"%s\"", key);
            else if (check_option(flag, value)) job_error(j, "bad value for \"%s\": %s", key, value);
            else if (add_arg(j, flag) || add_arg(j, value)) job_error(j, "too many options");
        }
        if (!j->error[0] && mx_cli_texture_parse(&j->c, j->nargs, j->args, 0, parse_usage) >= 0)
            job_error(j, "bad options");
    }
    mx_json_free(obj);
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

int mx_batch_manifest_read(mx_batch_manifest *m, const char *path, const char *weights, const char *outroot,
                           int shard, int nshards, mx_status *st) {
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
            j->args = calloc(JOB_MAX_ARGS, sizeof *j->args);
            if (!j->args) job_error(j, "out of memory");
            else parse_job(j, text + at, end - at, dir, weights, outroot, j->index % nshards == shard);
        }
        at = end + 1;
    }
    free(text);
    check_unique_names(m);
    return 0;
}

void mx_batch_manifest_free(mx_batch_manifest *m) {
    for (int i = 0; i < m->njobs; i++) {
        for (int k = 0; k < m->jobs[i].nargs; k++) free(m->jobs[i].args[k]);
        free(m->jobs[i].args);
    }
    free(m->jobs);
    memset(m, 0, sizeof *m);
}
