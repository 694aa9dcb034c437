/* Who may talk to `matex serve`, checked on every request before anything else (no HTTP library
 * here: the fuzzer links it). A web page the user visits must not reach a server on loopback: a
 * Host that is not a loopback name (DNS rebinding) and an Origin other than the server's own
 * (a cross-site request) are refused, and no CORS header is ever sent. With a token, every
 * request needs `Authorization: Bearer TOKEN`, compared in constant time. */
#ifndef MX_SERVE_AUTH_H
#define MX_SERVE_AUTH_H

#include <stddef.h>

#include "../../../runtime/status.h"
#include "serve_request.h"

#define MX_SERVE_TOKEN_MAX 256

typedef struct mx_serve_auth {
    int loopback;                        /* the server listens on a loopback address */
    int port;                            /* its port: the own Origin is http://LOOPBACK-NAME:port */
    char token[MX_SERVE_TOKEN_MAX + 1];  /* "" without a token */
} mx_serve_auth;

/* The token from a file: owned by this user, no permission for group or others (0600 or 0400),
 * one line of 16..MX_SERVE_TOKEN_MAX printable characters (a final newline is dropped). */
int mx_serve_token_read(const char *path, char *token, size_t cap, mx_status *st);
/* Whether ADDR (an IPv4 or IPv6 literal) is a loopback address. */
int mx_serve_addr_is_loopback(const char *addr);
/* The request's headers (NULL when absent) against the rules above: 0, or -1 with a 401 or 403 in e. */
int mx_serve_auth_check(const mx_serve_auth *a, const char *host, const char *origin, const char *authorization,
                        mx_serve_error *e);

#endif
