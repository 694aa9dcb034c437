/* The HTTP side of `matex serve` (libmicrohttpd, one thread per connection): the routes of
 * serve_request.h, the uploads of POST /v1/jobs into the queue's upload folder, the event
 * stream of a job, its output files, and the server's life: models loaded once, a worker
 * thread, SIGINT/SIGTERM. */
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <microhttpd.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../../../pipeline/texture/digest.h"
#include "../../../pipeline/texture/texture.h"
#include "../../../runtime/atomic_file.h"
#include "../../../runtime/version.h"
#include "../../../weights/networks.h"
#include "../cli_signals.h"
#include "serve.h"
#include "serve_auth.h"
#include "serve_request.h"
#include "serve_zip.h"

#define OPTIONS_PART_MAX ((size_t)64 << 10)
#define POST_BUFFER 65536

typedef struct server {
    const mx_serve_config *cfg;
    mx_serve_jobs q;
    mx_serve_auth auth;
    mx_buf info; /* GET /v1/info, made once the model set is loaded */
    _Atomic int ready; /* info is made */
    _Atomic int stopping; /* event streams end */
} server;

/* The state of one request across the calls libmicrohttpd makes for it. */
typedef struct request {
    mx_serve_error err;
    int failed; /* err holds the answer */
    /* POST /v1/jobs */
    struct MHD_PostProcessor *pp;
    char id[MX_SERVE_ID_MAX + 1], stage[4200];
    int staged, committed;
    uint64_t bytes;
    int part_fd;           /* the file part being written, or -1 */
    char mesh_path[4300];  /* the stored mesh ("" until its part came) */
    int mesh_zip;          /* mesh_path is a .zip of the mesh with its side files */
    char style_paths[MATEX_MAX_STYLE_IMAGES][4300];
    int nstyle;
    mx_buf options;
    int have_options;
} request;

/* ---- answers ---- */

/* A response holding body (copied; a fixed error body when it ran out of memory), with the headers
 * every answer has. No CORS header is ever sent. */
static struct MHD_Response *json_response(const mx_buf *body, int *status) {
    static const char oom[] = "{\"error\":{\"code\":\"internal\",\"message\":\"out of memory\"}}\n";
    struct MHD_Response *r = body->oom ? MHD_create_response_from_buffer(sizeof oom - 1, (void *)oom, MHD_RESPMEM_PERSISTENT)
                                       : MHD_create_response_from_buffer(body->len, body->p, MHD_RESPMEM_MUST_COPY);
    if (body->oom) *status = 500;
    if (r) {
        MHD_add_response_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, "application/json");
        MHD_add_response_header(r, "X-Content-Type-Options", "nosniff");
        MHD_add_response_header(r, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    }
    return r;
}

static enum MHD_Result queue(struct MHD_Connection *c, int status, struct MHD_Response *r) {
    if (!r) return MHD_NO;
    enum MHD_Result ok = MHD_queue_response(c, (unsigned)status, r);
    MHD_destroy_response(r);
    return ok;
}

/* A JSON answer (body freed). */
static enum MHD_Result answer_json(struct MHD_Connection *c, int status, mx_buf *body) {
    mx_buf_printf(body, "\n");
    struct MHD_Response *r = json_response(body, &status);
    mx_buf_free(body);
    return queue(c, status, r);
}

