/* Checked number parsing for every verb: the whole argument must be a decimal number (no
 * trailing text, no overflow, finite), within the option's range. */
#ifndef MX_CLI_ARGS_H
#define MX_CLI_ARGS_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "../../runtime/numparse.h"

/* The same, printing "matex VERB: OPT wants an integer in LO..HI, not 'S'" (or "a number",
 * "a non-negative integer") on stderr; return 0, or 2 (the usage-error exit code). */
int mx_arg_int(const char *verb, const char *opt, const char *s, long lo, long hi, int *out);
int mx_arg_float(const char *verb, const char *opt, const char *s, float *out);
int mx_arg_u64(const char *verb, const char *opt, const char *s, uint64_t *out);

/* The argument loop of a verb with one positional argument and valued options (run-net,
 * gen-weights): each option a name (and an alias or NULL), a type, where its value goes and,
 * for integers, its range. */
typedef enum { MX_OPT_STR, MX_OPT_INT, MX_OPT_U64, MX_OPT_FLOAT } mx_opt_type;
typedef struct mx_opt {
    const char *name, *alias;
    mx_opt_type type;
    void *out; /* const char **, int *, uint64_t * or float * */
    long lo, hi;
} mx_opt;

/* Parses argv[1..argc): -h/--help prints usage to stdout (returns 1: exit 0), a value of the
 * wrong form or an unknown or incomplete argument prints why (and usage) to stderr (returns 2),
 * the first word not starting with '-' goes to *positional; 0 when all went well. */
int mx_args_parse(const char *verb, int argc, char **argv, const mx_opt *opts, size_t n_opts, const char **positional,
                  void (*usage)(FILE *f));

#endif
