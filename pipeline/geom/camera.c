#include "camera.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const float DEG = 3.14159265358979f / 180.0f;

static float dot3(const float a[3], const float b[3]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void normalize3(float v[3]) {
    float n = sqrtf(dot3(v, v));
    if (n > 0) {
        v[0] /= n;
        v[1] /= n;
        v[2] /= n;
    }
}

static void cross3(const float a[3], const float b[3], float out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Places the eye and builds the basis; world up is +y except near the poles, where the
 * camera's up follows the azimuth (-z rotated) so that top and bottom views stay defined. */
static void camera_place(mx_camera *cam, float azimuth, float elevation, float radius) {
    float a = azimuth * DEG, e = elevation * DEG;
    cam->azimuth = azimuth;
    cam->elevation = elevation;
    cam->radius = radius;
    float dir[3] = {cosf(e) * sinf(a), sinf(e), cosf(e) * cosf(a)};
    for (int i = 0; i < 3; i++) {
        cam->eye[i] = radius * dir[i];
        cam->forward[i] = -dir[i];
    }
    float world_up[3] = {0, 1, 0};
    if (fabsf(dir[1]) > 0.999f) {
        world_up[0] = -sinf(a) * (dir[1] > 0 ? 1.0f : -1.0f);
        world_up[1] = 0;
        world_up[2] = -cosf(a) * (dir[1] > 0 ? 1.0f : -1.0f);
    }
    cross3(cam->forward, world_up, cam->right);
    normalize3(cam->right);
    cross3(cam->right, cam->forward, cam->up);
    normalize3(cam->up);
}

void mx_camera_ortho(mx_camera *cam, float azimuth, float elevation, float radius, float half_extent) {
    memset(cam, 0, sizeof *cam);
    cam->ortho = 1;
    cam->half_extent = half_extent;
    cam->fov_y = 0;
    camera_place(cam, azimuth, elevation, radius);
}

void mx_camera_persp(mx_camera *cam, float azimuth, float elevation, float radius, float fov_y) {
    memset(cam, 0, sizeof *cam);
    cam->ortho = 0;
    cam->fov_y = fov_y;
    cam->half_extent = radius * tanf(0.5f * fov_y * DEG);
    camera_place(cam, azimuth, elevation, radius);
}

int mx_camera_project(const mx_camera *cam, const float p[3], int w, int h, float out[3]) {
    float d[3] = {p[0] - cam->eye[0], p[1] - cam->eye[1], p[2] - cam->eye[2]};
    float x = dot3(d, cam->right), y = dot3(d, cam->up), z = dot3(d, cam->forward);
    float half = cam->half_extent;
    if (!cam->ortho) {
        if (z <= 1e-6f) return 0;
        half = z * tanf(0.5f * cam->fov_y * DEG);
    }
    /* square pixels: the vertical extent maps to h, the horizontal scales with w/h */
    float s = 0.5f * (float)h / half;
    out[0] = 0.5f * (float)w + x * s;
    out[1] = 0.5f * (float)h - y * s;
    out[2] = z;
    return 1;
}

void mx_camera_unproject(const mx_camera *cam, float x, float y, float depth, int w, int h,
                         float out[3]) {
    float half = cam->ortho ? cam->half_extent : depth * tanf(0.5f * cam->fov_y * DEG);
    float s = 2.0f * half / (float)h;
    float cx = (x - 0.5f * (float)w) * s, cy = (0.5f * (float)h - y) * s;
    for (int i = 0; i < 3; i++)
        out[i] = cam->eye[i] + cx * cam->right[i] + cy * cam->up[i] + depth * cam->forward[i];
}

void mx_camera_view_dir(const mx_camera *cam, const float p[3], float out[3]) {
    if (cam->ortho) {
        for (int i = 0; i < 3; i++) out[i] = -cam->forward[i];
        return;
    }
    for (int i = 0; i < 3; i++) out[i] = cam->eye[i] - p[i];
    normalize3(out);
}

void mx_camera_fibonacci(mx_camera *out, int n, const mx_camera *tmpl) {
    const float golden = 3.14159265358979f * (3.0f - sqrtf(5.0f));
    for (int i = 0; i < n; i++) {
        float y = 1.0f - 2.0f * ((float)i + 0.5f) / (float)n; /* sin(elevation) */
        float elevation = asinf(y) / DEG;
        float azimuth = fmodf((float)i * golden / DEG, 360.0f);
        if (tmpl->ortho)
            mx_camera_ortho(&out[i], azimuth, elevation, tmpl->radius, tmpl->half_extent);
        else
            mx_camera_persp(&out[i], azimuth, elevation, tmpl->radius, tmpl->fov_y);
    }
}

const char *mx_camera_view_word(const mx_camera *cam) {
    if (cam->elevation > 60) return "top";
    if (cam->elevation < -60) return "bottom";
    float a = fmodf(cam->azimuth, 360.0f);
    if (a < 0) a += 360.0f;
    if (a <= 45 || a >= 315) return "front";
    if (a >= 135 && a <= 225) return "back";
    return "side";
}

mx_crop mx_crop_from_mask(const unsigned char *mask, int w, int h, float margin) {
    int x0 = w, y0 = h, x1 = -1, y1 = -1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            if (mask[(size_t)y * w + x]) {
                if (x < x0) x0 = x;
                if (x > x1) x1 = x;
                if (y < y0) y0 = y;
                if (y > y1) y1 = y;
            }
    int full = w < h ? w : h;
    mx_crop c = {0, 0, full};
    if (x1 < 0) return c;
    int side = (x1 - x0 > y1 - y0 ? x1 - x0 : y1 - y0) + 1;
    int size = (int)ceilf((float)side * (1.0f + 2.0f * margin));
    if (size > full) size = full;
    if (size < 1) size = 1;
    c.size = size;
    c.x0 = (x0 + x1 + 1) / 2 - size / 2;
    c.y0 = (y0 + y1 + 1) / 2 - size / 2;
    if (c.x0 + size > w) c.x0 = w - size;
    if (c.y0 + size > h) c.y0 = h - size;
    if (c.x0 < 0) c.x0 = 0;
    if (c.y0 < 0) c.y0 = 0;
    return c;
}

/* The bilinear taps of one sample position along an axis (pixel centres at +0.5), clamped to the
 * border: source indices i0, i1 and the weight t of i1. */
typedef struct axis_tap {
    int i0, i1;
    float t;
} axis_tap;

static axis_tap tap_at(float x, int n) {
    float fx = x - 0.5f;
    int ix = (int)floorf(fx);
    axis_tap a = {ix < 0 ? 0 : ix >= n ? n - 1 : ix, ix + 1 < 0 ? 0 : ix + 1 >= n ? n - 1 : ix + 1, fx - (float)ix};
    return a;
}

/* Bilinear sample of channel-interleaved pixels at the taps (tx, ty). */
static void sample_taps(const mx_image *img, axis_tap tx, axis_tap ty, float *out) {
    const float *r0 = img->data + (size_t)ty.i0 * img->w * img->c, *r1 = img->data + (size_t)ty.i1 * img->w * img->c;
    for (int c = 0; c < img->c; c++) {
        float a = r0[tx.i0 * img->c + c], b = r0[tx.i1 * img->c + c];
        float d = r1[tx.i0 * img->c + c], e = r1[tx.i1 * img->c + c];
        out[c] = (a * (1 - tx.t) + b * tx.t) * (1 - ty.t) + (d * (1 - tx.t) + e * tx.t) * ty.t;
    }
}

/* Rows of an image per task of the resamplers (by size only: the same result on any pool). */
#define CROP_ROWS_PER_TASK 16

/* mx_crop_resize's work: its taps per output column and row (ss samples each, the sample
 * positions of the area filter), the output rows of a task. */
typedef struct resize_job {
    const mx_image *src;
    mx_image *dst;
    const axis_tap *xt, *yt;
    int ss;
} resize_job;

static void resize_rows(void *arg, int task, int thread) {
    (void)thread;
    const resize_job *r = arg;
    int size = r->dst->w, ss = r->ss, nc = r->src->c;
    float px[4];
    for (int y = task * CROP_ROWS_PER_TASK; y < (task + 1) * CROP_ROWS_PER_TASK && y < size; y++)
        for (int x = 0; x < size; x++) {
            float acc[4] = {0, 0, 0, 0};
            for (int sy = 0; sy < ss; sy++)
                for (int sx = 0; sx < ss; sx++) {
                    sample_taps(r->src, r->xt[x * ss + sx], r->yt[y * ss + sy], px);
                    for (int c = 0; c < nc; c++) acc[c] += px[c];
                }
            float *o = r->dst->data + ((size_t)y * size + x) * nc;
            for (int c = 0; c < nc; c++) o[c] = acc[c] / (float)(ss * ss);
        }
}

int mx_crop_resize(const mx_image *src, mx_crop crop, int size, mx_pool *pool, mx_image *dst, mx_status *st) {
    if (size <= 0 || crop.size <= 0 || src->c > 4)
        return mx_fail(st, MX_EINPUT, "crop resize: bad size %d or crop %d", size, crop.size);
    float scale = (float)crop.size / (float)size;
    /* supersample when shrinking so that every source pixel contributes (area filter) */
    int ss = (int)ceilf(scale);
    if (ss < 1) ss = 1;
    axis_tap *xt = malloc(sizeof *xt * 2 * (size_t)size * ss), *yt = xt ? xt + (size_t)size * ss : NULL;
    if (!xt) return mx_fail(st, MX_ENOMEM, "crop resize: out of memory");
    if (mx_image_alloc(dst, size, size, src->c, st)) {
        free(xt);
        return -1;
    }
    for (int x = 0; x < size; x++)
        for (int k = 0; k < ss; k++) {
            float o = ((float)x + ((float)k + 0.5f) / (float)ss) * scale;
            xt[x * ss + k] = tap_at((float)crop.x0 + o, src->w);
            yt[x * ss + k] = tap_at((float)crop.y0 + o, src->h);
        }
    resize_job r = {src, dst, xt, yt, ss};
    mx_pool_for(pool, (size + CROP_ROWS_PER_TASK - 1) / CROP_ROWS_PER_TASK, resize_rows, &r);
    free(xt);
    return 0;
}

/* mx_crop_paste's work: the box of dst it writes ([x0, x1) x [y0, y1)), the rows of a task. */
typedef struct paste_job {
    const mx_image *src;
    mx_image *dst;
    mx_crop crop;
    int x0, x1, y0, y1, nc;
    float scale;
} paste_job;

static void paste_rows(void *arg, int task, int thread) {
    (void)thread;
    const paste_job *p = arg;
    float px[4];
    for (int y = p->y0 + task * CROP_ROWS_PER_TASK; y < p->y0 + (task + 1) * CROP_ROWS_PER_TASK && y < p->y1; y++) {
        axis_tap ty = tap_at(((float)(y - p->crop.y0) + 0.5f) * p->scale, p->src->h);
        for (int x = p->x0; x < p->x1; x++) {
            sample_taps(p->src, tap_at(((float)(x - p->crop.x0) + 0.5f) * p->scale, p->src->w), ty, px);
            float *o = p->dst->data + ((size_t)y * p->dst->w + x) * p->dst->c;
            for (int k = 0; k < p->nc; k++) o[k] = px[k];
        }
    }
}

void mx_crop_paste(const mx_image *src, mx_crop crop, mx_pool *pool, mx_image *dst) {
    paste_job p = {.src = src,
                   .dst = dst,
                   .crop = crop,
                   .x0 = crop.x0 < 0 ? 0 : crop.x0,
                   .x1 = crop.x0 + crop.size < dst->w ? crop.x0 + crop.size : dst->w,
                   .y0 = crop.y0 < 0 ? 0 : crop.y0,
                   .y1 = crop.y0 + crop.size < dst->h ? crop.y0 + crop.size : dst->h,
                   .nc = src->c < dst->c ? src->c : dst->c,
                   .scale = (float)src->w / (float)crop.size};
    if (p.y1 > p.y0 && p.x1 > p.x0)
        mx_pool_for(pool, (p.y1 - p.y0 + CROP_ROWS_PER_TASK - 1) / CROP_ROWS_PER_TASK, paste_rows, &p);
}