static enum MHD_Result answer_error(struct MHD_Connection *c, const mx_serve_error *e, const char *allow) {
    mx_buf b = {0};
    int status = e->status;
    mx_serve_error_json(e, &b);
    struct MHD_Response *r = json_response(&b, &status);
    mx_buf_free(&b);
    if (r && allow) MHD_add_response_header(r, MHD_HTTP_HEADER_ALLOW, allow);
    if (r && status == 401) MHD_add_response_header(r, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer");
    return queue(c, status, r);
}

/* ---- uploads (POST /v1/jobs) ---- */

static void close_part(request *rq) {
    if (rq->part_fd >= 0) close(rq->part_fd);
    rq->part_fd = -1;
}

/* A file part's stored file in the upload folder: mesh.EXT or style_K.EXT (names of the server's own). */
static int open_part(request *rq, const char *key, const char *filename) {
    char *path;
    const char *kind;
    if (!strcmp(key, "mesh")) {
        if (rq->mesh_path[0]) return mx_serve_fail(&rq->err, 400, "bad_request", "more than one part \"mesh\"");
        if (!(kind = mx_serve_mesh_kind(filename, &rq->err))) return -1;
        path = rq->mesh_path;
        snprintf(path, sizeof rq->mesh_path, "%s/mesh.%s", rq->stage, kind);
        rq->mesh_zip = !strcmp(kind, "zip");
    } else {
        if (rq->nstyle == MATEX_MAX_STYLE_IMAGES)
            return mx_serve_fail(&rq->err, 400, "bad_request", "more than %d parts \"style_image\"", MATEX_MAX_STYLE_IMAGES);
        if (!(kind = mx_serve_image_kind(filename, &rq->err))) return -1;
        path = rq->style_paths[rq->nstyle];
        snprintf(path, sizeof rq->style_paths[0], "%s/style_%d.%s", rq->stage, rq->nstyle, kind);
        rq->nstyle++;
    }
    rq->part_fd = open(path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, 0600);
    if (rq->part_fd < 0) return mx_serve_fail(&rq->err, 503, "storage", "cannot store the upload: %s", strerror(errno));
    return 0;
}

static int write_all(int fd, const char *data, size_t n) {
    while (n) {
        ssize_t w = write(fd, data, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        data += w, n -= (size_t)w;
    }
    return 0;
}

/* One piece of a part (off 0: a new part begins). */
static int take_part(request *rq, const char *key, const char *filename, const char *data, uint64_t off, size_t size) {
    int is_options = !strcmp(key, "options");
    if (!is_options && strcmp(key, "mesh") && strcmp(key, "style_image"))
        return mx_serve_fail(&rq->err, 400, "bad_request", "unknown part \"%.64s\" (the parts are mesh, options and style_image)", key);
    if (off == 0) {
        close_part(rq);
        if (is_options && rq->have_options) return mx_serve_fail(&rq->err, 400, "bad_request", "more than one part \"options\"");
        rq->have_options |= is_options;
        if (!is_options && open_part(rq, key, filename)) return -1;
    }
    if (is_options) {
        if (rq->options.len + size > OPTIONS_PART_MAX)
            return mx_serve_fail(&rq->err, 413, "too_large", "part \"options\" is larger than %zu bytes", OPTIONS_PART_MAX);
        mx_buf_put(&rq->options, data, size);
        return rq->options.oom ? mx_serve_fail(&rq->err, 503, "internal", "out of memory") : 0;
    }
    if (write_all(rq->part_fd, data, size)) return mx_serve_fail(&rq->err, 503, "storage", "cannot store the upload: %s", strerror(errno));
    return 0;
}

static enum MHD_Result on_part(void *cls, enum MHD_ValueKind kind, const char *key, const char *filename,
                               const char *content_type, const char *transfer_encoding, const char *data, uint64_t off,
                               size_t size) {
    (void)kind, (void)content_type, (void)transfer_encoding;
    request *rq = cls;
    if (rq->failed) return MHD_NO;
    rq->failed = take_part(rq, key, filename, data, off, size) != 0;
    return rq->failed ? MHD_NO : MHD_YES;
}

/* The first call of a POST /v1/jobs: the body's type and announced size, the queue's room, the
 * upload folder. */
static int upload_begin(server *s, struct MHD_Connection *c, request *rq) {
    const char *type = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_TYPE);
    const char *length = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_CONTENT_LENGTH);
    rq->part_fd = -1;
    if (!type || strncasecmp(type, "multipart/form-data", 19))
        return mx_serve_fail(&rq->err, 415, "unsupported_media_type", "POST /v1/jobs takes multipart/form-data (parts mesh, options, style_image)");
    if (length && strtoull(length, NULL, 10) > s->cfg->max_upload)
        return mx_serve_fail(&rq->err, 413, "too_large", "the request is larger than the server takes (%llu bytes: --max-upload-mb)",
                             (unsigned long long)s->cfg->max_upload);
    if (mx_serve_jobs_stage(&s->q, rq->id, rq->stage, &rq->err)) return -1;
    rq->staged = 1;
    if (!(rq->pp = MHD_create_post_processor(c, POST_BUFFER, on_part, rq)))
        return mx_serve_fail(&rq->err, 415, "unsupported_media_type", "the multipart body has no boundary");
    return 0;
}

