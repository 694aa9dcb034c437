#include "jsonw.h"

#include <math.h>
#include <string.h>

void mx_jw_init(mx_jw *w) { memset(w, 0, sizeof *w); }

void mx_jw_free(mx_jw *w) {
    mx_buf_free(&w->b);
    memset(w, 0, sizeof *w);
}

const char *mx_jw_text(const mx_jw *w) { return w->b.oom ? NULL : (w->b.p ? w->b.p : ""); }

/* Comma and key before a value. */
static void start_value(mx_jw *w, const char *key) {
    if (w->need_comma) mx_buf_put(&w->b, ",", 1);
    if (key) {
        mx_buf_json_str(&w->b, key);
        mx_buf_put(&w->b, ":", 1);
    }
    w->need_comma = 1;
}

static void open_nested(mx_jw *w, const char *key, const char *bracket) {
    start_value(w, key);
    mx_buf_put(&w->b, bracket, 1);
    w->need_comma = 0;
}

static void close_nested(mx_jw *w, const char *bracket) {
    mx_buf_put(&w->b, bracket, 1);
    w->need_comma = 1;
}

void mx_jw_begin_obj(mx_jw *w, const char *key) { open_nested(w, key, "{"); }
void mx_jw_end_obj(mx_jw *w) { close_nested(w, "}"); }
void mx_jw_begin_arr(mx_jw *w, const char *key) { open_nested(w, key, "["); }
void mx_jw_end_arr(mx_jw *w) { close_nested(w, "]"); }

void mx_jw_str(mx_jw *w, const char *key, const char *value) {
    start_value(w, key);
    mx_buf_json_str(&w->b, value ? value : "");
}

void mx_jw_num(mx_jw *w, const char *key, double value) {
    start_value(w, key);
    if (isfinite(value))
        mx_buf_printf(&w->b, "%.9g", value);
    else
        mx_buf_put(&w->b, "null", 4);
}

void mx_jw_int(mx_jw *w, const char *key, long long value) {
    start_value(w, key);
    mx_buf_printf(&w->b, "%lld", value);
}

void mx_jw_bool(mx_jw *w, const char *key, int value) {
    start_value(w, key);
    mx_buf_put(&w->b, value ? "true" : "false", value ? 4 : 5);
}
