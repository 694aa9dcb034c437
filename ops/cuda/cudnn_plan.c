/* The host-side decisions of the cuDNN convolution path (cudnn_plan.h): no CUDA, no cuDNN. */
#include "cudnn_plan.h"

#include <stdio.h>
#include <string.h>

int mx_cudnn_decide(const char *env, int built, size_t loaded_version, const char *load_error, char *why,
                    size_t why_size) {
    const char *path = "convolution through im2col + cuBLASLt";
    if (!env || strcmp(env, "1") != 0) {
        snprintf(why, why_size, "%s (cuDNN is off until a GPU run proves it: MATEX_CUDNN=1 switches it on)", path);
        return 0;
    }
    if (!built) {
        snprintf(why, why_size, "%s: MATEX_CUDNN=1, but this build has no cuDNN (make CUDNN=1 with cudnn.h)", path);
        return 0;
    }
    if (loaded_version == 0) {
        snprintf(why, why_size, "%s: MATEX_CUDNN=1, but no cuDNN %d library could be loaded (%s)", path,
                 MX_CUDNN_MAJOR, load_error && *load_error ? load_error : "libcudnn.so.9 not found");
        return 0;
    }
    /* cuDNN 9 numbers versions major*10000 + minor*100 + patch (8.x: major*1000 + ...). */
    if (loaded_version / 10000 != MX_CUDNN_MAJOR) {
        snprintf(why, why_size, "%s: MATEX_CUDNN=1, but the cuDNN found is version %zu, not %d.x", path,
                 loaded_version, MX_CUDNN_MAJOR);
        return 0;
    }
    snprintf(why, why_size, "convolution through cuDNN %zu.%zu.%zu (MATEX_CUDNN=1)", loaded_version / 10000,
             loaded_version / 100 % 100, loaded_version % 100);
    return 1;
}

void mx_cudnn_key_init(mx_cudnn_conv_key *k, const char *gpu, int cc, int driver, long cudnn) {
    memset(k, 0, sizeof *k);
    if (gpu) strncpy(k->gpu, gpu, sizeof k->gpu - 1);
    k->cc = cc;
    k->driver = driver;
    k->cudnn = cudnn;
    k->bdtype = -1;
}

int mx_cudnn_key_equal(const mx_cudnn_conv_key *a, const mx_cudnn_conv_key *b) {
    return memcmp(a, b, sizeof *a) == 0; /* every byte defined by mx_cudnn_key_init */
}

/* FNV-1a over the key's bytes. */
uint64_t mx_cudnn_key_hash(const mx_cudnn_conv_key *k) {
    const unsigned char *p = (const unsigned char *)k;
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < sizeof *k; i++) h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

int mx_cudnn_align(uintptr_t p) {
    int a = 1;
    while (a < 16 && p % (uintptr_t)(2 * a) == 0) a *= 2;
    return a;
}
