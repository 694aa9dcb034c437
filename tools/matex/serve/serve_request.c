#include "serve_request.h"

#include <ctype.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../../pipeline/geom/mesh.h"
#include "../../../pipeline/io/mesh_load.h"
#include "../cli_batch_manifest.h"

#define ALNUM "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789"

int mx_serve_fail(mx_serve_error *e, int status, const char *code, const char *fmt, ...) {
    va_list ap;
    e->status = status;
    snprintf(e->code, sizeof e->code, "%s", code);
    va_start(ap, fmt);
    vsnprintf(e->message, sizeof e->message, fmt, ap);
    va_end(ap);
    return -1;
}

void mx_serve_error_json(const mx_serve_error *e, mx_buf *b) {
    mx_buf_printf(b, "{\"error\":{\"code\":");
    mx_buf_json_str(b, e->code);
    mx_buf_printf(b, ",\"message\":");
    mx_buf_json_str(b, e->message);
    mx_buf_printf(b, "}}\n");
}

int mx_serve_id_valid(const char *id) {
    size_t n = strlen(id);
    return n >= 1 && n <= MX_SERVE_ID_MAX && strspn(id, ALNUM) == n;
}

int mx_serve_name_valid(const char *name) {
    size_t n = strlen(name);
    return n >= 1 && n <= MX_SERVE_NAME_MAX && name[0] != '.' && strspn(name, ALNUM "._-") == n;
}

/* Splits the path of url (up to '?' or '#') at '/' into at most 5 segments of seg; the count, or -1
 * when the path does not start with '/', has an empty or too long segment, or more segments. */
static int split_path(const char *url, char seg[5][MX_SERVE_NAME_MAX + 1]) {
    size_t len = strcspn(url, "?#");
    int n = 0;
    if (url[0] != '/') return -1;
    for (size_t at = 1; at <= len; n++) {
        size_t k = at;
        while (k < len && url[k] != '/') k++;
        if (n == 5 || k == at || k - at > MX_SERVE_NAME_MAX) return -1;
        memcpy(seg[n], url + at, k - at);
        seg[n][k - at] = 0;
        at = k + 1;
    }
    return n;
}

/* A path the API knows: GET (and HEAD) give `get`; `other_method` (or NULL) gives `other`. */
static void route_for(mx_serve_route *r, const char *method, const char *allow, mx_serve_route_kind get,
                      const char *other_method, mx_serve_route_kind other) {
    r->allow = allow;
    if (!strcmp(method, "GET") || !strcmp(method, "HEAD")) r->kind = get;
    else if (other_method && !strcmp(method, other_method)) r->kind = other;
    else r->kind = MX_ROUTE_BAD_METHOD;
}

void mx_serve_route_parse(const char *method, const char *url, mx_serve_route *r) {
    memset(r, 0, sizeof *r);
    r->kind = MX_ROUTE_NOT_FOUND;
    char seg[5][MX_SERVE_NAME_MAX + 1];
    int n = split_path(url, seg);
    if (n < 2 || strcmp(seg[0], "v1")) return;
    if (n == 2 && !strcmp(seg[1], "health")) return route_for(r, method, "GET, HEAD", MX_ROUTE_HEALTH, NULL, 0);
    if (n == 2 && !strcmp(seg[1], "info")) return route_for(r, method, "GET, HEAD", MX_ROUTE_INFO, NULL, 0);
    if (strcmp(seg[1], "jobs")) return;
    if (n == 2) return route_for(r, method, "GET, HEAD, POST", MX_ROUTE_JOBS_LIST, "POST", MX_ROUTE_JOB_SUBMIT);
    if (!mx_serve_id_valid(seg[2])) return;
    snprintf(r->id, sizeof r->id, "%.40s", seg[2]); /* valid: at most 40 */
    if (n == 3) return route_for(r, method, "GET, HEAD, DELETE", MX_ROUTE_JOB_GET, "DELETE", MX_ROUTE_JOB_DELETE);
    if (n == 4 && !strcmp(seg[3], "events")) return route_for(r, method, "GET, HEAD", MX_ROUTE_JOB_EVENTS, NULL, 0);
    if (n == 5 && !strcmp(seg[3], "files") && mx_serve_name_valid(seg[4])) {
        snprintf(r->name, sizeof r->name, "%s", seg[4]);
        route_for(r, method, "GET, HEAD", MX_ROUTE_JOB_FILE, NULL, 0);
    }
}

