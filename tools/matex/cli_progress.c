#include "cli_progress.h"

#include <string.h>

#include "../../runtime/buf.h"

int mx_cli_progress_scan(int argc, char **argv) {
    int mode = MX_CLI_JSON_NONE;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--json") && mode == MX_CLI_JSON_NONE) mode = MX_CLI_JSON_SUMMARY;
        if (!strcmp(argv[i], "--progress") && i + 1 < argc && !strcmp(argv[i + 1], "json")) mode = MX_CLI_JSON_STREAM;
    }
    return mode;
}

int mx_cli_progress_parse(const char *val, int *json) {
    if (!strcmp(val, "text")) return *json = 0, 0;
    if (!strcmp(val, "json")) return *json = 1, 0;
    return -1;
}

/* One line, flushed: the reader sees each event when it happens, not when a buffer fills. */
static void put_line(FILE *f, mx_buf *b) {
    if (b->oom) fputs("{\"event\":\"result\",\"ok\":false,\"exit\":1,\"error\":\"out of memory\"}\n", f);
    else fprintf(f, "%s\n", b->p);
    fflush(f);
    mx_buf_free(b);
}

int mx_cli_progress_event(void *user, const mx_texture_progress *p) {
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"event\":\"%s\",\"stage\":", p->steps > 0 ? "step" : "stage");
    mx_buf_json_str(&b, p->stage);
    mx_buf_printf(&b, ",\"step\":%d,\"steps\":%d,\"views_done\":%d,\"views_total\":%d,\"coverage\":%.6f,\"seconds\":%.3f,"
                      "\"message\":",
                  p->step, p->steps, p->views_done, p->views_total, p->coverage, p->seconds);
    mx_buf_json_str(&b, p->message ? p->message : "");
    mx_buf_printf(&b, "}");
    put_line(user, &b);
    return 0;
}

int mx_cli_progress_api_event(void *user, const matex_progress *p) {
    mx_texture_progress q = {p->stage, p->step, p->steps, p->views_done, p->views_total, p->coverage, p->seconds, p->message};
    return mx_cli_progress_event(user, &q);
}

void mx_cli_progress_result_line(mx_buf *b, int exit_code, const char *error, const char *out,
                                 const mx_texture_result *res) {
    mx_buf_printf(b, "{\"event\":\"result\",\"ok\":%s,\"exit\":%d,", exit_code ? "false" : "true", exit_code);
    if (exit_code) {
        mx_buf_printf(b, "\"error\":");
        mx_buf_json_str(b, error);
    } else {
        mx_buf_printf(b, "\"out\":");
        mx_buf_json_str(b, out);
        mx_buf_printf(b, ",\"coverage\":%.6f,\"views\":%d,\"seconds\":%.3f", res->coverage, res->views, res->seconds);
    }
    mx_buf_printf(b, "}");
}

void mx_cli_progress_result(FILE *f, int exit_code, const char *error, const char *out, const mx_texture_result *res) {
    mx_buf b = {0};
    mx_cli_progress_result_line(&b, exit_code, error, out, res);
    put_line(f, &b);
}
