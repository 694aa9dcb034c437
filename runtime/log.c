#include "log.h"

#include <stdarg.h>
#include <stdio.h>
#include <time.h>

static mx_log_level g_level = MX_LOG_INFO;

void mx_log_set_level(mx_log_level level) { g_level = level; }

void mx_log(mx_log_level level, const char *fmt, ...) {
    if (level > g_level) return;
    static const char *tag[] = {"error", "warning", "info", "debug"};
    fprintf(stderr, "matex: %s: ", tag[level]);
    va_list ap;
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
}

double mx_now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
