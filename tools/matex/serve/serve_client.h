/* The client side of `matex batch --server URL [--token-file F]` (libcurl): a manifest's job is
 * sent to a running `matex serve` (POST /v1/jobs: the mesh, or a zip of it with its side files
 * (serve_upload.h), the job's options as the manifest line and the batch's defaults give them,
 * the style images), followed until it ends, and its
 * files are written into the job's output folder exactly as a local run publishes it (a staging
 * folder moved in place with its marker: pipeline/texture/outdir.h), so that a rerun resumes
 * the same way; then the job is removed from the server. In the builds without libcurl,
 * serve_none.c's mx_serve_client_open refuses. */
#ifndef MX_SERVE_CLIENT_H
#define MX_SERVE_CLIENT_H

#include <signal.h>
#include <stddef.h>

#include "../../../runtime/status.h"
#include "../cli_batch_manifest.h"

typedef struct mx_serve_client {
    char url[1024];    /* the server's base URL, without a final '/' */
    char token[300];   /* "" without a token */
} mx_serve_client;

int mx_serve_client_open(mx_serve_client *c, const char *url, const char *token_file, mx_status *st);
/* Runs job j of the manifest (its line re-read there for the options; defaults as for
 * mx_batch_manifest_read) on the server: 0 done (coverage set), 1 interrupted by *stop (the job is
 * cancelled on the server), -1 failed (why in error). */
int mx_serve_client_run(const mx_serve_client *c, const char *manifest, const mx_batch_job *j,
                        const char *const *defaults, int ndefaults, volatile sig_atomic_t *stop, double *coverage,
                        char *error, size_t cap);

#endif
