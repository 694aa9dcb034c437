/* `matex serve`: the model set loaded once, texturing jobs over HTTP (docs/SERVE.md). The verb
 * (tools/matex/cmd_serve.c) parses the command line into an mx_serve_config; mx_serve_run is the
 * server (serve_http.c: libmicrohttpd), or, in the builds without the HTTP library (matex-core,
 * the CUDA build), serve_none.c's refusal. The same holds for the client side of
 * `matex batch --server` (serve_client.c: libcurl). */
#ifndef MX_SERVE_H
#define MX_SERVE_H

#include <stdint.h>

#include "../cli_texture_opts.h"
#include "serve_jobs.h"

typedef struct mx_serve_config {
    const char *weights;
    mx_cli_texture models;  /* the model set's options (--device, --threads, --precision) */
    char listen_addr[64];   /* an IPv4 or IPv6 literal */
    int port;               /* 0: any free port (printed) */
    const char *jobs_dir;
    const char *token_file; /* NULL: no token (refused unless on loopback) */
    mx_serve_limits limits;
    uint64_t max_upload;    /* bytes of one request's body */
    int max_connections, max_per_client;
    int client_timeout;     /* seconds a client may stay silent */
    int finish_on_term;     /* SIGTERM: finish the running job (1) or stop it and queue it again (0) */
} mx_serve_config;

/* Runs the server until SIGINT/SIGTERM; the verb's exit code. */
int mx_serve_run(const mx_serve_config *cfg);

#endif
