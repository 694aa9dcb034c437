/* Shared by the fuzz harnesses (tests/fuzz/fuzz_*.c). Each harness defines
 * LLVMFuzzerTestOneInput; it is linked either with libFuzzer (clang, `make fuzz`) or with
 * tests/fuzz/replay.c (any compiler, `make test`), which feeds it the seed corpus and the
 * regression inputs of tests/fuzz/regress/<harness>/. */
#ifndef MX_FUZZ_H
#define MX_FUZZ_H

#include <stddef.h>
#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Writes data to <per-process temporary folder>/name (removed at exit) and returns that
 * path (static storage, overwritten by the next call with the same name slot). The parsers
 * under test take paths, as the product does. Exits on a failure of the test machine. */
const char *fuzz_file(const char *name, const void *data, size_t len);

/* Separator of the parts of a multi-part input (e.g. OBJ text and MTL text). */
#define FUZZ_SEP "\n#@@\n"

/* Splits data at the first occurrence of sep (not included in either part); *first_len is
 * the length before it, *rest and *rest_len what follows (NULL/0 when sep is absent). */
void fuzz_split(const uint8_t *data, size_t size, const char *sep, size_t *first_len, const uint8_t **rest,
                size_t *rest_len);

/* Silences warnings from the library (a hostile input makes many); once per process. */
void fuzz_quiet(void);

#endif
