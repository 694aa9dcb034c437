/* Backend names and what this binary has compiled in. */
#include "backend.h"

#include <string.h>

static const char *const names[MX_BACKEND_KINDS] = {"cpu", "cpu-strict", "cuda"};

const char *mx_backend_name(mx_backend_kind kind) {
    return (unsigned)kind < MX_BACKEND_KINDS ? names[kind] : "?";
}

int mx_backend_parse(const char *name, mx_backend_kind *kind, mx_status *st) {
    for (int i = 0; i < MX_BACKEND_KINDS; i++)
        if (name && strcmp(name, names[i]) == 0) {
            *kind = (mx_backend_kind)i;
            return 0;
        }
    return mx_fail(st, MX_EUSAGE, "unknown device '%s' (cpu, cpu-strict or cuda)", name ? name : "");
}

int mx_backend_compiled(mx_backend_kind kind) {
#ifdef MX_WITH_CUDA
    return (unsigned)kind < MX_BACKEND_KINDS;
#else
    return kind == MX_BACKEND_CPU || kind == MX_BACKEND_CPU_STRICT;
#endif
}

const char *mx_backends_compiled(void) {
#ifdef MX_WITH_CUDA
    return "cpu cpu-strict cuda";
#else
    return "cpu cpu-strict";
#endif
}
