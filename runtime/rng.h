/* Counter-based random numbers: Philox4x32-10 (Salmon et al., "Parallel random numbers:
 * as easy as 1, 2, 3", SC'11), the generator of cuRAND and JAX.
 *
 * Documented mapping (seed, stream, index) -> standard normal float, reproducible on any
 * device because each value depends only on its own coordinates:
 *   key     = (lo32(seed), hi32(seed))
 *   counter = (lo32(index/2), hi32(index/2), lo32(stream), hi32(stream))
 *   (r0, r1, r2, r3) = Philox4x32-10(counter, key)
 *   u1 = (r0 + 1) * 2^-32            in (0, 1]     (computed in double)
 *   u2 =  r1      * 2^-32            in [0, 1)
 *   radius = sqrt(-2 ln u1), angle = 2 pi u2
 *   normal(index) = (float)(radius * cos(angle))  for even index
 *                   (float)(radius * sin(angle))  for odd index
 * r2 and r3 are unused (kept so the counter layout matches the CUDA kernel).
 * The Box-Muller step is done in double and rounded once to float, so a GPU kernel that
 * uses double log/sqrt/sincos gives the same floats, except where its double math (within
 * 1-2 ulp of glibc's) lands on the other side of a float rounding boundary: rare, and not yet
 * measured on a GPU (ops/cuda/cuda_rng.cu, tests/cuda). */
#ifndef MX_RNG_H
#define MX_RNG_H

#include <stddef.h>
#include <stdint.h>

void mx_philox4x32_10(const uint32_t counter[4], const uint32_t key[2], uint32_t out[4]);
float mx_rng_normal(uint64_t seed, uint64_t stream, uint64_t index);
/* Fills out[i] = mx_rng_normal(seed, stream, first + i) for i < n. */
void mx_rng_fill_normal(float *out, size_t n, uint64_t seed, uint64_t stream, uint64_t first);

#endif
