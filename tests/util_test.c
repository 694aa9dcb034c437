#include "util_test.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

int mx_test_failures = 0;

double mx_rel_l2(const float *got, const float *want, size_t n) {
    double num = 0, den = 0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)got[i] - (double)want[i];
        num += d * d;
        den += (double)want[i] * (double)want[i];
    }
    if (den == 0) return sqrt(num);
    return sqrt(num / den);
}

int mx_check_close(const char *name, const float *got, const float *want, size_t n, double bound) {
    /* MX_TEST_MIN_BOUND raises every bound (make test-cuda: half-precision GPU arithmetic) */
    const char *min_bound = getenv("MX_TEST_MIN_BOUND");
    if (min_bound && atof(min_bound) > bound) bound = atof(min_bound);
    double e = mx_rel_l2(got, want, n);
    int ok = e <= bound; /* false for NaN */
    printf("%-48s rel_l2=%.3e (bound %.0e) %s\n", name, e, bound, ok ? "ok" : "FAIL");
    if (!ok) mx_test_failures++;
    return ok;
}

void mx_fill_random(float *x, size_t n, uint64_t seed, float lo, float hi) {
    uint64_t s = seed * 0x9E3779B97F4A7C15ull + 1;
    for (size_t i = 0; i < n; i++) {
        uint64_t z = (s += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        z ^= z >> 31;
        x[i] = lo + (hi - lo) * (float)((double)(z >> 40) / 16777216.0);
    }
}

const char *mx_shared_dir(void) {
    const char *d = getenv("MATEX_SHARED");
    return d && *d ? d : "../shared";
}

int mx_test_finish(const char *name) {
    if (mx_test_failures) {
        printf("%s: %d check(s) failed\n", name, mx_test_failures);
        return 1;
    }
    printf("%s: all checks passed\n", name);
    return 0;
}
