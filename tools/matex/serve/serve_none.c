/* `matex serve` in the builds without libmicrohttpd and libcurl (matex-core, matex-lite). */
#include <stdio.h>

#include "serve.h"

int mx_serve_run(const mx_serve_config *cfg) {
    (void)cfg;
    fprintf(stderr, "matex serve: not in this build (it needs libmicrohttpd: build matex with `make`)\n");
    return 2;
}
