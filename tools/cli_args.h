/* Checked number parsing for every verb: the whole argument must be a decimal number (no
 * trailing text, no overflow, finite), within the option's range. */
#ifndef MX_CLI_ARGS_H
#define MX_CLI_ARGS_H

#include <stdint.h>

#include "../runtime/numparse.h"

/* The same, printing "matex VERB: OPT wants an integer in LO..HI, not 'S'" (or "a number",
 * "a non-negative integer") on stderr; return 0, or 2 (the usage-error exit code). */
int mx_arg_int(const char *verb, const char *opt, const char *s, long lo, long hi, int *out);
int mx_arg_float(const char *verb, const char *opt, const char *s, float *out);
int mx_arg_u64(const char *verb, const char *opt, const char *s, uint64_t *out);

#endif
