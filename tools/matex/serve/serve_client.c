#include "serve_client.h"

#include <curl/curl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../../pipeline/texture/outdir.h"
#include "../../../runtime/buf.h"
#include "../../../runtime/fileio.h"
#include "../../../runtime/json.h"
#include "serve_auth.h"
#include "serve_upload.h"

#define MANIFEST_MAX_BYTES ((size_t)1 << 30)
#define POLL_US 100000

int mx_serve_client_open(mx_serve_client *c, const char *url, const char *token_file, mx_status *st) {
    memset(c, 0, sizeof *c);
    size_t n = strlen(url);
    while (n && url[n - 1] == '/') n--;
    if (strncmp(url, "http://", 7) && strncmp(url, "https://", 8))
        return mx_fail(st, MX_EUSAGE, "--server wants an http:// or https:// URL, not '%s'", url);
    if (n >= sizeof c->url) return mx_fail(st, MX_EUSAGE, "--server: URL too long");
    memcpy(c->url, url, n);
    if (token_file && mx_serve_token_read(token_file, c->token, sizeof c->token, st)) return -1;
    if (curl_global_init(CURL_GLOBAL_DEFAULT)) return mx_fail(st, MX_EIO, "cannot start libcurl");
    return 0;
}

/* ---- the job's options ---- */

/* A JSON value of a manifest line written back as JSON. */
static void put_value(mx_buf *b, const mx_json *v) {
    switch (mx_json_kind(v)) {
    case MX_JSON_STR: mx_buf_json_str(b, mx_json_str(v)); break;
    case MX_JSON_NUM: mx_buf_printf(b, "%.17g", mx_json_num(v)); break;
    case MX_JSON_BOOL: mx_buf_printf(b, "%s", mx_json_bool(v) ? "true" : "false"); break;
    case MX_JSON_ARR:
        mx_buf_printf(b, "[");
        for (size_t i = 0; i < mx_json_len(v); i++) {
            if (i) mx_buf_printf(b, ",");
            put_value(b, mx_json_at(v, i));
        }
        mx_buf_printf(b, "]");
        break;
    default: mx_buf_printf(b, "null"); break; /* the server answers with the key's message */
    }
}

/* The option a line key or a default names ("image_size" -> "image-size"; NULL when none). */
static const char *option_name(const char *key) {
    const mx_option_spec *s = mx_option_find(key, MX_VERB_TEXTURE | MX_VERB_BATCH);
    return s ? s->name : NULL;
}

static int is_part_key(const char *key) {
    return !strcmp(key, "mesh") || !strcmp(key, "name") || !strcmp(key, "style_image") || !strcmp(key, "style-image");
}

/* The options part: the batch's defaults the line does not set, then the line's keys but mesh,
 * name and style_image (the style images go as files). */
static int options_json(const char *manifest, int line, const char *const *defaults, int ndefaults, mx_buf *b,
                        char *error, size_t cap) {
    mx_status st;
    size_t len, at = 0;
    char *text = mx_read_file(manifest, MANIFEST_MAX_BYTES, &len, &st);
    if (!text) return snprintf(error, cap, "%s", st.msg), -1;
    for (int l = 1; l < line && at < len; at++) l += text[at] == '\n';
    size_t end = at;
    while (end < len && text[end] != '\n') end++;
    mx_json *obj = mx_json_parse(text + at, end - at, "line", &st);
    free(text);
    if (!obj || mx_json_kind(obj) != MX_JSON_OBJ) return mx_json_free(obj), snprintf(error, cap, "%s: line %d is not a JSON object", manifest, line), -1;
    int n = 0;
    mx_buf_printf(b, "{");
    for (int i = 0; i < 2 * ndefaults; i += 2) {
        int set_by_line = 0;
        for (size_t k = 0; k < mx_json_len(obj) && !set_by_line; k++) {
            const char *name = option_name(mx_json_key(obj, k));
            set_by_line = name && !strcmp(name, defaults[i]);
        }
        if (set_by_line || is_part_key(defaults[i])) continue;
        mx_buf_printf(b, "%s\"%s\":", n++ ? "," : "", defaults[i]);
        if (defaults[i + 1]) mx_buf_json_str(b, defaults[i + 1]);
        else mx_buf_printf(b, "true");
    }
    for (size_t k = 0; k < mx_json_len(obj); k++) {
        const char *key = mx_json_key(obj, k);
        if (is_part_key(key)) continue;
        mx_buf_printf(b, "%s", n++ ? "," : "");
        mx_buf_json_str(b, key);
        mx_buf_printf(b, ":");
        put_value(b, mx_json_at(obj, k));
    }
    mx_buf_printf(b, "}");
    mx_json_free(obj);
    return b->oom ? (snprintf(error, cap, "out of memory"), -1) : 0;
}

/* ---- HTTP ---- */

static size_t to_buf(char *p, size_t size, size_t n, void *user) {
    mx_buf_put(user, p, size * n);
    return ((mx_buf *)user)->oom ? 0 : size * n;
}

