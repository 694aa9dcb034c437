/* Small helpers shared by the test programs: checks that count failures, random inputs,
 * relative L2 error, and where the test data is. */
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
/* Test data, named by its path REL under the data root ("golden/unet_tiny/config.json",
 * "assets/spot/spot_triangulated.obj"): tests/data/<REL> when the repository ships it, otherwise
 * $MATEX_TESTDATA/REL (default ../shared), where the larger cases live (mini, SD1.5-size, the
 * full mesh library). Tests run from the repository root (tests/data/README.md). */
#define MX_PRINTF(f, a) __attribute__((format(printf, f, a)))
/* Writes the path of REL to buf; 0 when it exists, -1 when not (buf then names the outside copy). */
int mx_test_path(char *buf, size_t cap, const char *rel);
/* 1 with the path of REL (printf-style) in buf when it exists; otherwise prints "SKIP REL: ..."
 * and returns 0. The skip is counted, and is a failure when CI=true (CI always has the outside
 * data). */
int mx_test_need(char *buf, size_t cap, const char *rel_fmt, ...) MX_PRINTF(3, 4);
/* mx_test_need without the path. */
int mx_test_have(const char *rel);
/* The 15 shared meshes, paths under assets/ (mx_test_need "assets/%s"); MX_TEST_NASSETS of them. */
#define MX_TEST_NASSETS 15
extern const char *const mx_test_assets[MX_TEST_NASSETS];
/* Prints the summary (with the number of skipped cases) and returns the exit code (0 when no
 * failures). */
int mx_test_finish(const char *name);

#endif
