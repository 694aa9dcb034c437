/* A growing byte buffer for building files in memory (JSON texts, GLB chunks, reports).
 * Allocation failure is sticky: the buffer records it in `oom` and ignores later appends, so
 * callers check once at the end. The bytes are always followed by a NUL (handy for text). */
#ifndef MX_BUF_H
#define MX_BUF_H

#include <stddef.h>

typedef struct mx_buf {
    char *p; /* NULL until the first append */
    size_t len, cap;
    int oom;
} mx_buf;

void mx_buf_put(mx_buf *b, const void *data, size_t n);
void mx_buf_printf(mx_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* A JSON string literal: quotes, backslash and control characters escaped, and each byte that
 * is not part of valid UTF-8 written as \ufffd (JSON text is UTF-8). */
void mx_buf_json_str(mx_buf *b, const char *s);
void mx_buf_free(mx_buf *b);

#endif
