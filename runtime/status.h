/* Error reporting: every fallible function takes an mx_status* and returns 0 on
 * success, -1 on failure with a message in st->msg. The library never aborts. */
#ifndef MX_STATUS_H
#define MX_STATUS_H

enum { MX_OK = 0, MX_EINPUT = 1, MX_EUSAGE = 2, MX_EIO = 3, MX_ENOMEM = 4, MX_EINTERNAL = 5,
       MX_ECANCEL = 6 /* stopped by the caller's cancel flag (a signal): "interrupted" */ };

typedef struct mx_status {
    int code;       /* MX_OK or one of the MX_E* codes */
    char msg[1024]; /* one line naming the file/tensor and the problem */
} mx_status;

/* Records an error (printf-style) and returns -1, so callers can write
 * `return mx_fail(st, MX_EINPUT, "%s: truncated header", path);`. st may be NULL. */
int mx_fail(mx_status *st, int code, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* Prefixes an existing message with context ("loading unet: ..."), keeps the code. */
int mx_fail_prefix(mx_status *st, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

void mx_status_clear(mx_status *st);

#endif
