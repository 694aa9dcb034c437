/* Small helpers shared by the test programs: checks that count failures, random inputs,
 * relative L2 error, and the path of ../shared. */
#ifndef MX_UTIL_TEST_H
#define MX_UTIL_TEST_H

#include <stddef.h>
#include <stdint.h>

/* Exit code of a test that did not run (tests/run.sh reports it as skipped, not passed). */
#define MX_TEST_SKIP 77

extern int mx_test_failures;

#define CHECK(cond)                                                                               \
    do {                                                                                          \
        if (!(cond)) {                                                                            \
            mx_test_failures++;                                                                   \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);              \
        }                                                                                         \
    } while (0)

/* Reports "name: rel_l2=E (bound B)" and counts a failure when E > bound or E is NaN. */
int mx_check_close(const char *name, const float *got, const float *want, size_t n, double bound);
double mx_rel_l2(const float *got, const float *want, size_t n);
/* Deterministic uniform values in [lo, hi) from a seed (splitmix64). */
void mx_fill_random(float *x, size_t n, uint64_t seed, float lo, float hi);
/* Path of the shared folder: $MATEX_SHARED or ../shared. */
const char *mx_shared_dir(void);
/* Prints the summary and returns the exit code (0 when no failures). */
int mx_test_finish(const char *name);

#endif
