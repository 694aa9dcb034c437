#include "masks.h"

#include <math.h>
#include <string.h>

void mx_mask_foreground(const mx_gbuffer *gb, uint8_t *mask) {
    for (size_t i = 0; i < (size_t)gb->w * gb->h; i++) mask[i] = gb->face[i] >= 0;
}

/* World point seen at pixel (x, y), or 0 when the pixel is background or outside. */
static int pixel_point(const mx_gbuffer *gb, int x, int y, float out[3]) {
    if (x < 0 || y < 0 || x >= gb->w || y >= gb->h) return 0;
    size_t i = (size_t)y * gb->w + x;
    if (gb->face[i] < 0) return 0;
    mx_camera_unproject(&gb->cam, (float)x + 0.5f, (float)y + 0.5f, gb->depth[i], gb->w, gb->h, out);
    return 1;
}

/* Tangent along one image axis at p (step sx, sy), oriented along +axis: the one-sided
 * difference towards the neighbour closer in depth, so that depth discontinuities do
 * not tilt the normal. */
static int axis_tangent(const mx_gbuffer *gb, int x, int y, int sx, int sy, const float p[3],
                        float out[3]) {
    float a[3], b[3];
    int has_a = pixel_point(gb, x + sx, y + sy, a), has_b = pixel_point(gb, x - sx, y - sy, b);
    if (!has_a && !has_b) return 0;
    float da = has_a ? fabsf(gb->depth[(size_t)(y + sy) * gb->w + x + sx] - gb->depth[(size_t)y * gb->w + x]) : INFINITY;
    float db = has_b ? fabsf(gb->depth[(size_t)(y - sy) * gb->w + x - sx] - gb->depth[(size_t)y * gb->w + x]) : INFINITY;
    for (int k = 0; k < 3; k++) out[k] = da <= db ? a[k] - p[k] : p[k] - b[k];
    return 1;
}

/* |n . v| of the depth map's normal at pixel (x, y); -1 where it is undefined. */
static float depth_normal_cosine(const mx_gbuffer *gb, int x, int y) {
    float p[3], tx[3], ty[3];
    if (!pixel_point(gb, x, y, p)) return -1;
    if (!axis_tangent(gb, x, y, 1, 0, p, tx) || !axis_tangent(gb, x, y, 0, 1, p, ty)) return -1;
    float n[3] = {tx[1] * ty[2] - tx[2] * ty[1], tx[2] * ty[0] - tx[0] * ty[2],
                  tx[0] * ty[1] - tx[1] * ty[0]};
    float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(len > 0)) return -1;
    float v[3];
    mx_camera_view_dir(&gb->cam, p, v);
    return fabsf(n[0] * v[0] + n[1] * v[1] + n[2] * v[2]) / len;
}

