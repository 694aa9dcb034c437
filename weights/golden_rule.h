/* The "golden-v1" rule of tests/data/golden/README.md: random weights defined by a tensor's
 * name, shape and a seed, so that SD1.5-size parity tests need no downloaded model, and the
 * checksums listed in each sd15_* folder's weights_checksums.json. */
#ifndef MX_GOLDEN_RULE_H
#define MX_GOLDEN_RULE_H

#include <stddef.h>
#include <stdint.h>

/* Fills the whole tensor (numel = product of shape) with its golden-v1 values. */
void mx_golden_v1_fill(const char *name, int ndim, const int64_t *shape, uint64_t seed, float *out);
/* Elements [start, start + count) of the same tensor, for streaming large tensors in chunks. */
void mx_golden_v1_fill_range(const char *name, int ndim, const int64_t *shape, uint64_t seed, uint64_t start,
                             size_t count, float *out);

/* Checksums of a float32 tensor, accumulated over consecutive chunks (fields as in
 * weights_checksums.json). */
typedef struct mx_golden_checksum {
    uint64_t count;      /* elements seen */
    uint64_t u32_sum;    /* sum of float32 bit patterns */
    uint64_t u32_wsum;   /* sum of (i+1) * bits[i], mod 2^64 */
    uint64_t f16_u16_sum; /* sum of the fp16 (round to nearest even) bit patterns */
    double sum, sumsq;   /* compensated sums of the values and their squares */
    double sum_abs;      /* sum of |x|: scale for comparing `sum` with a tolerance */
    uint32_t first4[4];  /* bit patterns of the first four values */
    uint16_t f16_first4[4];
    double sum_c, sumsq_c; /* compensation terms (Neumaier) */
} mx_golden_checksum;

void mx_golden_checksum_init(mx_golden_checksum *c);
void mx_golden_checksum_add(mx_golden_checksum *c, const float *x, size_t n);
/* The final compensated sums. */
double mx_golden_checksum_sum(const mx_golden_checksum *c);
double mx_golden_checksum_sumsq(const mx_golden_checksum *c);

#endif
