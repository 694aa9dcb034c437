#include "condition.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int mx_depth_image(const mx_gbuffer *gb, mx_image *out, mx_status *st) {
    if (mx_image_alloc(out, gb->w, gb->h, 1, st)) return -1;
    int64_t n = (int64_t)gb->w * gb->h;
    float near = INFINITY, far = -INFINITY;
    for (int64_t i = 0; i < n; i++) {
        if (gb->face[i] < 0) continue;
        if (gb->depth[i] < near) near = gb->depth[i];
        if (gb->depth[i] > far) far = gb->depth[i];
    }
    float range = far - near > 1e-12f ? far - near : 1.0f;
    for (int64_t i = 0; i < n; i++) {
        out->data[i] = gb->face[i] < 0 ? 0.0f : 0.2f + 0.8f * (far - gb->depth[i]) / range;
    }
    return 0;
}

int mx_mask_image(const uint8_t *mask, int w, int h, mx_image *out, mx_status *st) {
    if (mx_image_alloc(out, w, h, 1, st)) return -1;
    for (int64_t i = 0; i < (int64_t)w * h; i++) out->data[i] = mask[i] ? 1.0f : 0.0f;
    return 0;
}

int mx_inpaint_image(const mx_image *rgb, const mx_image *mask, mx_image *out, mx_status *st) {
    if (rgb->w != mask->w || rgb->h != mask->h || rgb->c < 3 || mask->c != 1)
        return mx_fail(st, MX_EINTERNAL, "inpaint control: image %dx%dx%d and mask %dx%dx%d differ", rgb->w, rgb->h,
                       rgb->c, mask->w, mask->h, mask->c);
    if (mx_image_alloc(out, rgb->w, rgb->h, 3, st)) return -1;
    for (int64_t i = 0; i < (int64_t)rgb->w * rgb->h; i++)
        for (int k = 0; k < 3; k++) out->data[3 * i + k] = mask->data[i] >= 0.5f ? -1.0f : rgb->data[rgb->c * i + k];
    return 0;
}

int mx_paint_mask_cells(const mx_image *mask, int cell, int dilate, mx_image *out, mx_status *st) {
    if (mask->c != 1 || cell < 1 || dilate < 0)
        return mx_fail(st, MX_EINTERNAL, "paint mask: bad mask (%d channels), cell size %d or dilation %d", mask->c,
                       cell, dilate);
    int cw = (mask->w + cell - 1) / cell, ch = (mask->h + cell - 1) / cell;
    uint8_t *any = calloc((size_t)cw * ch, 1);
    if (!any) return mx_fail(st, MX_ENOMEM, "paint mask: out of memory");
    if (mx_image_alloc(out, mask->w, mask->h, 1, st)) {
        free(any);
        return -1;
    }
    for (int y = 0; y < mask->h; y++)
        for (int x = 0; x < mask->w; x++)
            if (mask->data[(size_t)y * mask->w + x] > 0.0f) any[(size_t)(y / cell) * cw + x / cell] = 1;
    for (int y = 0; y < mask->h; y++)
        for (int x = 0; x < mask->w; x++) {
            int cy = y / cell, cx = x / cell, hit = 0;
            for (int dy = -dilate; dy <= dilate && !hit; dy++)
                for (int dx = -dilate; dx <= dilate && !hit; dx++) {
                    int ny = cy + dy, nx = cx + dx;
                    hit = ny >= 0 && nx >= 0 && ny < ch && nx < cw && any[(size_t)ny * cw + nx];
                }
            out->data[(size_t)y * mask->w + x] = hit ? 1.0f : 0.0f;
        }
    free(any);
    return 0;
}

void mx_image_to_planes(const mx_image *img, float *planes, int plane_w, int x0) {
    size_t plane = (size_t)img->h * plane_w;
    for (int k = 0; k < img->c; k++)
        for (int y = 0; y < img->h; y++)
            for (int x = 0; x < img->w; x++)
                planes[k * plane + (size_t)y * plane_w + x0 + x] = img->data[((size_t)y * img->w + x) * img->c + k];
}

int mx_planes_to_image(const float *planes, int c, int h, int plane_w, int x0, int w, mx_image *out,
                       mx_status *st) {
    if (mx_image_alloc(out, w, h, c, st)) return -1;
    size_t plane = (size_t)h * plane_w;
    for (int k = 0; k < c; k++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++)
                out->data[((size_t)y * w + x) * c + k] = planes[k * plane + (size_t)y * plane_w + x0 + x];
    return 0;
}
