/* The AMX tile operations the AMX GEMM (gemm_amx.inc) uses, as a thin macro layer over either
 * the intrinsics (gemm_amx.c, built with -mamx-tile -mamx-bf16) or, with MX_AMX_EMULATE defined,
 * a software emulation of exactly the same semantics (tests/amx_emu.c), so that packing,
 * tiling and edge handling are tested on CPUs without AMX. Semantics (Intel SDM vol. 2,
 * LDTILECFG / TILELOADD / TILESTORED / TILEZERO / TDPBF16PS / TILERELEASE):
 *   - the 64-byte config: byte 0 palette (1: 8 tiles of at most 16 rows × 64 bytes), byte 1
 *     start_row (0), bytes 16..47 colsb[16] (bytes per row, uint16), bytes 48..63 rows[16];
 *     loading a config zeroes every tile;
 *   - tileloadd t, [base + stride]: rows[t] rows of colsb[t] bytes from base + r·stride; the rest
 *     of the tile reads as zero; tilestored writes rows[t] × colsb[t] bytes back;
 *   - tdpbf16ps d, a, b: d is M×N fp32 (M = rows[d], N = colsb[d]/4), a is M rows of K bf16 pairs
 *     (colsb[a]/4 = K), b is K rows of N pairs (the VNNI layout: word n of row k holds the pair
 *     (k-pair k, column n)); for each m, n, k in order:
 *       d[m][n] += fp32(a[m].bf16[2k]) · fp32(b[k].bf16[2n]);
 *       d[m][n] += fp32(a[m].bf16[2k+1]) · fp32(b[k].bf16[2n+1]);
 *     in fp32, round to nearest even, bf16 denormal inputs as zero and denormal results flushed to
 *     zero; shapes must agree (rows[a] = rows[d], colsb[b] = colsb[d], rows[b] = colsb[a]/4),
 *     else #UD (the emulation aborts).
 * Linux lets a process use the tile data only after arch_prctl(ARCH_REQ_XCOMP_PERM,
 * XFEATURE_XTILEDATA) (runtime/cpuid.c asks before choosing the amx level). */
#ifndef MX_AMX_TILES_H
#define MX_AMX_TILES_H

#include <stdint.h>
#include <string.h>

typedef struct {
    uint8_t palette, start_row, reserved[14];
    uint16_t colsb[16];
    uint8_t rows[16];
} mx_amx_cfg;
_Static_assert(sizeof(mx_amx_cfg) == 64, "the tile config is 64 bytes");

/* Palette 1 with tiles 0..ntiles-1 of `rows` rows × `colsb` bytes. */
static inline void mx_amx_cfg_uniform(mx_amx_cfg *cfg, int ntiles, int rows, int colsb) {
    memset(cfg, 0, sizeof *cfg);
    cfg->palette = 1;
    for (int t = 0; t < ntiles; t++) {
        cfg->rows[t] = (uint8_t)rows;
        cfg->colsb[t] = (uint16_t)colsb;
    }
}

#ifdef MX_AMX_EMULATE
#include <stdio.h>
#include <stdlib.h>

#include "../../runtime/half.h"

#define MX_AMX_TILES 8
#define MX_AMX_ROWS 16
#define MX_AMX_COLSB 64

typedef struct {
    mx_amx_cfg cfg;
    _Alignas(64) uint8_t t[MX_AMX_TILES][MX_AMX_ROWS][MX_AMX_COLSB];
} mx_amx_emu;

static inline void mx_amx_emu_fault(const char *what) {
    fprintf(stderr, "AMX emulation: %s (#UD on a real CPU)\n", what);
    abort();
}

static inline void mx_amx_emu_check_tile(const mx_amx_emu *s, int t) {
    if (t < 0 || t >= MX_AMX_TILES || s->cfg.palette != 1) mx_amx_emu_fault("tile or palette");
    if (s->cfg.rows[t] == 0 || s->cfg.rows[t] > MX_AMX_ROWS || s->cfg.colsb[t] == 0 ||
        s->cfg.colsb[t] > MX_AMX_COLSB)
        mx_amx_emu_fault("tile not configured");
}

static inline void mx_amx_emu_loadconfig(mx_amx_emu *s, const void *cfg) {
    memcpy(&s->cfg, cfg, sizeof s->cfg);
    if (s->cfg.palette != 1 || s->cfg.start_row) mx_amx_emu_fault("config: palette 1, start_row 0 expected");
    memset(s->t, 0, sizeof s->t);
}

static inline void mx_amx_emu_loadd(mx_amx_emu *s, int t, const void *base, size_t stride) {
    mx_amx_emu_check_tile(s, t);
    memset(s->t[t], 0, sizeof s->t[t]);
    for (int r = 0; r < s->cfg.rows[t]; r++)
        memcpy(s->t[t][r], (const uint8_t *)base + (size_t)r * stride, s->cfg.colsb[t]);
}