/* A zip mesh part: unpacked into the upload folder (serve_zip.h), the archive removed; mesh_path
 * becomes the mesh inside it. */
static int unpack_mesh(request *rq) {
    char zip[sizeof rq->mesh_path];
    snprintf(zip, sizeof zip, "%s", rq->mesh_path);
    if (mx_serve_zip_extract(zip, rq->stage, rq->mesh_path, sizeof rq->mesh_path, &rq->err)) return -1;
    unlink(zip);
    return 0;
}

/* The whole body came: the parts are checked as the CLI checks its inputs, then the job is queued. */
static int upload_end(server *s, request *rq) {
    char out[4200], options[4300];
    const char *styles[MATEX_MAX_STYLE_IMAGES];
    close_part(rq);
    if (!rq->mesh_path[0]) return mx_serve_fail(&rq->err, 400, "bad_request", "no part \"mesh\" (a mesh file)");
    if (!rq->have_options) return mx_serve_fail(&rq->err, 400, "bad_request", "no part \"options\" (a JSON object)");
    if (rq->mesh_zip && unpack_mesh(rq)) return -1;
    for (int i = 0; i < rq->nstyle; i++) styles[i] = rq->style_paths[i];
    mx_serve_jobs_path(&s->q, rq->id, "out", out);
    if (mx_serve_options_check(rq->options.p ? rq->options.p : "", rq->options.len, rq->mesh_path, out, styles, rq->nstyle, &rq->err) ||
        mx_serve_mesh_check(rq->mesh_path, rq->mesh_zip ? rq->stage : NULL, &rq->err))
        return -1;
    snprintf(options, sizeof options, "%s/options.json", rq->stage);
    mx_status st;
    if (mx_atomic_write(options, rq->options.p, rq->options.len, &st))
        return mx_serve_fail(&rq->err, 503, "storage", "cannot store the job's options");
    if (mx_serve_jobs_commit(&s->q, rq->id, &rq->err)) return -1;
    rq->committed = 1;
    return 0;
}

/* POST /v1/jobs across its calls: 202 {"id"} once the job is on disk. */
static enum MHD_Result submit(server *s, struct MHD_Connection *c, request *rq, const char *data, size_t *size) {
    if (*size) {
        rq->bytes += *size;
        if (!rq->failed && rq->bytes > s->cfg->max_upload)
            rq->failed = 1, mx_serve_fail(&rq->err, 413, "too_large", "the request is larger than the server takes (%llu bytes: --max-upload-mb)",
                                          (unsigned long long)s->cfg->max_upload);
        if (!rq->failed && MHD_post_process(rq->pp, data, *size) != MHD_YES && !rq->failed)
            rq->failed = 1, mx_serve_fail(&rq->err, 400, "bad_request", "the multipart body is malformed");
        *size = 0; /* all taken (after a failure: read and dropped, so the answer can be sent) */
        return MHD_YES;
    }
    if (!rq->failed && rq->pp) {
        MHD_destroy_post_processor(rq->pp); /* flushes the last part */
        rq->pp = NULL;
    }
    if (rq->failed || upload_end(s, rq)) return answer_error(c, &rq->err, NULL);
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"id\":\"%s\"}", rq->id);
    return answer_json(c, 202, &b);
}

/* ---- GET /v1/jobs/ID/events: text/event-stream ---- */

