/* Logging to stderr. The level is the only process-wide setting (like stderr itself):
 * set once by the command line (--quiet). */
#ifndef MX_LOG_H
#define MX_LOG_H

typedef enum { MX_LOG_ERROR = 0, MX_LOG_WARN = 1, MX_LOG_INFO = 2, MX_LOG_DEBUG = 3 } mx_log_level;

void mx_log_set_level(mx_log_level level);
void mx_log(mx_log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

#define mx_error(...) mx_log(MX_LOG_ERROR, __VA_ARGS__)
#define mx_warn(...) mx_log(MX_LOG_WARN, __VA_ARGS__)
#define mx_info(...) mx_log(MX_LOG_INFO, __VA_ARGS__)
#define mx_debug(...) mx_log(MX_LOG_DEBUG, __VA_ARGS__)

/* Monotonic wall clock in seconds, for progress lines and reports. */
double mx_now(void);

#endif
