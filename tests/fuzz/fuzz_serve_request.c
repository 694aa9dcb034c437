/* The request decoding and validation of `matex serve` (tools/matex/serve/serve_request.c and
 * serve_auth.c, serve_zip.c; no HTTP library): the input is up to four parts split at FUZZ_SEP,
 *   "METHOD URL"  -> the route (an id or file name it yields must pass the alphabet checks),
 *   the options  -> the job's options check (the batch manifest's key table),
 *   "HOST\nORIGIN\nAUTHORIZATION\nFILENAME" -> the Host/Origin/token rules and the part kinds,
 *   a zip archive -> the checks of a zip mesh part (serve_zip.h), then every entry inflated and
 *   checked (written nowhere): an archive that passes has exactly one mesh and only names that
 *   cannot leave the job folder;
 * every refusal's error body must read back as JSON with its code and message. */
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"
#include "../../tools/matex/serve/serve_auth.h"
#include "../../tools/matex/serve/serve_request.h"
#include "../../tools/matex/serve/serve_zip.h"
#include "fuzz.h"

/* The error body of e must be the JSON {"error": {"code": C, "message": M}} (M as text: a byte
 * of the client's that is not UTF-8 reads back as U+FFFD, so only its presence is checked). */
static void check_error_body(const mx_serve_error *e) {
    mx_buf b = {0};
    mx_status st;
    mx_serve_error_json(e, &b);
    mx_json *j = b.oom ? NULL : mx_json_parse(b.p, b.len, "error", &st);
    const mx_json *err = j ? mx_json_get(j, "error") : NULL;
    if (!b.oom && (!err || strcmp(mx_json_get_str(err, "code", ""), e->code) || !mx_json_get_str(err, "message", NULL)))
        abort();
    mx_json_free(j);
    mx_buf_free(&b);
}

/* A copy of len bytes as a C string (NULs end it early, as in a header). */
static char *text_of(const uint8_t *p, size_t len) {
    char *s = malloc(len + 1);
    if (!s) abort();
    memcpy(s, p, len);
    s[len] = 0;
    return s;
}

static void fuzz_route(const char *line) {
    char method[16] = "GET";
    const char *sp = strchr(line, ' ');
    if (sp && (size_t)(sp - line) < sizeof method) memcpy(method, line, (size_t)(sp - line)), method[sp - line] = 0;
    mx_serve_route r;
    mx_serve_route_parse(method, sp ? sp + 1 : line, &r);
    if ((r.id[0] && !mx_serve_id_valid(r.id)) || (r.name[0] && !mx_serve_name_valid(r.name))) abort();
    if (r.kind == MX_ROUTE_JOB_FILE && (strchr(r.name, '/') || r.name[0] == '.')) abort();
}

static void fuzz_headers(char *text) {
    char *field[4] = {text, NULL, NULL, NULL};
    for (int i = 1; i < 4 && field[i - 1]; i++) {
        char *nl = strchr(field[i - 1], '\n');
        if (nl) *nl = 0, field[i] = nl + 1;
    }
    mx_serve_auth a = {1, 8421, "0123456789abcdef"};
    mx_serve_error e;
    for (int loopback = 0; loopback < 2; loopback++) {
        a.loopback = loopback;
        if (mx_serve_auth_check(&a, field[0], field[1], field[2], &e)) check_error_body(&e);
    }
    const char *name = field[3] ? field[3] : "";
    if (!mx_serve_mesh_kind(name, &e)) check_error_body(&e);
    if (!mx_serve_image_kind(name, &e)) check_error_body(&e);
}

/* A name the checks let through must be relative with no '.' or '..' component and no backslash. */
static void check_safe_name(const char *name) {
    if (name[0] == '/' || strchr(name, '\\') || strstr(name, "//")) abort();
    for (const char *c = name; *c; c = strchr(c, '/') ? strchr(c, '/') + 1 : c + strlen(c)) {
        size_t n = strcspn(c, "/");
        if ((n == 1 && c[0] == '.') || (n == 2 && c[0] == '.' && c[1] == '.')) abort();
    }
}

static void fuzz_zip(const uint8_t *data, size_t len) {
    mx_serve_zip z;
    mx_serve_error e;
    if (mx_serve_zip_check(data, len, &z, &e)) {
        check_error_body(&e);
        mx_serve_zip_free(&z);
        return;
    }
    if (z.mesh >= z.n) abort();
    for (size_t i = 0; i < z.n; i++) {
        const mx_zip_entry *en = &z.entries[i];
        if (en->name_len >= 9 && !memcmp(en->name, "__MACOSX/", 9)) continue; /* skipped, never written */
        char name[MX_SERVE_ZIP_NAME_MAX + 1];
        if (en->name_len > MX_SERVE_ZIP_NAME_MAX || en->is_link) abort();
        memcpy(name, en->name, en->name_len);
        name[en->name_len] = 0;
        if (!mx_serve_zip_name_valid(name)) abort();
        check_safe_name(name);
        if (mx_serve_zip_unpack(&z, i, -1, &e)) check_error_body(&e);
    }
    mx_serve_zip_free(&z);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    fuzz_quiet();
    size_t first_len, rest_len, opt_len = 0, hdr_len = 0;
    const uint8_t *rest, *opt = NULL, *hdr = NULL;
    fuzz_split(data, size, FUZZ_SEP, &first_len, &rest, &rest_len);
    if (rest) fuzz_split(rest, rest_len, FUZZ_SEP, &opt_len, &hdr, &hdr_len), opt = rest;
    char *line = text_of(data, first_len);
    fuzz_route(line);
    free(line);
    if (opt) {
        mx_serve_error e;
        if (mx_serve_options_check((const char *)opt, opt_len, "/nonexistent/mesh.obj", "/nonexistent/out", NULL, 0, &e))
            check_error_body(&e);
    }
    if (hdr) {
        size_t zip_len = 0;
        const uint8_t *zip = NULL;
        fuzz_split(hdr, hdr_len, FUZZ_SEP, &hdr_len, &zip, &zip_len);
        if (zip) fuzz_zip(zip, zip_len);
        char *h = text_of(hdr, hdr_len);
        fuzz_headers(h);
        free(h);
    }
    return 0;
}
