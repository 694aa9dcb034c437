#include "util_test.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

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

static int mx_test_skips = 0;

static const char *outside_data_dir(void) {
    const char *d = getenv("MATEX_TESTDATA");
    return d && *d ? d : "../shared";
}

int mx_test_path(char *buf, size_t cap, const char *rel) {
    struct stat sb;
    snprintf(buf, cap, "tests/data/%s", rel);
    if (stat(buf, &sb) == 0) return 0;
    snprintf(buf, cap, "%s/%s", outside_data_dir(), rel);
    return stat(buf, &sb) == 0 ? 0 : -1;
}

int mx_test_need(char *buf, size_t cap, const char *rel_fmt, ...) {
    char rel[1024];
    va_list ap;
    va_start(ap, rel_fmt);
    vsnprintf(rel, sizeof rel, rel_fmt, ap);
    va_end(ap);
    if (mx_test_path(buf, cap, rel) == 0) return 1;
    const char *ci = getenv("CI");
    if (ci && strcmp(ci, "true") == 0) {
        printf("FAIL %s: test data missing (not in tests/data nor %s; CI must have it)\n", rel, outside_data_dir());
        mx_test_failures++;
    } else {
        printf("SKIP %s: not in tests/data nor %s (set MATEX_TESTDATA)\n", rel, outside_data_dir());
        mx_test_skips++;
    }
    return 0;
}

int mx_test_have(const char *rel) {
    char path[1100];
    return mx_test_need(path, sizeof path, "%s", rel);
}

int mx_test_finish(const char *name) {
    if (mx_test_failures) {
        printf("%s: %d check(s) failed\n", name, mx_test_failures);
        return 1;
    }
    if (mx_test_skips)
        printf("%s: all checks passed, %d case(s) skipped for want of test data\n", name, mx_test_skips);
    else
        printf("%s: all checks passed\n", name);
    return 0;
}

const char *const mx_test_assets[MX_TEST_NASSETS] = {
    "spot/spot_triangulated.obj",   "spot_ply/spot.ply",
    "bob/bob_tri.obj",              "blub/blub_triangulated.obj",
    "garment_female_casual/female_casualsuit01.obj",
    "garment_female_elegant/female_elegantsuit01.obj",
    "shoes_pair/shoes03.obj",       "fedora_hat/fedora.obj",
    "boot/boot.obj",                "koala/koala.obj",
    "mountain/mountain.obj",        "hammer/hammer.obj",
    "wooden_stool/painted_wooden_stool_1k.gltf",
    "flight_helmet/FlightHelmet.gltf",
    "cesium_milk_truck/CesiumMilkTruck.glb",
};
