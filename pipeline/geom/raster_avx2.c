/* AVX2 triangle drawing: 8 pixels of a row per step, in 32-bit edge arithmetic (exact for
 * the small triangles it is given, see RASTER_SMALL_EXTENT). Matches draw_tri_scalar in
 * raster.c bit for bit: the same inside test, the same float depth expression in the same
 * order (FMA contraction is off in this build). Steps start at multiples of 8 columns, so
 * a step lies inside the tile (tiles are 32 wide) unless it crosses the image's right
 * edge; inside, it updates pixels with a blend and a plain store (pixels that stay are
 * rewritten unchanged, and only this task touches the tile), at the edge with masked
 * loads and stores that never touch memory outside the image. */
#include <immintrin.h>

#include "raster_tri.h"

/* Depth test and update of the 8 pixels from index i: lanes in `inside` that are closer
 * than `buf` get z (and, with face, the face id). */
static inline __m256i update_plain(float *buf, size_t i, __m256i inside, __m256 z) {
    __m256 d = _mm256_loadu_ps(buf + i);
    __m256 closer = _mm256_and_ps(_mm256_castsi256_ps(inside), _mm256_cmp_ps(z, d, _CMP_LT_OQ));
    _mm256_storeu_ps(buf + i, _mm256_blendv_ps(d, z, closer));
    return _mm256_castps_si256(closer);
}

static inline __m256i update_masked(float *buf, size_t i, __m256i inside, __m256 z) {
    __m256 d = _mm256_maskload_ps(buf + i, inside);
    __m256i closer = _mm256_and_si256(inside, _mm256_castps_si256(_mm256_cmp_ps(z, d, _CMP_LT_OQ)));
    _mm256_maskstore_ps(buf + i, closer, z);
    return closer;
}

static inline void update_face(int32_t *face, size_t i, __m256i closer, __m256i id, int plain) {
    if (plain) {
        __m256i old = _mm256_loadu_si256((const __m256i *)(face + i));
        _mm256_storeu_si256((__m256i *)(face + i), _mm256_blendv_epi8(old, id, closer));
    } else {
        _mm256_maskstore_epi32((int *)(face + i), closer, id);
    }
}

void mx_raster_draw_small_avx2(const raster_tri *t, const raster_target *o) {
    const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    int xs = t->x0 & ~7; /* first step column (the tile starts at a multiple of 32) */
    __m256i step8[3], lane_off[3], limit[3];
    for (int k = 0; k < 3; k++) {
        step8[k] = _mm256_set1_epi32((int32_t)(8 * t->step_x[k]));
        /* lane l of the first step is column xs + l, i.e. x0 + (xs - x0) + l */
        lane_off[k] = _mm256_mullo_epi32(_mm256_add_epi32(lane, _mm256_set1_epi32(xs - t->x0)),
                                         _mm256_set1_epi32((int32_t)t->step_x[k]));
        limit[k] = _mm256_set1_epi32((int32_t)(t->bias[k] - 1)); /* w >= bias <=> w > bias - 1 */
    }
    const __m256 z0 = _mm256_set1_ps(t->z0), dz1 = _mm256_set1_ps(t->dz1), dz2 = _mm256_set1_ps(t->dz2);
    const __m256 inv_area = _mm256_set1_ps(t->inv_area), one = _mm256_set1_ps(1.0f);
    const __m256i face = _mm256_set1_epi32(t->face);
    const __m256i box_lo = _mm256_set1_epi32(t->x0 - 1), box_hi = _mm256_set1_epi32(t->x1 + 1);
    int64_t row[3] = {t->row[0], t->row[1], t->row[2]};
    for (int y = t->y0; y <= t->y1; y++) {
        __m256i w0 = _mm256_add_epi32(_mm256_set1_epi32((int32_t)row[0]), lane_off[0]);
        __m256i w1 = _mm256_add_epi32(_mm256_set1_epi32((int32_t)row[1]), lane_off[1]);
        __m256i w2 = _mm256_add_epi32(_mm256_set1_epi32((int32_t)row[2]), lane_off[2]);
        for (int x = xs; x <= t->x1; x += 8) {
            __m256i col = _mm256_add_epi32(_mm256_set1_epi32(x), lane);
            __m256i in_box = _mm256_and_si256(_mm256_cmpgt_epi32(col, box_lo), _mm256_cmpgt_epi32(box_hi, col));
            __m256i inside = _mm256_and_si256(in_box, _mm256_cmpgt_epi32(w0, limit[0]));
            inside = _mm256_and_si256(inside, _mm256_cmpgt_epi32(w1, limit[1]));
            inside = _mm256_and_si256(inside, _mm256_cmpgt_epi32(w2, limit[2]));
            if (!_mm256_testz_si256(inside, inside)) {
                __m256 a = _mm256_mul_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(w1), inv_area), dz1);
                __m256 b = _mm256_mul_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(w2), inv_area), dz2);
                __m256 z = _mm256_add_ps(_mm256_add_ps(z0, a), b);
                if (t->persp) z = _mm256_div_ps(one, z);
                size_t i = (size_t)y * o->w + x;
                int plain = x + 7 <= t->tile_x1;
                if (o->depth_all) {
                    if (plain)
                        update_plain(o->depth_all, i, inside, z);
                    else
                        update_masked(o->depth_all, i, inside, z);
                }
                if (!t->back) {
                    __m256i closer = plain ? update_plain(o->depth, i, inside, z)
                                           : update_masked(o->depth, i, inside, z);
                    update_face(o->face, i, closer, face, plain);
                }
            }
            w0 = _mm256_add_epi32(w0, step8[0]);
            w1 = _mm256_add_epi32(w1, step8[1]);
            w2 = _mm256_add_epi32(w2, step8[2]);
        }
        for (int k = 0; k < 3; k++) row[k] += t->step_y[k];
    }
}
