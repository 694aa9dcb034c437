/* golden-v1 (tests/data/golden/README.md). The value expressions must be evaluated exactly as
 * written, in double and rounded once to float, without fused multiply-add: the Makefile
 * compiles with -ffp-contract=off, and each product is stored in a double before the add. */
#include "golden_rule.h"

#include <math.h>
#include <string.h>

#include "../runtime/half.h"

#define GOLDEN 0x9E3779B97F4A7C15ull

static uint64_t fnv1a64(const char *s) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
        h ^= *p;
        h *= 0x100000001b3ull;
    }
    return h;
}

/* x in [-1, 1) for element i: splitmix64 finalizer of key + (i+1) * golden, top 24 bits. */
static double golden_x(uint64_t key, uint64_t i) {
    uint64_t z = key + (i + 1) * GOLDEN;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z = z ^ (z >> 31);
    return (double)(z >> 40) * (1.0 / 8388608.0) - 1.0;
}

static int ends_with(const char *s, const char *suffix) {
    size_t n = strlen(s), k = strlen(suffix);
    return n >= k && !strcmp(s + n - k, suffix);
}

void mx_golden_v1_fill_range(const char *name, int ndim, const int64_t *shape, uint64_t seed, uint64_t start,
                             size_t count, float *out) {
    uint64_t key = fnv1a64(name) ^ (seed * GOLDEN);
    if (ndim <= 1) {
        /* 1-D: "<...>.weight" (norm scales) near 1, everything else (biases) near 0 */
        int is_weight = ends_with(name, ".weight");
        for (size_t k = 0; k < count; k++) {
            double x = golden_x(key, start + k);
            volatile double scaled = (is_weight ? 0.1 : 0.05) * x; /* rounded before the add */
            out[k] = (float)(is_weight ? 1.0 + scaled : scaled);
        }
        return;
    }
    double fan_in = 1;
    for (int d = 1; d < ndim; d++) fan_in *= (double)shape[d];
    double scale = 1.0 / sqrt(fan_in);
    for (size_t k = 0; k < count; k++) out[k] = (float)(scale * golden_x(key, start + k));
}

void mx_golden_v1_fill(const char *name, int ndim, const int64_t *shape, uint64_t seed, float *out) {
    uint64_t n = 1;
    for (int d = 0; d < ndim; d++) n *= (uint64_t)shape[d];
    mx_golden_v1_fill_range(name, ndim, shape, seed, 0, (size_t)n, out);
}

void mx_golden_checksum_init(mx_golden_checksum *c) { memset(c, 0, sizeof *c); }

/* Neumaier's compensated addition: keeps the sums far more accurate than the tolerance
 * used against the reference's pairwise sums. */
static void neumaier_add(double *sum, double *comp, double v) {
    double t = *sum + v;
    if (fabs(*sum) >= fabs(v)) *comp += (*sum - t) + v;
    else *comp += (v - t) + *sum;
    *sum = t;
}

void mx_golden_checksum_add(mx_golden_checksum *c, const float *x, size_t n) {
    for (size_t k = 0; k < n; k++, c->count++) {
        uint32_t bits;
        memcpy(&bits, &x[k], 4);
        uint16_t h = mx_float_to_half(x[k]);
        if (c->count < 4) {
            c->first4[c->count] = bits;
            c->f16_first4[c->count] = h;
        }
        c->u32_sum += bits;
        c->u32_wsum += (c->count + 1) * bits;
        c->f16_u16_sum += h;
        double v = x[k];
        neumaier_add(&c->sum, &c->sum_c, v);
        neumaier_add(&c->sumsq, &c->sumsq_c, v * v);
        c->sum_abs += fabs(v);
    }
}

double mx_golden_checksum_sum(const mx_golden_checksum *c) { return c->sum + c->sum_c; }
double mx_golden_checksum_sumsq(const mx_golden_checksum *c) { return c->sumsq + c->sumsq_c; }
