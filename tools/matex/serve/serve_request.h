/* What a request to `matex serve` asks for, decoded and checked without the HTTP library (so the
 * fuzzer, tests/fuzz/fuzz_serve_request.c, links it alone): the route of a method and a URL, the
 * kind of an uploaded mesh from its file name, a job's options object (the keys of a batch
 * manifest line, tools/matex/cli_batch_manifest.h), and the error every refusal answers with:
 * an HTTP status and {"error": {"code": "...", "message": "..."}}. No name from a request ever
 * becomes a path: ids and file names are checked here against fixed alphabets. */
#ifndef MX_SERVE_REQUEST_H
#define MX_SERVE_REQUEST_H

#include <stddef.h>

#include "../../../runtime/buf.h"

#define MX_SERVE_ID_MAX 40   /* letters and digits */
#define MX_SERVE_NAME_MAX 64 /* an output file's name */

typedef enum {
    MX_ROUTE_NOT_FOUND,
    MX_ROUTE_BAD_METHOD, /* a known path, another method: 405 */
    MX_ROUTE_HEALTH,     /* GET /v1/health */
    MX_ROUTE_INFO,       /* GET /v1/info */
    MX_ROUTE_JOBS_LIST,  /* GET /v1/jobs */
    MX_ROUTE_JOB_SUBMIT, /* POST /v1/jobs */
    MX_ROUTE_JOB_GET,    /* GET /v1/jobs/ID */
    MX_ROUTE_JOB_DELETE, /* DELETE /v1/jobs/ID */
    MX_ROUTE_JOB_EVENTS, /* GET /v1/jobs/ID/events */
    MX_ROUTE_JOB_FILE    /* GET /v1/jobs/ID/files/NAME */
} mx_serve_route_kind;

typedef struct mx_serve_route {
    mx_serve_route_kind kind;
    char id[MX_SERVE_ID_MAX + 1];
    char name[MX_SERVE_NAME_MAX + 1];
    const char *allow; /* MX_ROUTE_BAD_METHOD: the methods the path takes (the Allow header) */
} mx_serve_route;

/* An error answer: status (400, 401, 403, 404, 405, 409, 413, 415, 429, 500 or 503), a code word
 * ("bad_options", "unauthorized", ...) and a one-line message. */
typedef struct mx_serve_error {
    int status;
    char code[32];
    char message[1024];
} mx_serve_error;

int mx_serve_fail(mx_serve_error *e, int status, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* {"error": {"code": ..., "message": ...}} into b. */
void mx_serve_error_json(const mx_serve_error *e, mx_buf *b);

/* The route of METHOD URL (the path only: the query is not part of the API). Fills r; never fails. */
void mx_serve_route_parse(const char *method, const char *url, mx_serve_route *r);
/* A job id: 1..MX_SERVE_ID_MAX letters and digits. */
int mx_serve_id_valid(const char *id);
/* An output file name: [A-Za-z0-9._-], not starting with '.', at most MX_SERVE_NAME_MAX. */
int mx_serve_name_valid(const char *name);

/* The extension a mesh part is stored under ("obj", "ply", "stl", "off", "glb", or "zip": a mesh
 * with its side files, serve_zip.h), from the file
 * name the client gave (only its extension is used); NULL with a 415 in e for any other kind. */
const char *mx_serve_mesh_kind(const char *filename, mx_serve_error *e);
/* The same for a style image part ("png", "jpg", "jpeg", "tif", "tiff"). */
const char *mx_serve_image_kind(const char *filename, mx_serve_error *e);

/* Reads the stored mesh as a run reads it (pipeline/geom/mesh.h): 0, or 400 "bad_mesh" with the
 * reader's message (the stored name in it, never the client's). With root (an unpacked zip's
 * folder), every texture file the mesh names must lie inside it. */
int mx_serve_mesh_check(const char *path, const char *root, mx_serve_error *e);
/* Checks a job's options object (len bytes) as `matex batch` checks a manifest line, with mesh and
 * the style images the stored files and out_dir the job's output folder: 0, or 400 "bad_options"
 * with the CLI's message. */
int mx_serve_options_check(const char *json, size_t len, const char *mesh, const char *out_dir,
                           const char *const *style_images, int nstyle, mx_serve_error *e);

#endif