/* The lower-case extension of a file name into ext ("" when none or too long). */
static void extension(const char *filename, char *ext, size_t cap) {
    const char *dot = filename ? strrchr(filename, '.') : NULL;
    ext[0] = 0;
    if (!dot || strlen(dot + 1) >= cap) return;
    size_t i = 0;
    for (const char *s = dot + 1; *s; s++) ext[i++] = (char)tolower((unsigned char)*s);
    ext[i] = 0;
}

static const char *kind_of(const char *filename, const char *const *kinds, size_t n, const char *part, const char *list,
                           mx_serve_error *e) {
    char ext[8];
    extension(filename, ext, sizeof ext);
    for (size_t i = 0; i < n; i++)
        if (!strcmp(ext, kinds[i])) return kinds[i];
    mx_serve_fail(e, 415, "unsupported_media_type", "part \"%s\": the file name must end in %s", part, list);
    return NULL;
}

const char *mx_serve_mesh_kind(const char *filename, mx_serve_error *e) {
    static const char *const kinds[] = {"obj", "ply", "stl", "off", "glb", "zip"};
    return kind_of(filename, kinds, sizeof kinds / sizeof kinds[0], "mesh",
                   ".obj, .ply, .stl, .off, .glb, or .zip (a mesh with its side files)", e);
}

const char *mx_serve_image_kind(const char *filename, mx_serve_error *e) {
    static const char *const kinds[] = {"png", "jpg", "jpeg", "tif", "tiff"};
    return kind_of(filename, kinds, sizeof kinds / sizeof kinds[0], "style_image", ".png, .jpg, .jpeg, .tif or .tiff", e);
}

int mx_serve_options_check(const char *json, size_t len, const char *mesh, const char *out_dir,
                           const char *const *style_images, int nstyle, mx_serve_error *e) {
    mx_batch_job j;
    int rc = mx_batch_job_from_options(&j, json, len, mesh, out_dir, style_images, nstyle);
    if (rc) mx_serve_fail(e, 400, "bad_options", "options: %s", j.error);
    mx_batch_job_free(&j);
    return rc;
}

/* Every texture file the mesh names that exists must lie inside root (an MTL or a glTF in a zip
 * may name any path: "/home/someone/secret.png", "../../x.png"). A "#imageN" suffix (an image
 * inside a .glb / .gltf) is dropped first; a file that does not exist is not read by a run. */
static int textures_inside(const mx_mesh *m, const char *root, mx_serve_error *e) {
    char real_root[PATH_MAX], file[sizeof m->mats[0].texture_path], real[PATH_MAX];
    if (!realpath(root, real_root)) return mx_serve_fail(e, 503, "storage", "cannot resolve the job folder");
    size_t rl = strlen(real_root);
    for (int i = 0; i < m->nmat; i++) {
        snprintf(file, sizeof file, "%s", m->mats[i].texture_path);
        char *hash = strstr(file, "#image");
        if (hash) *hash = 0;
        if (!file[0] || !realpath(file, real)) continue;
        if (strncmp(real, real_root, rl) || real[rl] != '/')
            return mx_serve_fail(e, 400, "bad_mesh", "part \"mesh\": material '%.100s' names a texture outside the archive",
                                 m->mats[i].name);
    }
    return 0;
}

int mx_serve_mesh_check(const char *path, const char *root, mx_serve_error *e) {
    mx_mesh m;
    mx_status st;
    memset(&m, 0, sizeof m);
    int rc = mx_mesh_load(path, &m, &st);
    if (rc) return mx_serve_fail(e, 400, "bad_mesh", "part \"mesh\": %s", st.msg);
    if (root) rc = textures_inside(&m, root, e);
    mx_mesh_free(&m);
    return rc;
}
