/* Checked number parsing (command lines, option tables): the whole text must be a decimal number
 * (no leading space, no trailing text, no overflow, finite). */
#ifndef MX_NUMPARSE_H
#define MX_NUMPARSE_H

#include <stdint.h>

/* 0 and *out set on success; -1 (out untouched) otherwise. */
int mx_parse_int(const char *s, long lo, long hi, int *out);
int mx_parse_float(const char *s, float *out);
int mx_parse_u64(const char *s, uint64_t *out); /* digits only: "-1" is refused */

#endif
