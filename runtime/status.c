#include "status.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

int mx_fail(mx_status *st, int code, const char *fmt, ...) {
    if (!st) return -1;
    st->code = code;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(st->msg, sizeof st->msg, fmt, ap);
    va_end(ap);
    return -1;
}

int mx_fail_prefix(mx_status *st, const char *fmt, ...) {
    if (!st) return -1;
    char prefix[512], old[sizeof st->msg];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(prefix, sizeof prefix, fmt, ap);
    va_end(ap);
    memcpy(old, st->msg, sizeof old);
    snprintf(st->msg, sizeof st->msg, "%.500s: %.500s", prefix, old);
    if (st->code == MX_OK) st->code = MX_EINTERNAL;
    return -1;
}

void mx_status_clear(mx_status *st) {
    if (!st) return;
    st->code = MX_OK;
    st->msg[0] = 0;
}
