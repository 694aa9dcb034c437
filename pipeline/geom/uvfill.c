#include "uvfill.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static void mark_texel(uint8_t *chart, int w, int h, int x, int y) {
    x %= w;
    y %= h;
    if (x < 0) x += w;
    if (y < 0) y += h;
    chart[(size_t)y * w + x] = 1;
}

/* Marks texels whose centre lies within half a texel of the triangle (texel coordinates). */
static void mark_triangle(uint8_t *chart, int w, int h, const float p[3][2]) {
    float minx = fminf(p[0][0], fminf(p[1][0], p[2][0])), maxx = fmaxf(p[0][0], fmaxf(p[1][0], p[2][0]));
    float miny = fminf(p[0][1], fminf(p[1][1], p[2][1])), maxy = fmaxf(p[0][1], fmaxf(p[1][1], p[2][1]));
    /* NaN, absurdly far (int conversion) or absurdly large (loop length): skip */
    if (!(maxx - minx < 4.0f * w && maxy - miny < 4.0f * h && fabsf(minx) < 1e8f && fabsf(miny) < 1e8f))
        return;
    double area = (double)(p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) -
                  (double)(p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
    double sgn = area < 0 ? -1.0 : 1.0;
    double len[3];
    for (int k = 0; k < 3; k++) {
        const float *a = p[k], *b = p[(k + 1) % 3];
        len[k] = hypot(b[0] - a[0], b[1] - a[1]);
    }
    for (int y = (int)floorf(miny - 1); y <= (int)ceilf(maxy + 1); y++)
        for (int x = (int)floorf(minx - 1); x <= (int)ceilf(maxx + 1); x++) {
            double cx = x + 0.5, cy = y + 0.5;
            int in = 1;
            for (int k = 0; k < 3 && in; k++) {
                const float *a = p[k], *b = p[(k + 1) % 3];
                double e = ((b[0] - a[0]) * (cy - a[1]) - (b[1] - a[1]) * (cx - a[0])) * sgn;
                /* signed distance (positive inside); degenerate edges only test the others */
                in = len[k] == 0 || e / len[k] >= -0.5;
            }
            if (in && area != 0) mark_texel(chart, w, h, x, y);
        }
}

int mx_uv_chart_mask(const mx_mesh *m, int layer, int nlayers, int w, int h, uint8_t *chart,
                     mx_status *st) {
    if (!m->face_uv) return mx_fail(st, MX_EINPUT, "%s: no UVs to find charts in", m->source_path);
    memset(chart, 0, (size_t)w * h);
    for (int f = 0; f < m->nfaces; f++) {
        int mat = m->face_mat ? m->face_mat[f] : 0;
        if (mat < 0 || mat >= nlayers) mat = 0;
        if (nlayers > 1 && mat != layer) continue;
        const int32_t *fu = m->face_uv + 3 * (size_t)f;
        if (fu[0] < 0 || fu[1] < 0 || fu[2] < 0 || fu[0] >= m->nuv || fu[1] >= m->nuv || fu[2] >= m->nuv)
            continue;
        float p[3][2];
        for (int k = 0; k < 3; k++) {
            p[k][0] = m->uv[2 * (size_t)fu[k]] * (float)w;
            p[k][1] = (1.0f - m->uv[2 * (size_t)fu[k] + 1]) * (float)h;
        }
        mark_triangle(chart, w, h, p);
    }
    return 0;
}

typedef struct level {
    int w, h;
    float *c; /* [h][w][3] premultiplied sums, then normalised colour */
    float *a; /* [h][w] weight */
} level;

/* Bilinear sample of a filled level at the position of texel (x, y) of the level below. */
static void sample_coarse(const level *L, int x, int y, float out[3]) {
    float fx = ((float)x + 0.5f) * 0.5f - 0.5f, fy = ((float)y + 0.5f) * 0.5f - 0.5f;
    int x0 = (int)floorf(fx), y0 = (int)floorf(fy);
    float tx = fx - (float)x0, ty = fy - (float)y0;
    int xs[2] = {x0 < 0 ? 0 : x0, x0 + 1 >= L->w ? L->w - 1 : x0 + 1};
    int ys[2] = {y0 < 0 ? 0 : y0, y0 + 1 >= L->h ? L->h - 1 : y0 + 1};
    if (xs[0] >= L->w) xs[0] = L->w - 1;
    if (ys[0] >= L->h) ys[0] = L->h - 1;
    for (int k = 0; k < 3; k++) {
        float a = L->c[3 * ((size_t)ys[0] * L->w + xs[0]) + k], b = L->c[3 * ((size_t)ys[0] * L->w + xs[1]) + k];
        float c = L->c[3 * ((size_t)ys[1] * L->w + xs[0]) + k], d = L->c[3 * ((size_t)ys[1] * L->w + xs[1]) + k];
        out[k] = (a * (1 - tx) + b * tx) * (1 - ty) + (c * (1 - tx) + d * tx) * ty;
    }
}

static void pull_down(const level *fine, level *coarse) {
    for (int y = 0; y < coarse->h; y++)
        for (int x = 0; x < coarse->w; x++) {
            float c[3] = {0, 0, 0}, a = 0;
            for (int dy = 0; dy < 2; dy++)
                for (int dx = 0; dx < 2; dx++) {
                    int fx = 2 * x + dx, fy = 2 * y + dy;
                    if (fx >= fine->w || fy >= fine->h) continue;
                    size_t i = (size_t)fy * fine->w + fx;
                    a += fine->a[i];
                    for (int k = 0; k < 3; k++) c[k] += fine->c[3 * i + k];
                }
            size_t o = (size_t)y * coarse->w + x;
            coarse->a[o] = a;
            for (int k = 0; k < 3; k++) coarse->c[3 * o + k] = c[k];
        }
}

/* Normalises a level, then fills its empty texels from the (filled) coarser level. */
static void push_up(level *L, const level *coarser) {
    for (size_t i = 0; i < (size_t)L->w * L->h; i++) {
        if (L->a[i] > 0) {
            for (int k = 0; k < 3; k++) L->c[3 * i + k] /= L->a[i];
        } else if (coarser) {
            sample_coarse(coarser, (int)(i % (size_t)L->w), (int)(i / (size_t)L->w), L->c + 3 * i);
        }
    }
}

static void free_levels(level *lv, int n) {
    for (int k = 0; k < n; k++) {
        free(lv[k].c);
        free(lv[k].a);
    }
}

/* Push-pull colours for all texels into colour (w x h x 3) from the known texels. */
static int push_pull(const mx_image *tex, const uint8_t *known, float *colour, mx_status *st) {
    level lv[32];
    int n = 0, w = tex->w, h = tex->h;
    for (;;) {
        lv[n].w = w;
        lv[n].h = h;
        lv[n].c = malloc((size_t)w * h * 3 * sizeof(float));
        lv[n].a = malloc((size_t)w * h * sizeof(float));
        if (!lv[n].c || !lv[n].a) {
            free_levels(lv, n + 1);
            return mx_fail(st, MX_ENOMEM, "uv fill: out of memory");
        }
        n++;
        if (w == 1 && h == 1) break;
        w = (w + 1) / 2;
        h = (h + 1) / 2;
    }
    for (size_t i = 0; i < (size_t)tex->w * tex->h; i++) {
        lv[0].a[i] = known[i] ? 1.0f : 0.0f;
        for (int k = 0; k < 3; k++) lv[0].c[3 * i + k] = known[i] ? tex->data[3 * i + k] : 0.0f;
    }
    for (int k = 1; k < n; k++) pull_down(&lv[k - 1], &lv[k]);
    for (int k = n - 1; k >= 0; k--) push_up(&lv[k], k + 1 < n ? &lv[k + 1] : NULL);
    memcpy(colour, lv[0].c, (size_t)tex->w * tex->h * 3 * sizeof(float));
    free_levels(lv, n);
    return 0;
}

/* One ring of dilation: texels not valid take the mean of their valid 8-neighbours. */
static void dilate_once(mx_image *tex, uint8_t *valid, uint8_t *next) {
    int w = tex->w, h = tex->h;
    memcpy(next, valid, (size_t)w * h);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            if (valid[i]) continue;
            float c[3] = {0, 0, 0};
            int n = 0;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    int nx = x + dx, ny = y + dy;
                    if (nx < 0 || ny < 0 || nx >= w || ny >= h || !valid[(size_t)ny * w + nx]) continue;
                    for (int k = 0; k < 3; k++) c[k] += tex->data[3 * ((size_t)ny * w + nx) + k];
                    n++;
                }
            if (!n) continue;
            for (int k = 0; k < 3; k++) tex->data[3 * i + k] = c[k] / (float)n;
            next[i] = 1;
        }
    memcpy(valid, next, (size_t)w * h);
}

