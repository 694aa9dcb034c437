#include "buf.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "json.h"

void mx_buf_put(mx_buf *b, const void *data, size_t n) {
    if (b->oom) return;
    if (b->len + n + 1 > b->cap) {
        size_t cap = b->cap ? b->cap : 256;
        while (cap < b->len + n + 1) cap *= 2;
        char *p = realloc(b->p, cap);
        if (!p) {
            b->oom = 1;
            return;
        }
        b->p = p;
        b->cap = cap;
    }
    if (n) memcpy(b->p + b->len, data, n);
    b->len += n;
    b->p[b->len] = 0;
}

void mx_buf_printf(mx_buf *b, const char *fmt, ...) {
    char tmp[512];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(tmp, sizeof tmp, fmt, ap);
    va_end(ap);
    if (n < 0) return;
    if ((size_t)n < sizeof tmp) {
        mx_buf_put(b, tmp, (size_t)n);
        return;
    }
    char *big = malloc((size_t)n + 1); /* longer than the stack buffer: format again */
    if (!big) {
        b->oom = 1;
        return;
    }
    va_start(ap, fmt);
    vsnprintf(big, (size_t)n + 1, fmt, ap);
    va_end(ap);
    mx_buf_put(b, big, (size_t)n);
    free(big);
}

void mx_buf_json_str(mx_buf *b, const char *s) {
    mx_buf_put(b, "\"", 1);
    const unsigned char *c = (const unsigned char *)s;
    for (size_t left = strlen(s); left > 0;) {
        uint32_t cp;
        size_t k = mx_utf8_decode(c, left, &cp);
        if (*c == '"' || *c == '\\')
            mx_buf_printf(b, "\\%c", *c);
        else if (*c < 0x20)
            mx_buf_printf(b, "\\u%04x", *c);
        else if (cp == 0xFFFD && k == 1)
            mx_buf_printf(b, "\\ufffd"); /* a byte that is not UTF-8: JSON text must be */
        else
            mx_buf_put(b, c, k);
        c += k;
        left -= k;
    }
    mx_buf_put(b, "\"", 1);
}

void mx_buf_free(mx_buf *b) {
    free(b->p);
    memset(b, 0, sizeof *b);
}
