#include "jsonw.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void mx_jw_init(mx_jw *w) { memset(w, 0, sizeof *w); }

void mx_jw_free(mx_jw *w) {
    free(w->s);
    memset(w, 0, sizeof *w);
}

const char *mx_jw_text(const mx_jw *w) { return w->oom ? NULL : (w->s ? w->s : ""); }

static void append(mx_jw *w, const char *p, size_t n) {
    if (w->oom) return;
    if (w->len + n + 1 > w->cap) {
        size_t cap = w->cap ? w->cap : 256;
        while (cap < w->len + n + 1) cap *= 2;
        char *s = realloc(w->s, cap);
        if (!s) {
            w->oom = 1;
            return;
        }
        w->s = s;
        w->cap = cap;
    }
    memcpy(w->s + w->len, p, n);
    w->len += n;
    w->s[w->len] = 0;
}

static void appendf(mx_jw *w, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void appendf(mx_jw *w, const char *fmt, ...) {
    char buf[128];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    if (n > 0) append(w, buf, (size_t)n < sizeof buf ? (size_t)n : sizeof buf - 1);
}

static void append_string(mx_jw *w, const char *s) {
    append(w, "\"", 1);
    for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
        if (*p == '"' || *p == '\\') {
            char esc[2] = {'\\', (char)*p};
            append(w, esc, 2);
        } else if (*p < 0x20) {
            appendf(w, "\\u%04x", *p);
        } else {
            append(w, (const char *)p, 1);
        }
    }
    append(w, "\"", 1);
}

/* Comma and key before a value. */
static void start_value(mx_jw *w, const char *key) {
    if (w->need_comma) append(w, ",", 1);
    if (key) {
        append_string(w, key);
        append(w, ":", 1);
    }
    w->need_comma = 1;
}

void mx_jw_begin_obj(mx_jw *w, const char *key) {
    start_value(w, key);
    append(w, "{", 1);
    w->need_comma = 0;
}

void mx_jw_end_obj(mx_jw *w) {
    append(w, "}", 1);
    w->need_comma = 1;
}

void mx_jw_begin_arr(mx_jw *w, const char *key) {
    start_value(w, key);
    append(w, "[", 1);
    w->need_comma = 0;
}

void mx_jw_end_arr(mx_jw *w) {
    append(w, "]", 1);
    w->need_comma = 1;
}

void mx_jw_str(mx_jw *w, const char *key, const char *value) {
    start_value(w, key);
    append_string(w, value ? value : "");
}

void mx_jw_num(mx_jw *w, const char *key, double value) {
    start_value(w, key);
    if (isfinite(value))
        appendf(w, "%.9g", value);
    else
        append(w, "null", 4);
}

void mx_jw_int(mx_jw *w, const char *key, long long value) {
    start_value(w, key);
    appendf(w, "%lld", value);
}

void mx_jw_bool(mx_jw *w, const char *key, int value) {
    start_value(w, key);
    append(w, value ? "true" : "false", value ? 4 : 5);
}