typedef struct event_stream {
    server *s;
    char id[MX_SERVE_ID_MAX + 1];
    off_t off;        /* of events.jsonl read so far (whole lines) */
    mx_buf pending;   /* the next bytes to send */
    size_t sent;      /* of pending */
    int ended;        /* the end event is in pending */
    double quiet_since;
} event_stream;

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* The whole lines of events.jsonl after es->off, each as an event `progress`; how many. */
static int take_progress_lines(event_stream *es) {
    char path[4200], chunk[16384];
    mx_serve_jobs_path(&es->s->q, es->id, "events.jsonl", path);
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW), lines = 0;
    ssize_t n = fd < 0 ? -1 : pread(fd, chunk, sizeof chunk, es->off);
    if (fd >= 0) close(fd);
    for (ssize_t at = 0; n > 0;) {
        const char *nl = memchr(chunk + at, '\n', (size_t)(n - at));
        if (!nl) break;
        mx_buf_printf(&es->pending, "event: progress\ndata: %.*s\n\n", (int)(nl - chunk - at), chunk + at);
        es->off += nl - chunk - at + 1;
        at = nl - chunk + 1;
        lines++;
    }
    return lines;
}

/* Fills es->pending: progress lines, else the end event once the job is finished (or the server
 * stops), else a keep-alive comment when the client has heard nothing for a while. Blocks (this
 * connection's own thread) until there is something. */
static void next_events(event_stream *es) {
    double keepalive = es->s->cfg->client_timeout > 4 ? es->s->cfg->client_timeout / 2.0 : 2.0;
    while (!es->pending.len) {
        mx_job_state st = mx_serve_jobs_state(&es->s->q, es->id); /* before the lines: none is missed */
        if (take_progress_lines(es)) break;
        if (st != MX_JOB_QUEUED && st != MX_JOB_RUNNING) {
            mx_buf_printf(&es->pending, "event: end\ndata: ");
            mx_serve_error e;
            if (mx_serve_jobs_describe(&es->s->q, es->id, &es->pending, &e)) mx_buf_printf(&es->pending, "{\"id\":\"%s\",\"state\":\"removed\"}", es->id);
            mx_buf_printf(&es->pending, "\n\n");
            es->ended = 1;
        } else if (es->s->stopping) {
            mx_buf_printf(&es->pending, "event: end\ndata: {\"id\":\"%s\",\"state\":\"%s\",\"server\":\"stopping\"}\n\n", es->id,
                          mx_serve_state_name(st));
            es->ended = 1;
        } else if (now_s() - es->quiet_since > keepalive) {
            mx_buf_printf(&es->pending, ": keep-alive\n\n");
        } else {
            usleep(10000); /* the end event comes at most 10 ms after the job ends */
        }
    }
    es->quiet_since = now_s();
}

static ssize_t events_read(void *cls, uint64_t pos, char *buf, size_t max) {
    (void)pos;
    event_stream *es = cls;
    if (es->sent == es->pending.len) {
        if (es->ended) return MHD_CONTENT_READER_END_OF_STREAM;
        mx_buf_free(&es->pending);
        es->sent = 0;
        next_events(es);
        if (es->pending.oom) return MHD_CONTENT_READER_END_WITH_ERROR;
    }
    size_t n = es->pending.len - es->sent < max ? es->pending.len - es->sent : max;
    memcpy(buf, es->pending.p + es->sent, n);
    es->sent += n;
    return (ssize_t)n;
}

static void events_free(void *cls) {
    event_stream *es = cls;
    mx_buf_free(&es->pending);
    free(es);
}

static enum MHD_Result events(server *s, struct MHD_Connection *c, const char *id) {
    mx_serve_error e;
    if (mx_serve_jobs_state(&s->q, id) == MX_JOB_NONE) return mx_serve_fail(&e, 404, "not_found", "no job %s", id), answer_error(c, &e, NULL);
    event_stream *es = calloc(1, sizeof *es);
    if (!es) return MHD_NO;
    es->s = s;
    snprintf(es->id, sizeof es->id, "%s", id);
    es->quiet_since = now_s();
    struct MHD_Response *r = MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 4096, events_read, es, events_free);
    if (!r) return events_free(es), MHD_NO;
    MHD_add_response_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, "text/event-stream");
    MHD_add_response_header(r, MHD_HTTP_HEADER_CACHE_CONTROL, "no-store");
    MHD_add_response_header(r, "X-Content-Type-Options", "nosniff");
    return queue(c, 200, r);
}