static float geometric_cosine(const mx_gbuffer *gb, int x, int y) {
    size_t i = (size_t)y * gb->w + x;
    if (gb->face[i] < 0) return -1;
    float n[3], p[3] = {0, 0, 0}, v[3];
    mx_gbuffer_normal(gb, (int64_t)i, n);
    if (!gb->cam.ortho) /* orthographic: one view direction for every pixel */
        mx_camera_unproject(&gb->cam, (float)x + 0.5f, (float)y + 0.5f, gb->depth[i], gb->w, gb->h, p);
    mx_camera_view_dir(&gb->cam, p, v);
    return fabsf(n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
}

void mx_mask_frontal(const mx_gbuffer *gb, int normal_source, float threshold, uint8_t *mask) {
    mx_mask_frontal_rows(gb, normal_source, threshold, 0, gb->h, mask);
}

/* Orthographic geometric case: one view direction, normals read from the face table. */
static void frontal_rows_ortho_geometric(const mx_gbuffer *gb, float threshold, int y0, int y1,
                                         uint8_t *mask) {
    const float *fn = mx_gbuffer_face_normals(gb);
    float v[3] = {-gb->cam.forward[0], -gb->cam.forward[1], -gb->cam.forward[2]};
    for (size_t i = (size_t)y0 * gb->w; i < (size_t)y1 * gb->w; i++) {
        int f = gb->face[i];
        if (f < 0) {
            mask[i] = 0;
            continue;
        }
        const float *n = fn + 3 * (size_t)f;
        float c = fabsf(n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
        mask[i] = c >= threshold;
    }
}

void mx_mask_frontal_rows(const mx_gbuffer *gb, int normal_source, float threshold, int y0, int y1,
                          uint8_t *mask) {
    if (normal_source != MX_NORMAL_FROM_DEPTH && gb->cam.ortho) {
        frontal_rows_ortho_geometric(gb, threshold, y0, y1, mask);
        return;
    }
    for (int y = y0; y < y1; y++)
        for (int x = 0; x < gb->w; x++) {
            float c = normal_source == MX_NORMAL_FROM_DEPTH ? depth_normal_cosine(gb, x, y)
                                                            : geometric_cosine(gb, x, y);
            mask[(size_t)y * gb->w + x] = c >= 0 && c >= threshold;
        }
}

void mx_mask_internal(const float *depth_culled, const float *depth_unculled, int64_t n, uint8_t *mask) {
    for (int64_t i = 0; i < n; i++) {
        float a = depth_culled[i], b = depth_unculled[i];
        /* without culling the nearest surface can only be closer; a visible gap means the
         * nearest surface there is a back face, i.e. the inside of an open mesh */
        mask[i] = !isinf(b) && (isinf(a) || a - b > 1e-4f * fabsf(a));
    }
}

int64_t mx_uv_texel(float u, float v, int tex_w, int tex_h) {
    float fx = floorf(u * (float)tex_w), fy = floorf((1.0f - v) * (float)tex_h);
    int x = (int)fmodf(fx, (float)tex_w), y = (int)fmodf(fy, (float)tex_h);
    if (x < 0) x += tex_w;
    if (y < 0) y += tex_h;
    return (int64_t)y * tex_w + x;
}

/* Pixels of an inpainting-mask task (by size only: the same mask on any pool). */
#define INPAINT_PIXELS_PER_TASK 16384

typedef struct inpaint_job {
    const mx_gbuffer *gb;
    const mx_mesh *m;
    const uint8_t *allowed, *known;
    int tex_w, tex_h;
    uint8_t *mask;
} inpaint_job;

static void inpaint_pixels(void *arg, int task, int thread) {
    (void)thread;
    const inpaint_job *p = arg;
    const mx_gbuffer *gb = p->gb;
    size_t plane = (size_t)p->tex_w * p->tex_h, n = (size_t)gb->w * gb->h;
    for (size_t i = (size_t)task * INPAINT_PIXELS_PER_TASK; i < (size_t)(task + 1) * INPAINT_PIXELS_PER_TASK && i < n; i++) {
        int f = gb->face[i];
        if (f < 0 || (p->allowed && !p->allowed[i]) || !gb->uv) {
            p->mask[i] = 0;
            continue;
        }
        int mat = p->m->face_mat ? p->m->face_mat[f] : 0;
        if (mat < 0 || mat >= (p->m->nmat > 0 ? p->m->nmat : 1)) mat = 0;
        if (!isfinite(gb->uv[2 * i]) || !isfinite(gb->uv[2 * i + 1])) {
            p->mask[i] = 0; /* a face without UVs: nothing to paint into */
            continue;
        }
        int64_t t = mx_uv_texel(gb->uv[2 * i], gb->uv[2 * i + 1], p->tex_w, p->tex_h);
        p->mask[i] = !p->known[(size_t)mat * plane + (size_t)t];
    }
}

void mx_mask_inpaint(const mx_gbuffer *gb, const mx_mesh *m, const uint8_t *allowed,
                     const uint8_t *known, int tex_w, int tex_h, mx_pool *pool, uint8_t *mask) {
    inpaint_job p = {gb, m, allowed, known, tex_w, tex_h, mask};
    size_t n = (size_t)gb->w * gb->h;
    mx_pool_for(pool, (int)((n + INPAINT_PIXELS_PER_TASK - 1) / INPAINT_PIXELS_PER_TASK), inpaint_pixels, &p);
}

void mx_mask_and_not(const uint8_t *a, const uint8_t *b, uint8_t *dst, int64_t n) {
    for (int64_t i = 0; i < n; i++) dst[i] = a[i] && !b[i];
}

int64_t mx_mask_count(const uint8_t *mask, int64_t n) {
    int64_t c = 0;
    for (int64_t i = 0; i < n; i++) c += mask[i] != 0;
    return c;
}
