#include "cli_args.h"

#include <stdio.h>

int mx_arg_int(const char *verb, const char *opt, const char *s, long lo, long hi, int *out) {
    if (!mx_parse_int(s, lo, hi, out)) return 0;
    fprintf(stderr, "matex %s: %s wants an integer in %ld..%ld, not '%s'\n", verb, opt, lo, hi, s);
    return 2;
}

int mx_arg_float(const char *verb, const char *opt, const char *s, float *out) {
    if (!mx_parse_float(s, out)) return 0;
    fprintf(stderr, "matex %s: %s wants a finite number, not '%s'\n", verb, opt, s);
    return 2;
}

int mx_arg_u64(const char *verb, const char *opt, const char *s, uint64_t *out) {
    if (!mx_parse_u64(s, out)) return 0;
    fprintf(stderr, "matex %s: %s wants a non-negative integer, not '%s'\n", verb, opt, s);
    return 2;
}
