/* `matex serve` in the builds without libmicrohttpd and libcurl (matex-core, the CUDA build). */
#include <stdio.h>

#include "serve.h"
#include "serve_client.h"

int mx_serve_run(const mx_serve_config *cfg) {
    (void)cfg;
    fprintf(stderr, "matex serve: not in this build (it needs libmicrohttpd: build matex with `make`)\n");
    return 2;
}

int mx_serve_client_open(mx_serve_client *c, const char *url, const char *token_file, mx_status *st) {
    (void)c, (void)url, (void)token_file;
    return mx_fail(st, MX_EUSAGE, "--server is not in this build (it needs libcurl: build matex with `make`)");
}

/* Never reached (mx_serve_client_open refuses); here so that cmd_batch.c links. */
int mx_serve_client_run(const mx_serve_client *c, const char *manifest, const mx_batch_job *j,
                        const char *const *defaults, int ndefaults, volatile sig_atomic_t *stop, double *coverage,
                        char *error, size_t cap) {
    (void)c, (void)manifest, (void)j, (void)defaults, (void)ndefaults, (void)stop, (void)coverage;
    snprintf(error, cap, "--server is not in this build");
    return -1;
}