/* ---- the other routes ---- */

static const char *file_type(const char *name) {
    static const char *const types[][2] = {{".glb", "model/gltf-binary"}, {".png", "image/png"}, {".exr", "image/x-exr"},
                                           {".json", "application/json"}, {".obj", "text/plain"}, {".mtl", "text/plain"}};
    size_t n = strlen(name);
    for (size_t i = 0; i < sizeof types / sizeof types[0]; i++)
        if (n > strlen(types[i][0]) && !strcmp(name + n - strlen(types[i][0]), types[i][0])) return types[i][1];
    return "application/octet-stream";
}

static enum MHD_Result output_file(server *s, struct MHD_Connection *c, const mx_serve_route *r) {
    mx_serve_error e;
    int fd;
    uint64_t size;
    if (mx_serve_jobs_open_file(&s->q, r->id, r->name, &fd, &size, &e)) return answer_error(c, &e, NULL);
    struct MHD_Response *resp = MHD_create_response_from_fd64(size, fd);
    if (!resp) return close(fd), MHD_NO;
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, file_type(r->name));
    MHD_add_response_header(resp, "X-Content-Type-Options", "nosniff");
    return queue(c, 200, resp);
}

static enum MHD_Result route(server *s, struct MHD_Connection *c, const mx_serve_route *r) {
    mx_serve_error e;
    mx_buf b = {0};
    int status = 200;
    switch (r->kind) {
    case MX_ROUTE_HEALTH: mx_buf_printf(&b, "{\"ok\":true}"); break;
    case MX_ROUTE_INFO:
        if (!s->ready) return mx_serve_fail(&e, 503, "loading", "the model set is loading"), answer_error(c, &e, NULL);
        mx_buf_put(&b, s->info.p, s->info.len);
        break;
    case MX_ROUTE_JOBS_LIST: mx_serve_jobs_list(&s->q, &b); break;
    case MX_ROUTE_JOB_GET:
        if (mx_serve_jobs_describe(&s->q, r->id, &b, &e)) return mx_buf_free(&b), answer_error(c, &e, NULL);
        break;
    case MX_ROUTE_JOB_DELETE:
        if (mx_serve_jobs_delete(&s->q, r->id, &status, &b, &e)) return mx_buf_free(&b), answer_error(c, &e, NULL);
        break;
    case MX_ROUTE_JOB_EVENTS: return events(s, c, r->id);
    case MX_ROUTE_JOB_FILE: return output_file(s, c, r);
    case MX_ROUTE_BAD_METHOD:
        mx_serve_fail(&e, 405, "method_not_allowed", "this path takes %s", r->allow);
        return answer_error(c, &e, r->allow);
    default: /* MX_ROUTE_NOT_FOUND; MX_ROUTE_JOB_SUBMIT is handled by the caller */
        mx_serve_fail(&e, 404, "not_found", "no such route (the API is under /v1: docs/SERVE.md)");
        return answer_error(c, &e, NULL);
    }
    return answer_json(c, status, &b);
}

/* ---- the request handler ---- */

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url, const char *method,
                                  const char *version, const char *data, size_t *size, void **con_cls) {
    (void)version;
    server *s = cls;
    request *rq = *con_cls;
    if (rq) return submit(s, c, rq, data, size); /* only a POST /v1/jobs keeps its state */
    mx_serve_error e;
    const char *host = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_HOST);
    const char *origin = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Origin");
    const char *authorization = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
    if (mx_serve_auth_check(&s->auth, host, origin, authorization, &e)) return answer_error(c, &e, NULL);
    mx_serve_route r;
    mx_serve_route_parse(method, url, &r);
    if (r.kind != MX_ROUTE_JOB_SUBMIT) return route(s, c, &r);
    if (s->stopping) return mx_serve_fail(&e, 503, "stopping", "the server is stopping"), answer_error(c, &e, NULL);
    if (!(rq = calloc(1, sizeof *rq))) return MHD_NO;
    *con_cls = rq;
    if (!upload_begin(s, c, rq)) return MHD_YES;
    rq->failed = 1;
    return answer_error(c, &rq->err, NULL); /* at once: the body is not read (the connection closes after) */
}

