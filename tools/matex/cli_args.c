#include "cli_args.h"

#include <stdio.h>
#include <string.h>

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

static const mx_opt *find_opt(const mx_opt *opts, size_t n, const char *a) {
    for (size_t i = 0; i < n; i++)
        if (!strcmp(a, opts[i].name) || (opts[i].alias && !strcmp(a, opts[i].alias))) return &opts[i];
    return NULL;
}

/* The value v of option o into o->out: 0, or 2 with the message printed. */
static int set_opt(const char *verb, const mx_opt *o, const char *v) {
    switch (o->type) {
    case MX_OPT_INT: return mx_arg_int(verb, o->name, v, o->lo, o->hi, o->out);
    case MX_OPT_U64: return mx_arg_u64(verb, o->name, v, o->out);
    case MX_OPT_FLOAT: return mx_arg_float(verb, o->name, v, o->out);
    case MX_OPT_STR: *(const char **)o->out = v; return 0;
    }
    return 2;
}

int mx_args_parse(const char *verb, int argc, char **argv, const mx_opt *opts, size_t n_opts, const char **positional,
                  void (*usage)(FILE *f)) {
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            usage(stdout);
            return 1;
        }
        const mx_opt *o = find_opt(opts, n_opts, a);
        if (o && i + 1 < argc) {
            if (set_opt(verb, o, argv[++i])) return 2;
        } else if (!o && a[0] != '-' && !*positional) {
            *positional = a;
        } else {
            fprintf(stderr, "matex %s: unknown or incomplete argument '%s'\n", verb, a);
            usage(stderr);
            return 2;
        }
    }
    return 0;
}
