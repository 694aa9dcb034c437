/* Philox4x32-10 normals, bit-identical to runtime/rng.c: the same (seed, stream, index) -> counter/key
 * mapping, the same rounds, and Box-Muller in double rounded once to float. The double steps use the
 * _rn intrinsics so that nvcc cannot contract them into FMAs (the CPU build uses -ffp-contract=off). */
#include "cuda_common.cuh"

#define PHILOX_M0 0xD2511F53u
#define PHILOX_M1 0xCD9E8D57u
#define PHILOX_W0 0x9E3779B9u
#define PHILOX_W1 0xBB67AE85u

__device__ __forceinline__ void philox4x32_10(uint32_t c[4], uint32_t k0, uint32_t k1) {
    for (int r = 0; r < 10; r++) {
        uint32_t hi0 = __umulhi(PHILOX_M0, c[0]), lo0 = PHILOX_M0 * c[0];
        uint32_t hi1 = __umulhi(PHILOX_M1, c[2]), lo1 = PHILOX_M1 * c[2];
        uint32_t n0 = hi1 ^ c[1] ^ k0, n2 = hi0 ^ c[3] ^ k1;
        c[0] = n0;
        c[1] = lo1;
        c[2] = n2;
        c[3] = lo0;
        k0 += PHILOX_W0; /* the key after the last round is unused, so bumping it there is harmless */
        k1 += PHILOX_W1;
    }
}

__device__ float rng_normal(uint64_t seed, uint64_t stream, uint64_t index) {
    uint64_t pair = index / 2;
    uint32_t c[4] = {(uint32_t)pair, (uint32_t)(pair >> 32), (uint32_t)stream, (uint32_t)(stream >> 32)};
    philox4x32_10(c, (uint32_t)seed, (uint32_t)(seed >> 32));
    const double two_m32 = 1.0 / 4294967296.0;
    double u1 = __dmul_rn(__dadd_rn((double)c[0], 1.0), two_m32);
    double u2 = __dmul_rn((double)c[1], two_m32);
    double radius = sqrt(__dmul_rn(-2.0, log(u1)));
    double angle = __dmul_rn(6.283185307179586476925, u2);
    return (float)__dmul_rn(radius, (index & 1) ? sin(angle) : cos(angle));
}

__global__ void rng_fill_normal_kernel(float *out, size_t n, uint64_t seed, uint64_t stream, uint64_t first) {
    MX_CUDA_GRID_STRIDE(i, n) out[i] = rng_normal(seed, stream, first + i);
}

int mx_cuda_rng_fill_normal(mx_cuda_ctx *c, float *out, size_t n, uint64_t seed, uint64_t stream, uint64_t first,
                            mx_status *st) {
    if (n == 0) return 0;
    rng_fill_normal_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(out, n, seed, stream, first);
    return mx_cuda_launched("cuda rng_fill_normal", st);
}