static inline void mx_amx_emu_stored(const mx_amx_emu *s, int t, void *base, size_t stride) {
    mx_amx_emu_check_tile(s, t);
    for (int r = 0; r < s->cfg.rows[t]; r++)
        memcpy((uint8_t *)base + (size_t)r * stride, s->t[t][r], s->cfg.colsb[t]);
}

static inline void mx_amx_emu_zero(mx_amx_emu *s, int t) {
    mx_amx_emu_check_tile(s, t);
    memset(s->t[t], 0, sizeof s->t[t]);
}

/* bf16 -> fp32, denormals as zero (DAZ). */
static inline float mx_amx_emu_bf16(uint16_t h) {
    return mx_bits_f32((h & 0x7f80u) ? (uint32_t)h << 16 : (uint32_t)(h & 0x8000u) << 16);
}

/* Denormal results flushed to (signed) zero (FTZ). */
static inline float mx_amx_emu_ftz(float x) {
    uint32_t u = mx_f32_bits(x);
    return (u & 0x7f800000u) ? x : mx_bits_f32(u & 0x80000000u);
}

static inline void mx_amx_emu_dpbf16ps(mx_amx_emu *s, int d, int a, int b) {
    mx_amx_emu_check_tile(s, d);
    mx_amx_emu_check_tile(s, a);
    mx_amx_emu_check_tile(s, b);
    const mx_amx_cfg *c = &s->cfg;
    if (d == a || d == b || a == b) mx_amx_emu_fault("tdpbf16ps: tiles must differ");
    if (c->rows[a] != c->rows[d] || c->colsb[b] != c->colsb[d] || c->rows[b] != c->colsb[a] / 4 || c->colsb[a] % 4 ||
        c->colsb[d] % 4)
        mx_amx_emu_fault("tdpbf16ps: shapes disagree");
    int M = c->rows[d], N = c->colsb[d] / 4, K = c->colsb[a] / 4;
    for (int m = 0; m < M; m++) {
        float acc[MX_AMX_COLSB / 4];
        memcpy(acc, s->t[d][m], sizeof acc);
        uint16_t arow[MX_AMX_COLSB / 2], brow[MX_AMX_COLSB / 2]; /* the bytes as bf16 (no aliasing) */
        memcpy(arow, s->t[a][m], sizeof arow);
        for (int k = 0; k < K; k++) {
            memcpy(brow, s->t[b][k], sizeof brow);
            for (int n = 0; n < N; n++) {
                acc[n] += mx_amx_emu_bf16(arow[2 * k]) * mx_amx_emu_bf16(brow[2 * n]);
                acc[n] += mx_amx_emu_bf16(arow[2 * k + 1]) * mx_amx_emu_bf16(brow[2 * n + 1]);
            }
        }
        for (int n = 0; n < N; n++) acc[n] = mx_amx_emu_ftz(acc[n]);
        memset(s->t[d][m], 0, MX_AMX_COLSB); /* the row past colsb reads as zero */
        memcpy(s->t[d][m], acc, (size_t)N * sizeof(float));
    }
    for (int m = M; m < MX_AMX_ROWS; m++) memset(s->t[d][m], 0, MX_AMX_COLSB);
}

/* TILERELEASE: back to the init state, no tile configured (a use before the next config faults). */
static inline void mx_amx_emu_release(mx_amx_emu *s) { memset(s, 0, sizeof *s); }

/* The state lives in the thread, as the real one does: a config loaded in one function holds in
 * the functions it calls until released. */
static _Thread_local mx_amx_emu mx_amx_emu_state;
#define AMX_LOADCONFIG(cfg) mx_amx_emu_loadconfig(&mx_amx_emu_state, (cfg))
#define AMX_LOADD(t, base, stride) mx_amx_emu_loadd(&mx_amx_emu_state, (t), (base), (stride))
#define AMX_STORED(t, base, stride) mx_amx_emu_stored(&mx_amx_emu_state, (t), (base), (stride))
#define AMX_ZERO(t) mx_amx_emu_zero(&mx_amx_emu_state, (t))
#define AMX_DPBF16PS(d, a, b) mx_amx_emu_dpbf16ps(&mx_amx_emu_state, (d), (a), (b))
#define AMX_RELEASE() mx_amx_emu_release(&mx_amx_emu_state)
#else
#include <immintrin.h>

/* The barrier makes the config's stores happen first: GCC 12 does not see _tile_loadconfig read
 * its 64 bytes and dropped the stores of rows and colsb (a #GP on the real CPU). */
#define AMX_LOADCONFIG(cfg)                                                                                  \
    do {                                                                                                     \
        __asm__ volatile("" : : "m"(*(const mx_amx_cfg *)(cfg)) : "memory");                                 \
        _tile_loadconfig(cfg);                                                                               \
    } while (0)
#define AMX_LOADD(t, base, stride) _tile_loadd(t, base, stride)
#define AMX_STORED(t, base, stride) _tile_stored(t, base, stride)
#define AMX_ZERO(t) _tile_zero(t)
#define AMX_DPBF16PS(d, a, b) _tile_dpbf16ps(d, a, b)
#define AMX_RELEASE() _tile_release()
#endif

#endif
