/* The JSON writer (the reader is json.h) over mx_buf, for report.json: objects, arrays, members
 * with commas placed. Out-of-memory is sticky: mx_jw_text then returns NULL. */
#ifndef MX_JSONW_H
#define MX_JSONW_H

#include "buf.h"

typedef struct mx_jw {
    mx_buf b;
    int need_comma; /* a value was written at the current nesting level */
} mx_jw;

void mx_jw_init(mx_jw *w);
void mx_jw_free(mx_jw *w);
/* The text so far (NUL-terminated), NULL after an allocation failure. */
const char *mx_jw_text(const mx_jw *w);

void mx_jw_begin_obj(mx_jw *w, const char *key);
void mx_jw_end_obj(mx_jw *w);
void mx_jw_begin_arr(mx_jw *w, const char *key);
void mx_jw_end_arr(mx_jw *w);
/* Members (key may be NULL inside an array). */
void mx_jw_str(mx_jw *w, const char *key, const char *value);
void mx_jw_num(mx_jw *w, const char *key, double value);
void mx_jw_int(mx_jw *w, const char *key, long long value);
void mx_jw_bool(mx_jw *w, const char *key, int value);

#endif
