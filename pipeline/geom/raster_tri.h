/* Internal to the rasterizer: one triangle clipped to one tile, ready to draw, and the
 * kernels that draw it (raster.c: the scalar reference; raster_avx2.c: 8 pixels at a
 * time). Both give bit-identical buffers: the same integer edge values, and the same
 * float operations in the same order for the depth. */
#ifndef MX_RASTER_TRI_H
#define MX_RASTER_TRI_H

#include <stdint.h>

typedef struct raster_tri {
    int x0, y0, x1, y1;     /* pixel box to scan (inside the tile) */
    int tile_x0, tile_x1;   /* columns of the tile: the drawing task owns every pixel there */
    int64_t row[3];         /* edge function k at the centre of pixel (x0, y0) */
    int64_t step_x[3];      /* its change per pixel to the right */
    int64_t step_y[3];      /* its change per pixel down */
    int64_t bias[3];        /* a pixel is inside when every row[k] >= bias[k] (top-left rule) */
    float z0, dz1, dz2, inv_area; /* depth = z0 + w1 * inv_area * dz1 + w2 * inv_area * dz2 */
    int persp;              /* the interpolated value is 1/depth */
    int back;               /* a back face of a culled pass: only depth_all is written */
    int32_t face;
} raster_tri;

typedef struct raster_target {
    int w;
    int32_t *face;
    float *depth;
    float *depth_all; /* depth without culling, or NULL */
} raster_target;

/* Edge values fit in 32 bits (with room for 8-pixel steps) when the triangle's snapped
 * box is at most this many sub-pixel units wide and high (64 pixels). */
#define RASTER_SMALL_EXTENT (1 << 14)

/* Draws a triangle whose snapped box is within RASTER_SMALL_EXTENT (AVX2 + FMA build; x86
 * only: the Makefile leaves raster_avx2.c out of other builds, and raster.c does not call it). */
void mx_raster_draw_small_avx2(const raster_tri *t, const raster_target *o);

#endif