/* One request: METHOD c->url + path, with a multipart body (or none), the answer into body (or
 * the file out). Returns the HTTP status, or -1 with the transport's error in error. */
static long http(const mx_serve_client *c, const char *method, const char *path, curl_mime *mime, mx_buf *body, FILE *out,
                 char *error, size_t cap) {
    CURL *h = curl_easy_init();
    char url[2048], auth[400];
    long status = -1;
    struct curl_slist *headers = NULL;
    if (!h) return snprintf(error, cap, "cannot start libcurl"), -1;
    snprintf(url, sizeof url, "%s%s", c->url, path);
    curl_easy_setopt(h, CURLOPT_URL, url);
    curl_easy_setopt(h, CURLOPT_CUSTOMREQUEST, method);
    curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(h, CURLOPT_CONNECTTIMEOUT, 10L);
    if (c->token[0]) {
        snprintf(auth, sizeof auth, "Authorization: Bearer %s", c->token);
        headers = curl_slist_append(headers, auth);
        curl_easy_setopt(h, CURLOPT_HTTPHEADER, headers);
    }
    if (mime) curl_easy_setopt(h, CURLOPT_MIMEPOST, mime);
    if (out) curl_easy_setopt(h, CURLOPT_WRITEDATA, out);
    else curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, to_buf), curl_easy_setopt(h, CURLOPT_WRITEDATA, body);
    CURLcode rc = curl_easy_perform(h);
    if (rc) snprintf(error, cap, "%s: %s", url, curl_easy_strerror(rc));
    else curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
    curl_slist_free_all(headers);
    curl_easy_cleanup(h);
    return status;
}

/* An error answer's message (or the status when the body says none). */
static void answer_error(long status, const mx_buf *body, char *error, size_t cap) {
    mx_status st;
    mx_json *j = body->p ? mx_json_parse(body->p, body->len, "answer", &st) : NULL;
    const mx_json *e = j ? mx_json_get(j, "error") : NULL;
    const char *msg = e ? mx_json_get_str(e, "message", NULL) : NULL;
    snprintf(error, cap, "server: HTTP %ld%s%s", status, msg ? ": " : "", msg ? msg : "");
    mx_json_free(j);
}

/* curl's reader and seeker of a mesh part made as a zip (a FILE *: serve_upload.h). */
static size_t read_zip(char *p, size_t size, size_t n, void *zip) { return fread(p, size, n, zip); }
static int seek_zip(void *zip, curl_off_t offset, int origin) {
    return fseeko(zip, (off_t)offset, origin) ? CURL_SEEKFUNC_FAIL : CURL_SEEKFUNC_OK;
}

/* The mesh part: the file itself, or zip (not NULL) as MESHNAME.zip. */
static void add_mesh_part(curl_mime *mime, const char *mesh, FILE *zip) {
    curl_mimepart *p = curl_mime_addpart(mime);
    curl_mime_name(p, "mesh");
    if (!zip) {
        curl_mime_filedata(p, mesh);
        return;
    }
    char name[300];
    const char *base = strrchr(mesh, '/');
    snprintf(name, sizeof name, "%.250s.zip", base ? base + 1 : mesh);
    fseeko(zip, 0, SEEK_END);
    curl_off_t size = (curl_off_t)ftello(zip);
    rewind(zip);
    curl_mime_data_cb(p, size, read_zip, seek_zip, NULL, zip);
    curl_mime_filename(p, name);
}

/* POST /v1/jobs (the mesh, or zip: the mesh with its side files): the job's id into id. */
static int submit(const mx_serve_client *c, const mx_batch_job *j, FILE *zip, const mx_buf *options, char *id,
                  size_t idcap, char *error, size_t cap) {
    CURL *h = curl_easy_init();
    curl_mime *mime = h ? curl_mime_init(h) : NULL;
    mx_buf body = {0};
    long status = -1;
    if (!mime) snprintf(error, cap, "cannot start libcurl");
    else {
        add_mesh_part(mime, j->c.o.mesh_path, zip);
        curl_mimepart *p = curl_mime_addpart(mime);
        curl_mime_name(p, "options");
        curl_mime_data(p, options->p, options->len);
        curl_mime_type(p, "application/json");
        for (int i = 0; i < MATEX_MAX_STYLE_IMAGES && j->c.o.style_images[i]; i++) {
            p = curl_mime_addpart(mime);
            curl_mime_name(p, "style_image");
            curl_mime_filedata(p, j->c.o.style_images[i]);
        }
        status = http(c, "POST", "/v1/jobs", mime, &body, NULL, error, cap);
    }
    mx_status st;
    mx_json *a = status == 202 ? mx_json_parse(body.p, body.len, "answer", &st) : NULL;
    const char *got = a ? mx_json_get_str(a, "id", NULL) : NULL;
    if (got && mx_serve_id_valid(got)) snprintf(id, idcap, "%s", got);
    else if (status >= 0) answer_error(status, &body, error, cap);
    mx_json_free(a);
    mx_buf_free(&body);
    curl_mime_free(mime);
    if (h) curl_easy_cleanup(h);
    return got && id[0] ? 0 : -1;
}