int mx_uv_fill(mx_image *tex, const uint8_t *known, const uint8_t *chart, int gutter, mx_status *st) {
    if (tex->c != 3) return mx_fail(st, MX_EINPUT, "uv fill: texture must be RGB (has %d channels)", tex->c);
    size_t n = (size_t)tex->w * tex->h;
    int any = 0;
    for (size_t i = 0; i < n && !any; i++) any = known[i];
    if (!any) return 0;
    float *colour = malloc(n * 3 * sizeof(float));
    uint8_t *valid = malloc(n), *next = malloc(n);
    if (!colour || !valid || !next) {
        free(colour), free(valid), free(next);
        return mx_fail(st, MX_ENOMEM, "uv fill: out of memory");
    }
    int rc = push_pull(tex, known, colour, st);
    if (rc == 0) {
        for (size_t i = 0; i < n; i++) {
            if (!known[i] && chart[i])
                for (int k = 0; k < 3; k++) tex->data[3 * i + k] = colour[3 * i + k];
            valid[i] = known[i] || chart[i];
        }
        for (int g = 0; g < gutter; g++) dilate_once(tex, valid, next);
    }
    free(colour), free(valid), free(next);
    return rc;
}

int mx_uv_dilate(mx_image *tex, const uint8_t *known, int rings, mx_status *st) {
    if (tex->c != 3) return mx_fail(st, MX_EINPUT, "uv dilate: texture must be RGB (has %d channels)", tex->c);
    size_t n = (size_t)tex->w * tex->h;
    uint8_t *valid = malloc(n), *next = malloc(n);
    if (!valid || !next) {
        free(valid), free(next);
        return mx_fail(st, MX_ENOMEM, "uv dilate: out of memory");
    }
    memcpy(valid, known, n);
    for (int r = 0; r < rings; r++) dilate_once(tex, valid, next);
    free(valid), free(next);
    return 0;
}
