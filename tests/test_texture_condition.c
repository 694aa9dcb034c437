/* The paint mask of the inpaint pipeline (mx_paint_mask_cells): a cell is painted in all its
 * pixels when any pixel of it, or of a cell within `dilate` cells, is untextured; checked
 * against a direct per-pixel definition on sizes that are not multiples of the cell, with
 * masked pixels on the borders, and its refusals of bad arguments. */
#include <stdio.h>
#include <stdlib.h>

#include "../pipeline/texture/condition.h"
#include "util_test.h"

/* Painted or not, by the definition: some masked pixel whose cell is within dilate cells
 * (Chebyshev distance) of this pixel's cell. */
static int painted_by_definition(const mx_image *mask, int cell, int dilate, int x, int y) {
    for (int v = 0; v < mask->h; v++)
        for (int u = 0; u < mask->w; u++)
            if (mask->data[(size_t)v * mask->w + u] > 0.0f && abs(u / cell - x / cell) <= dilate &&
                abs(v / cell - y / cell) <= dilate)
                return 1;
    return 0;
}

/* mask w x h with the listed pixels set (value 1 or a small positive value), then compares. */
static void check_case(int w, int h, int cell, int dilate, const int (*px)[2], int npx) {
    mx_status st;
    mx_image mask, out;
    CHECK(mx_image_alloc(&mask, w, h, 1, &st) == 0);
    for (int i = 0; i < w * h; i++) mask.data[i] = i % 3 ? 0.0f : -0.5f; /* negatives are not masked */
    for (int i = 0; i < npx; i++) mask.data[px[i][1] * w + px[i][0]] = i % 2 ? 1.0f : 1e-3f;
    CHECK(mx_paint_mask_cells(&mask, cell, dilate, &out, &st) == 0);
    CHECK(out.w == w && out.h == h && out.c == 1);
    int wrong = 0, painted = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float want = painted_by_definition(&mask, cell, dilate, x, y) ? 1.0f : 0.0f;
            wrong += out.data[(size_t)y * w + x] != want;
            painted += out.data[(size_t)y * w + x] == 1.0f;
        }
    printf("paint mask %dx%d cell %d dilate %d, %d masked: %d painted, %d wrong\n", w, h, cell, dilate, npx, painted,
           wrong);
    CHECK(wrong == 0);
    CHECK(npx == 0 ? painted == 0 : painted > 0);
    mx_image_free(&mask);
    mx_image_free(&out);
}

static void check_refusals(void) {
    mx_status st;
    mx_image rgb, mask, out;
    CHECK(mx_image_alloc(&rgb, 9, 9, 3, &st) == 0 && mx_image_alloc(&mask, 9, 9, 1, &st) == 0);
    CHECK(mx_paint_mask_cells(&rgb, 8, 1, &out, &st) != 0 && st.code == MX_EINTERNAL);
    CHECK(mx_paint_mask_cells(&mask, 0, 1, &out, &st) != 0);
    CHECK(mx_paint_mask_cells(&mask, 8, -1, &out, &st) != 0);
    printf("paint mask refusals: %s\n", st.msg);
    mx_image_free(&rgb);
    mx_image_free(&mask);
}

int main(void) {
    static const int corners[][2] = {{0, 0}, {36, 0}, {0, 28}, {36, 28}};
    static const int middle[][2] = {{17, 13}};
    static const int row[][2] = {{8, 7}, {9, 7}, {23, 7}, {24, 20}};
    check_case(37, 29, 8, 0, corners, 4); /* partial last cells on both axes */
    check_case(37, 29, 8, 1, corners, 4);
    check_case(37, 29, 8, 1, middle, 1);
    check_case(37, 29, 8, 2, row, 4);
    check_case(16, 16, 8, 1, middle, 0); /* nothing masked: nothing painted */
    check_case(5, 3, 1, 1, middle, 0);
    static const int one[][2] = {{4, 2}};
    check_case(5, 3, 1, 1, one, 1); /* cell 1: a 3x3 dilation of the pixel, clipped */
    check_case(7, 7, 16, 0, one, 1); /* one cell larger than the image */
    check_refusals();
    return mx_test_finish("test_texture_condition");
}