/* GET /v1/jobs/ID until the job ends: its description (free it) or NULL (error set); *stop
 * cancels it (DELETE) and returns NULL with *interrupted set. */
static mx_json *await_job(const mx_serve_client *c, const char *id, volatile sig_atomic_t *stop, int *interrupted,
                          char *error, size_t cap) {
    char path[128];
    snprintf(path, sizeof path, "/v1/jobs/%s", id);
    for (;;) {
        mx_buf body = {0};
        mx_status st;
        if (*stop) {
            http(c, "DELETE", path, NULL, &body, NULL, error, cap);
            mx_buf_free(&body);
            *interrupted = 1;
            return NULL;
        }
        long status = http(c, "GET", path, NULL, &body, NULL, error, cap);
        mx_json *d = status == 200 ? mx_json_parse(body.p, body.len, "answer", &st) : NULL;
        const char *state = d ? mx_json_get_str(d, "state", "") : "";
        if (status >= 0 && !d) answer_error(status, &body, error, cap);
        mx_buf_free(&body);
        if (!d || (strcmp(state, "queued") && strcmp(state, "running"))) return d;
        mx_json_free(d);
        usleep(POLL_US);
    }
}

/* The files of a done job into the output folder, published as a local run publishes it. */
static int fetch_files(const mx_serve_client *c, const char *id, const mx_json *files, const char *out_dir,
                       const char *mesh, volatile sig_atomic_t *stop, char *error, size_t cap) {
    mx_outdir od;
    mx_status st;
    const char *inputs[1] = {mesh};
    if (mx_outdir_open(&od, out_dir, 0, inputs, 1, &st)) return snprintf(error, cap, "%s", st.msg), -1;
    int rc = 0;
    for (size_t i = 0; i < mx_json_len(files) && !rc; i++) {
        const char *name = mx_json_str(mx_json_at(files, i));
        char path[4400], url[256];
        if (!name || !mx_serve_name_valid(name)) rc = -1, snprintf(error, cap, "server: a bad file name in the job's list");
        else {
            snprintf(path, sizeof path, "%s/%s", od.stage, name);
            snprintf(url, sizeof url, "/v1/jobs/%s/files/%s", id, name);
            FILE *f = fopen(path, "wbx");
            long status = f ? http(c, "GET", url, NULL, NULL, f, error, cap) : -1;
            if ((f && fclose(f)) || status != 200) rc = -1, snprintf(error + strlen(error), cap - strlen(error), "%s%s: download failed", error[0] ? "; " : "", name);
        }
    }
    if (!rc && mx_outdir_publish(&od, stop, &st)) rc = -1, snprintf(error, cap, "%s", st.msg);
    mx_outdir_discard(&od);
    return rc;
}

int mx_serve_client_run(const mx_serve_client *c, const char *manifest, const mx_batch_job *j,
                        const char *const *defaults, int ndefaults, volatile sig_atomic_t *stop, double *coverage,
                        char *error, size_t cap) {
    mx_buf options = {0};
    char id[MX_SERVE_ID_MAX + 1] = "", path[128];
    int interrupted = 0, rc = -1;
    FILE *zip = NULL;
    mx_status st;
    error[0] = 0;
    if (mx_serve_upload_zip(j->c.o.mesh_path, &zip, &st)) snprintf(error, cap, "%s", st.msg);
    int failed = error[0] || options_json(manifest, j->line, defaults, ndefaults, &options, error, cap) ||
                 submit(c, j, zip, &options, id, sizeof id, error, cap);
    if (zip) fclose(zip);
    mx_buf_free(&options);
    if (failed) return -1;
    mx_json *d = await_job(c, id, stop, &interrupted, error, cap);
    const char *state = d ? mx_json_get_str(d, "state", "") : "";
    const mx_json *progress = d ? mx_json_get(d, "progress") : NULL;
    if (interrupted) rc = 1;
    else if (d && !strcmp(state, "done"))
        rc = fetch_files(c, id, mx_json_get(d, "files"), j->c.o.out_dir, j->c.o.mesh_path, stop, error, cap);
    else if (d) snprintf(error, cap, "server: job %s %s%s%s", id, state, mx_json_get_str(d, "error", NULL) ? ": " : "",
                         mx_json_get_str(d, "error", ""));
    if (!rc && progress) *coverage = mx_json_get_num(progress, "coverage", 0.0);
    mx_json_free(d);
    if (!interrupted) {
        mx_buf body = {0};
        snprintf(path, sizeof path, "/v1/jobs/%s", id);
        http(c, "DELETE", path, NULL, &body, NULL, error + strlen(error), cap - strlen(error)); /* the server keeps no copy */
        mx_buf_free(&body);
    }
    return rc;
}