/* After every request: an upload that did not become a job leaves nothing. */
static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls, enum MHD_RequestTerminationCode toe) {
    (void)c, (void)toe;
    server *s = cls;
    request *rq = *con_cls;
    if (!rq) return;
    if (rq->pp) MHD_destroy_post_processor(rq->pp);
    close_part(rq);
    if (rq->staged && !rq->committed) mx_serve_jobs_unstage(&s->q, rq->id);
    mx_buf_free(&rq->options);
    free(rq);
    *con_cls = NULL;
}

/* ---- the server's life ---- */

/* "networks": every network of weights/networks.h's list, with its config class and whether m
 * loaded it. */
static void info_networks(const matex_models *m, mx_buf *b) {
    mx_buf_printf(b, ",\"networks\":[");
    for (size_t i = 0; i < mx_net_kind_count; i++) {
        mx_buf_printf(b, "%s{\"name\":", i ? "," : "");
        mx_buf_json_str(b, mx_net_kinds[i].name);
        mx_buf_printf(b, ",\"class\":");
        mx_buf_json_str(b, mx_net_kinds[i].class_name);
        mx_buf_printf(b, ",\"loaded\":%s}", matex_models_has_network(m, mx_net_kinds[i].name) ? "true" : "false");
    }
    mx_buf_printf(b, "]");
}

/* GET /v1/info's answer, made once the model set is loaded; -1 when out of memory. */
static int make_info(server *s, const matex_models *m) {
    const mx_serve_config *cfg = s->cfg;
    char digest[32], *build = NULL;
    size_t build_len = 0;
    FILE *f = open_memstream(&build, &build_len);
    if (f) mx_build_report(f), fclose(f);
    mx_file_digest_hex(NULL, cfg->weights, digest);
    const char *base = strrchr(cfg->weights, '/') ? strrchr(cfg->weights, '/') + 1 : cfg->weights;
    mx_buf *b = &s->info;
    mx_buf_printf(b, "{\"version\":");
    mx_buf_json_str(b, matex_version());
    mx_buf_printf(b, ",\"device\":");
    mx_buf_json_str(b, cfg->models.o.device ? cfg->models.o.device : "cpu");
    mx_buf_printf(b, ",\"threads\":%d,\"precision\":\"%s\",\"weights\":", cfg->models.o.threads,
                  mx_precision_name(mx_precision_of_option(cfg->models.o.precision)));
    mx_buf_json_str(b, base);
    mx_buf_printf(b, ",\"weights_digest\":\"%s\",\"build\":", digest);
    mx_buf_json_str(b, build ? build : "");
    info_networks(m, b);
    mx_buf_printf(b, ",\"max_queued\":%d,\"max_upload\":%llu}", cfg->limits.max_queued, (unsigned long long)cfg->max_upload);
    free(build);
    if (b->oom) return -1;
    s->ready = 1;
    return 0;
}

static struct MHD_Daemon *start_daemon(server *s, struct sockaddr_storage *sa) {
    const mx_serve_config *cfg = s->cfg;
    int v6 = strchr(cfg->listen_addr, ':') != NULL;
    memset(sa, 0, sizeof *sa);
    if (v6) {
        struct sockaddr_in6 *a = (struct sockaddr_in6 *)sa;
        a->sin6_family = AF_INET6;
        a->sin6_port = htons((uint16_t)cfg->port);
        if (inet_pton(AF_INET6, cfg->listen_addr, &a->sin6_addr) != 1) return NULL;
    } else {
        struct sockaddr_in *a = (struct sockaddr_in *)sa;
        a->sin_family = AF_INET;
        a->sin_port = htons((uint16_t)cfg->port);
        if (inet_pton(AF_INET, cfg->listen_addr, &a->sin_addr) != 1) return NULL;
    }
    unsigned flags = MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_THREAD_PER_CONNECTION | MHD_USE_ITC | (v6 ? MHD_USE_IPv6 : 0);
    return MHD_start_daemon(flags, (uint16_t)cfg->port, NULL, NULL, on_request, s, MHD_OPTION_SOCK_ADDR, sa,
                            MHD_OPTION_CONNECTION_LIMIT, (unsigned)cfg->max_connections, MHD_OPTION_PER_IP_CONNECTION_LIMIT,
                            (unsigned)cfg->max_per_client, MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)cfg->client_timeout,
                            MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)256 << 10, MHD_OPTION_NOTIFY_COMPLETED, on_completed, s,
                            MHD_OPTION_END);
}

static void *worker_main(void *arg) {
    void **a = arg;
    mx_serve_jobs_work(a[0], a[1]);
    return NULL;
}

/* Listens (before the weights load, so that a taken port fails at once), loads the model set,
 * then serves until the flag is set: stops accepting, lets the worker end, closes. Requests that
 * come while the weights load are served; their jobs wait for the worker; /v1/info is a 503. */
static int serve_until_signal(server *s, volatile sig_atomic_t *stop) {
    struct sockaddr_storage sa;
    struct MHD_Daemon *d = start_daemon(s, &sa);
    if (!d) {
        fprintf(stderr, "matex serve: cannot listen on %s port %d: %s\n", s->cfg->listen_addr, s->cfg->port, strerror(errno));
        return 1;
    }
    const union MHD_DaemonInfo *info = MHD_get_daemon_info(d, MHD_DAEMON_INFO_BIND_PORT);
    s->auth.port = info ? info->port : s->cfg->port;
    matex_error err;
    matex_models *m = matex_models_open(s->cfg->weights, &s->cfg->models.o, &err);
    pthread_t worker;
    void *args[2] = {&s->q, m};
    int rc = 1;
    if (!m) fprintf(stderr, "matex serve: %s\n", err.message);
    else if (make_info(s, m)) fprintf(stderr, "matex serve: out of memory\n");
    else if (pthread_create(&worker, NULL, worker_main, args)) fprintf(stderr, "matex serve: cannot start the worker thread\n");
    else {
        int v6 = strchr(s->cfg->listen_addr, ':') != NULL;
        fprintf(stderr, "matex serve: listening on http://%s%s%s:%d/v1 (jobs in %s)\n", v6 ? "[" : "", s->cfg->listen_addr,
                v6 ? "]" : "", s->auth.port, s->q.dir);
        while (!*stop) usleep(50000);
        fprintf(stderr, "matex serve: stopping (%s)\n", s->cfg->finish_on_term ? "the running job finishes" : "a running job goes back to the queue");
        MHD_quiesce_daemon(d); /* no new connections */
        mx_serve_jobs_stop(&s->q, !s->cfg->finish_on_term);
        pthread_join(worker, NULL);
        rc = 0;
    }
    s->stopping = 1; /* the event streams end */
    MHD_stop_daemon(d);
    matex_models_close(m);
    if (!rc) fprintf(stderr, "matex serve: stopped\n");
    return rc;
}

int mx_serve_run(const mx_serve_config *cfg) {
    server s;
    memset(&s, 0, sizeof s);
    s.cfg = cfg;
    mx_status st;
    s.auth.loopback = mx_serve_addr_is_loopback(cfg->listen_addr);
    if (cfg->token_file && mx_serve_token_read(cfg->token_file, s.auth.token, sizeof s.auth.token, &st)) {
        fprintf(stderr, "matex serve: %s\n", st.msg);
        return 1;
    }
    if (!s.auth.loopback && !s.auth.token[0]) {
        fprintf(stderr, "matex serve: %s is not a loopback address: give --token-file F (clients send Authorization: Bearer TOKEN)\n",
                cfg->listen_addr);
        return 2;
    }
    if (mx_serve_jobs_open(&s.q, cfg->jobs_dir, &cfg->limits, &st)) {
        fprintf(stderr, "matex serve: %s\n", st.msg);
        return 1;
    }
    int rc = serve_until_signal(&s, mx_cli_signals_catch());
    mx_buf_free(&s.info);
    mx_serve_jobs_close(&s.q);
    return rc;
}
