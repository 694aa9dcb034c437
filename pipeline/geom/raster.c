#include "raster.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Sub-pixel precision of snapped vertices: 8 bits. Vertices farther than GUARD image
 * sizes from the image are not rasterized (their faces are dropped), which keeps the
 * integer edge functions far from overflow; a normalised mesh seen by a fitted camera
 * never comes near it. Perspective faces with a corner behind the eye are dropped too
 * (no near clipping: cameras orbit outside the unit sphere). */
#define SUBPIX_BITS 8
#define SUBPIX (1 << SUBPIX_BITS)
#define GUARD 16
#define TILE 32
#define FACES_PER_CHUNK 4096

typedef struct raster_scratch {
    size_t vert_cap, face_cap, count_cap, bin_cap, tile_cap;
    float *vz;          /* [nverts] depth */
    int64_t *vxy;       /* [nverts][2] snapped position */
    uint8_t *vok;       /* [nverts] projected inside the guard band */
    int16_t *face_tiles; /* [nfaces][4] tx0, ty0, tx1, ty1; tx0 > tx1 when dropped */
    int32_t *counts;    /* [nchunks][ntiles] */
    int32_t *bin_start; /* [ntiles + 1] */
    int32_t *bin_faces; /* [total] face ids per tile, ascending */
} raster_scratch;

static int grow(void **p, size_t *cap, size_t need, size_t elem, mx_status *st) {
    if (need <= *cap) return 0;
    void *q = realloc(*p, need * elem);
    if (!q) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory (%zu bytes)", need * elem);
    *p = q;
    *cap = need;
    return 0;
}

int mx_gbuffer_init(mx_gbuffer *gb, int w, int h, mx_status *st) {
    memset(gb, 0, sizeof *gb);
    if (w <= 0 || h <= 0 || w > 16384 || h > 16384)
        return mx_fail(st, MX_EINPUT, "rasterizer: bad image size %dx%d", w, h);
    size_t n = (size_t)w * h;
    gb->w = w;
    gb->h = h;
    gb->face = malloc(n * sizeof *gb->face);
    gb->depth = malloc(n * sizeof *gb->depth);
    gb->bary = malloc(2 * n * sizeof *gb->bary);
    gb->scratch = calloc(1, sizeof(raster_scratch));
    if (!gb->face || !gb->depth || !gb->bary || !gb->scratch) {
        mx_gbuffer_free(gb);
        return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory for a %dx%d buffer", w, h);
    }
    return 0;
}

void mx_gbuffer_free(mx_gbuffer *gb) {
    raster_scratch *s = gb->scratch;
    if (s) {
        free(s->vz);
        free(s->vxy);
        free(s->vok);
        free(s->face_tiles);
        free(s->counts);
        free(s->bin_start);
        free(s->bin_faces);
        free(s);
    }
    free(gb->face);
    free(gb->depth);
    free(gb->bary);
    free(gb->uv);
    free(gb->face_normal);
    memset(gb, 0, sizeof *gb);
}

typedef struct raster_job {
    const mx_mesh *m;
    const float *pos;
    const mx_camera *cam;
    int flags;
    mx_gbuffer *gb;
    raster_scratch *s;
    int tiles_x, tiles_y, nchunks;
} raster_job;

static void project_vertices_task(void *ctx, int task, int thread) {
    (void)thread;
    raster_job *j = ctx;
    raster_scratch *s = j->s;
    int v0 = task * FACES_PER_CHUNK, v1 = v0 + FACES_PER_CHUNK;
    if (v1 > j->m->nverts) v1 = j->m->nverts;
    double lim = (double)GUARD * (j->gb->w > j->gb->h ? j->gb->w : j->gb->h);
    for (int v = v0; v < v1; v++) {
        float p[3];
        int ok = mx_camera_project(j->cam, j->pos + 3 * (size_t)v, j->gb->w, j->gb->h, p);
        ok = ok && isfinite(p[0]) && isfinite(p[1]) && isfinite(p[2]) && fabs(p[0]) < lim &&
             fabs(p[1]) < lim;
        s->vok[v] = (uint8_t)ok;
        s->vz[v] = p[2];
        s->vxy[2 * (size_t)v] = ok ? llround((double)p[0] * SUBPIX) : 0;
        s->vxy[2 * (size_t)v + 1] = ok ? llround((double)p[1] * SUBPIX) : 0;
    }
}

static int64_t edge_fn(int64_t ax, int64_t ay, int64_t bx, int64_t by, int64_t px, int64_t py) {
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

/* Signed doubled area of the snapped triangle; > 0 means clockwise as the camera sees
 * it (image y points down), i.e. a back face for counter-clockwise front faces. */
static int64_t face_area(const raster_scratch *s, const int32_t *f) {
    const int64_t *a = s->vxy + 2 * (size_t)f[0], *b = s->vxy + 2 * (size_t)f[1],
                  *c = s->vxy + 2 * (size_t)f[2];
    return edge_fn(a[0], a[1], b[0], b[1], c[0], c[1]);
}

static int64_t min3(int64_t a, int64_t b, int64_t c) {
    return a < b ? (a < c ? a : c) : (b < c ? b : c);
}
static int64_t max3(int64_t a, int64_t b, int64_t c) {
    return a > b ? (a > c ? a : c) : (b > c ? b : c);
}

/* Pixel-centre range [p0, p1] covered by the snapped interval [lo, hi]. */
static void pixel_range(int64_t lo, int64_t hi, int n, int *p0, int *p1) {
    int64_t a = (lo - SUBPIX / 2 + SUBPIX - 1);
    a = a >= 0 ? a / SUBPIX : -((-a + SUBPIX - 1) / SUBPIX);
    int64_t b = hi - SUBPIX / 2;
    b = b >= 0 ? b / SUBPIX : -((-b + SUBPIX - 1) / SUBPIX);
    if (a < 0) a = 0;
    if (b > n - 1) b = n - 1;
    *p0 = (int)a;
    *p1 = (int)b;
}

/* Decides whether a face is drawn and which tiles its bounding box touches. */
static void setup_face(const raster_job *j, int f, int16_t *tiles) {
    const raster_scratch *s = j->s;
    const int32_t *fv = j->m->faces + 3 * (size_t)f;
    tiles[0] = 1;
    tiles[2] = 0;
    if (!s->vok[fv[0]] || !s->vok[fv[1]] || !s->vok[fv[2]]) return;
    int64_t area = face_area(s, fv);
    if (area == 0 || (area > 0 && (j->flags & MX_RASTER_CULL_BACK))) return;
    const int64_t *a = s->vxy + 2 * (size_t)fv[0], *b = s->vxy + 2 * (size_t)fv[1],
                  *c = s->vxy + 2 * (size_t)fv[2];
    int x0, x1, y0, y1;
    pixel_range(min3(a[0], b[0], c[0]), max3(a[0], b[0], c[0]), j->gb->w, &x0, &x1);
    pixel_range(min3(a[1], b[1], c[1]), max3(a[1], b[1], c[1]), j->gb->h, &y0, &y1);
    if (x0 > x1 || y0 > y1) return;
    tiles[0] = (int16_t)(x0 / TILE);
    tiles[1] = (int16_t)(y0 / TILE);
    tiles[2] = (int16_t)(x1 / TILE);
    tiles[3] = (int16_t)(y1 / TILE);
}

static void count_bins_task(void *ctx, int task, int thread) {
    (void)thread;
    raster_job *j = ctx;
    raster_scratch *s = j->s;
    int ntiles = j->tiles_x * j->tiles_y;
    int32_t *cnt = s->counts + (size_t)task * ntiles;
    memset(cnt, 0, (size_t)ntiles * sizeof *cnt);
    int f0 = task * FACES_PER_CHUNK, f1 = f0 + FACES_PER_CHUNK;
    if (f1 > j->m->nfaces) f1 = j->m->nfaces;
    for (int f = f0; f < f1; f++) {
        int16_t *t = s->face_tiles + 4 * (size_t)f;
        setup_face(j, f, t);
        for (int ty = t[1]; t[0] <= t[2] && ty <= t[3]; ty++)
            for (int tx = t[0]; tx <= t[2]; tx++) cnt[ty * j->tiles_x + tx]++;
    }
}

/* counts[chunk][tile] becomes the write offset of that chunk in that tile's list. */
static int64_t prefix_bins(raster_job *j) {
    raster_scratch *s = j->s;
    int ntiles = j->tiles_x * j->tiles_y;
    int64_t total = 0;
    for (int t = 0; t < ntiles; t++) {
        s->bin_start[t] = (int32_t)total;
        for (int c = 0; c < j->nchunks; c++) {
            int32_t n = s->counts[(size_t)c * ntiles + t];
            s->counts[(size_t)c * ntiles + t] = (int32_t)total;
            total += n;
            if (total > INT32_MAX) return -1;
        }
    }
    s->bin_start[ntiles] = (int32_t)total;
    return total;
}

static void fill_bins_task(void *ctx, int task, int thread) {
    (void)thread;
    raster_job *j = ctx;
    raster_scratch *s = j->s;
    int ntiles = j->tiles_x * j->tiles_y;
    int32_t *off = s->counts + (size_t)task * ntiles;
    int f0 = task * FACES_PER_CHUNK, f1 = f0 + FACES_PER_CHUNK;
    if (f1 > j->m->nfaces) f1 = j->m->nfaces;
    for (int f = f0; f < f1; f++) {
        const int16_t *t = s->face_tiles + 4 * (size_t)f;
        for (int ty = t[1]; t[0] <= t[2] && ty <= t[3]; ty++)
            for (int tx = t[0]; tx <= t[2]; tx++) s->bin_faces[off[ty * j->tiles_x + tx]++] = f;
    }
}

/* Draws one face into the pixels of the tile [tx0, tx1] x [ty0, ty1]. */
static void draw_face(const raster_job *j, int f, int tx0, int ty0, int tx1, int ty1) {
    const raster_scratch *s = j->s;
    mx_gbuffer *gb = j->gb;
    const int32_t *fv = j->m->faces + 3 * (size_t)f;
    int i0 = fv[0], i1 = fv[1], i2 = fv[2];
    int64_t area = face_area(s, fv);
    int swapped = area < 0; /* make the area positive: inside is then w > 0 */
    if (swapped) {
        int t = i1;
        i1 = i2;
        i2 = t;
        area = -area;
    }
    const int64_t *a = s->vxy + 2 * (size_t)i0, *b = s->vxy + 2 * (size_t)i1,
                  *c = s->vxy + 2 * (size_t)i2;
    int x0, x1, y0, y1;
    pixel_range(min3(a[0], b[0], c[0]), max3(a[0], b[0], c[0]), gb->w, &x0, &x1);
    pixel_range(min3(a[1], b[1], c[1]), max3(a[1], b[1], c[1]), gb->h, &y0, &y1);
    if (x0 < tx0) x0 = tx0;
    if (y0 < ty0) y0 = ty0;
    if (x1 > tx1) x1 = tx1;
    if (y1 > ty1) y1 = ty1;
    if (x0 > x1 || y0 > y1) return;
    /* edge k is opposite corner k; w_k(p) = (e.dx)(p.y - e.y) - (e.dy)(p.x - e.x) */
    const int64_t *ea[3] = {b, c, a}, *eb[3] = {c, a, b};
    int64_t dx[3], dy[3], row[3], bias[3];
    int64_t px = (int64_t)x0 * SUBPIX + SUBPIX / 2, py = (int64_t)y0 * SUBPIX + SUBPIX / 2;
    for (int k = 0; k < 3; k++) {
        dx[k] = eb[k][0] - ea[k][0];
        dy[k] = eb[k][1] - ea[k][1];
        row[k] = edge_fn(ea[k][0], ea[k][1], eb[k][0], eb[k][1], px, py);
        /* top-left rule: pixel centres exactly on a top or left edge belong to the face */
        int top_left = dy[k] < 0 || (dy[k] == 0 && dx[k] > 0);
        bias[k] = top_left ? 0 : 1;
    }
    float z0 = s->vz[i0], z1 = s->vz[i1], z2 = s->vz[i2];
    int persp = !j->cam->ortho;
    double inv_area = 1.0 / (double)area;
    for (int y = y0; y <= y1; y++) {
        int64_t w0 = row[0], w1 = row[1], w2 = row[2];
        for (int x = x0; x <= x1; x++) {
            if (w0 >= bias[0] && w1 >= bias[1] && w2 >= bias[2]) {
                float b0 = (float)((double)w0 * inv_area), b1 = (float)((double)w1 * inv_area);
                float b2 = 1.0f - b0 - b1;
                float z;
                if (persp) {
                    float q0 = b0 / z0, q1 = b1 / z1, q2 = b2 / z2, iz = q0 + q1 + q2;
                    z = 1.0f / iz;
                    b1 = q1 * z;
                    b2 = q2 * z;
                } else {
                    z = b0 * z0 + b1 * z1 + b2 * z2;
                }
                size_t i = (size_t)y * gb->w + x;
                if (z < gb->depth[i]) {
                    gb->depth[i] = z;
                    gb->face[i] = f;
                    /* back to the face's own corner order */
                    gb->bary[2 * i] = swapped ? b2 : b1;
                    gb->bary[2 * i + 1] = swapped ? b1 : b2;
                }
            }
            w0 -= dy[0] * SUBPIX;
            w1 -= dy[1] * SUBPIX;
            w2 -= dy[2] * SUBPIX;
        }
        row[0] += dx[0] * SUBPIX;
        row[1] += dx[1] * SUBPIX;
        row[2] += dx[2] * SUBPIX;
    }
}

static void draw_tile_task(void *ctx, int task, int thread) {
    (void)thread;
    raster_job *j = ctx;
    mx_gbuffer *gb = j->gb;
    int tx = task % j->tiles_x, ty = task / j->tiles_x;
    int x0 = tx * TILE, y0 = ty * TILE;
    int x1 = x0 + TILE - 1 < gb->w - 1 ? x0 + TILE - 1 : gb->w - 1;
    int y1 = y0 + TILE - 1 < gb->h - 1 ? y0 + TILE - 1 : gb->h - 1;
    for (int y = y0; y <= y1; y++)
        for (int x = x0; x <= x1; x++) {
            size_t i = (size_t)y * gb->w + x;
            gb->face[i] = -1;
            gb->depth[i] = INFINITY;
            gb->bary[2 * i] = gb->bary[2 * i + 1] = 0;
        }
    const raster_scratch *s = j->s;
    for (int32_t k = s->bin_start[task]; k < s->bin_start[task + 1]; k++)
        draw_face(j, s->bin_faces[k], x0, y0, x1, y1);
}

static void face_normals_task(void *ctx, int task, int thread) {
    (void)thread;
    raster_job *j = ctx;
    int f0 = task * FACES_PER_CHUNK, f1 = f0 + FACES_PER_CHUNK;
    if (f1 > j->m->nfaces) f1 = j->m->nfaces;
    for (int f = f0; f < f1; f++) {
        const int32_t *fv = j->m->faces + 3 * (size_t)f;
        const float *a = j->pos + 3 * (size_t)fv[0], *b = j->pos + 3 * (size_t)fv[1],
                    *c = j->pos + 3 * (size_t)fv[2];
        double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                       e1[0] * e2[1] - e1[1] * e2[0]};
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        float *o = j->gb->face_normal + 3 * (size_t)f;
        for (int k = 0; k < 3; k++) o[k] = len > 0 ? (float)(n[k] / len) : 0.0f;
    }
}

#define UV_ROWS 16
static void resolve_uv_task(void *ctx, int task, int thread) {
    (void)thread;
    raster_job *j = ctx;
    mx_gbuffer *gb = j->gb;
    const mx_mesh *m = j->m;
    int y0 = task * UV_ROWS, y1 = y0 + UV_ROWS < gb->h ? y0 + UV_ROWS : gb->h;
    for (size_t i = (size_t)y0 * gb->w; i < (size_t)y1 * gb->w; i++) {
        int f = gb->face[i];
        if (f < 0) {
            gb->uv[2 * i] = gb->uv[2 * i + 1] = 0;
            continue;
        }
        const int32_t *fu = m->face_uv + 3 * (size_t)f;
        if (fu[0] < 0 || fu[1] < 0 || fu[2] < 0) { /* a face without UVs: no texel */
            gb->uv[2 * i] = gb->uv[2 * i + 1] = NAN;
            continue;
        }
        float b1 = gb->bary[2 * i], b2 = gb->bary[2 * i + 1], b0 = 1.0f - b1 - b2;
        const float *u0 = m->uv + 2 * (size_t)fu[0], *u1 = m->uv + 2 * (size_t)fu[1],
                    *u2 = m->uv + 2 * (size_t)fu[2];
        gb->uv[2 * i] = b0 * u0[0] + b1 * u1[0] + b2 * u2[0];
        gb->uv[2 * i + 1] = b0 * u0[1] + b1 * u1[1] + b2 * u2[1];
    }
}

static int check_mesh(const mx_mesh *m, mx_status *st) {
    for (size_t k = 0; k < 3 * (size_t)m->nfaces; k++)
        if (m->faces[k] < 0 || m->faces[k] >= m->nverts)
            return mx_fail(st, MX_EINPUT, "%s: face %zu uses vertex %d of %d", m->source_path,
                           k / 3, m->faces[k], m->nverts);
    if (m->face_uv)
        for (size_t k = 0; k < 3 * (size_t)m->nfaces; k++)
            if (m->face_uv[k] < -1 || m->face_uv[k] >= m->nuv) /* -1: corner without UV */
                return mx_fail(st, MX_EINPUT, "%s: face %zu uses UV %d of %d", m->source_path,
                               k / 3, m->face_uv[k], m->nuv);
    return 0;
}

static int reserve_scratch(raster_job *j, mx_status *st) {
    raster_scratch *s = j->s;
    size_t nv = (size_t)j->m->nverts + 1, nf = (size_t)j->m->nfaces + 1;
    size_t ntiles = (size_t)j->tiles_x * j->tiles_y;
    if (nv > s->vert_cap) {
        free(s->vz);
        free(s->vxy);
        free(s->vok);
        s->vz = malloc(nv * sizeof *s->vz);
        s->vxy = malloc(2 * nv * sizeof *s->vxy);
        s->vok = malloc(nv * sizeof *s->vok);
        s->vert_cap = s->vz && s->vxy && s->vok ? nv : 0;
        if (!s->vert_cap) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    if (grow((void **)&s->face_tiles, &s->face_cap, 4 * nf, sizeof *s->face_tiles, st)) return -1;
    if (grow((void **)&s->counts, &s->count_cap, (size_t)j->nchunks * ntiles + 1,
             sizeof *s->counts, st))
        return -1;
    return grow((void **)&s->bin_start, &s->tile_cap, ntiles + 1, sizeof *s->bin_start, st);
}

static int reserve_outputs(raster_job *j, mx_status *st) {
    mx_gbuffer *gb = j->gb;
    if (gb->nfaces != j->m->nfaces || !gb->face_normal) {
        free(gb->face_normal);
        gb->face_normal = malloc(3 * ((size_t)j->m->nfaces + 1) * sizeof *gb->face_normal);
        gb->nfaces = j->m->nfaces;
        if (!gb->face_normal) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    if ((j->flags & MX_RASTER_UV) && j->m->face_uv && !gb->uv) {
        gb->uv = malloc(2 * (size_t)gb->w * gb->h * sizeof *gb->uv);
        if (!gb->uv) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    return 0;
}

int mx_rasterize(const mx_mesh *m, const float *pos, const mx_camera *cam, int flags,
                 mx_pool *pool, mx_gbuffer *gb, mx_status *st) {
    if (check_mesh(m, st)) return -1;
    raster_job j = {m, pos ? pos : m->pos, cam, flags, gb, gb->scratch, 0, 0, 0};
    j.tiles_x = (gb->w + TILE - 1) / TILE;
    j.tiles_y = (gb->h + TILE - 1) / TILE;
    j.nchunks = (m->nfaces > m->nverts ? m->nfaces : m->nverts) / FACES_PER_CHUNK + 1;
    if (reserve_scratch(&j, st) || reserve_outputs(&j, st)) return -1;
    gb->cam = *cam;
    int vchunks = m->nverts / FACES_PER_CHUNK + 1, fchunks = m->nfaces / FACES_PER_CHUNK + 1;
    mx_pool_for(pool, vchunks, project_vertices_task, &j);
    mx_pool_for(pool, fchunks, count_bins_task, &j);
    for (int c = fchunks; c < j.nchunks; c++)
        memset(j.s->counts + (size_t)c * j.tiles_x * j.tiles_y, 0,
               (size_t)j.tiles_x * j.tiles_y * sizeof(int32_t));
    int64_t total = prefix_bins(&j);
    if (total < 0) return mx_fail(st, MX_EINPUT, "%s: too many face-tile pairs", m->source_path);
    if (grow((void **)&j.s->bin_faces, &j.s->bin_cap, (size_t)total + 1, sizeof(int32_t), st))
        return -1;
    mx_pool_for(pool, fchunks, fill_bins_task, &j);
    mx_pool_for(pool, j.tiles_x * j.tiles_y, draw_tile_task, &j);
    mx_pool_for(pool, fchunks, face_normals_task, &j);
    if ((flags & MX_RASTER_UV) && m->face_uv)
        mx_pool_for(pool, (gb->h + UV_ROWS - 1) / UV_ROWS, resolve_uv_task, &j);
    return 0;
}

void mx_gbuffer_normal(const mx_gbuffer *gb, int64_t i, float out[3]) {
    int f = gb->face[i];
    for (int k = 0; k < 3; k++) out[k] = f >= 0 ? gb->face_normal[3 * (size_t)f + k] : 0.0f;
}

void mx_texture_sample(const mx_image *img, float u, float v, float *out) {
    float fx = u * (float)img->w - 0.5f, fy = (1.0f - v) * (float)img->h - 0.5f;
    float flx = floorf(fx), fly = floorf(fy);
    float tx = fx - flx, ty = fy - fly;
    /* repeat wrapping; fmod keeps huge UVs from overflowing the int conversion */
    int x0 = (int)fmodf(flx, (float)img->w), y0 = (int)fmodf(fly, (float)img->h);
    if (x0 < 0) x0 += img->w;
    if (y0 < 0) y0 += img->h;
    int x1 = x0 + 1 == img->w ? 0 : x0 + 1, y1 = y0 + 1 == img->h ? 0 : y0 + 1;
    const float *p00 = img->data + ((size_t)y0 * img->w + x0) * img->c;
    const float *p01 = img->data + ((size_t)y0 * img->w + x1) * img->c;
    const float *p10 = img->data + ((size_t)y1 * img->w + x0) * img->c;
    const float *p11 = img->data + ((size_t)y1 * img->w + x1) * img->c;
    for (int c = 0; c < img->c; c++)
        out[c] = (p00[c] * (1 - tx) + p01[c] * tx) * (1 - ty) + (p10[c] * (1 - tx) + p11[c] * tx) * ty;
}

typedef struct textured_job {
    const mx_gbuffer *gb;
    const mx_mesh *m;
    const mx_image *tex;
    int ntex;
    const float *bg;
    mx_image *out;
} textured_job;

static void render_textured_task(void *ctx, int task, int thread) {
    (void)thread;
    textured_job *j = ctx;
    const mx_gbuffer *gb = j->gb;
    int y0 = task * UV_ROWS, y1 = y0 + UV_ROWS < gb->h ? y0 + UV_ROWS : gb->h;
    for (size_t i = (size_t)y0 * gb->w; i < (size_t)y1 * gb->w; i++) {
        float *o = j->out->data + 3 * i;
        int f = gb->face[i];
        if (f < 0) {
            o[0] = j->bg[0];
            o[1] = j->bg[1];
            o[2] = j->bg[2];
            continue;
        }
        int mat = j->m->face_mat ? j->m->face_mat[f] : 0;
        const mx_image *t = mat >= 0 && mat < j->ntex ? &j->tex[mat] : NULL;
        if (!t || !t->data || !gb->uv || !isfinite(gb->uv[2 * i]) || !isfinite(gb->uv[2 * i + 1])) {
            o[0] = o[1] = o[2] = 0.5f;
            continue;
        }
        float px[4] = {0, 0, 0, 0};
        mx_texture_sample(t, gb->uv[2 * i], gb->uv[2 * i + 1], px);
        if (t->c < 3) px[1] = px[2] = px[0];
        o[0] = px[0];
        o[1] = px[1];
        o[2] = px[2];
    }
}

int mx_render_textured(const mx_gbuffer *gb, const mx_mesh *m, const mx_image *textures, int ntex,
                       const float background[3], mx_pool *pool, mx_image *out, mx_status *st) {
    for (int k = 0; k < ntex; k++)
        if (textures[k].data && (textures[k].w <= 0 || textures[k].h <= 0 || textures[k].c > 4))
            return mx_fail(st, MX_EINPUT, "render: texture %d has a bad shape", k);
    if (mx_image_alloc(out, gb->w, gb->h, 3, st)) return -1;
    textured_job j = {gb, m, textures, ntex, background, out};
    mx_pool_for(pool, (gb->h + UV_ROWS - 1) / UV_ROWS, render_textured_task, &j);
    return 0;
}

int mx_render_normals(const mx_gbuffer *gb, const float background[3], mx_image *out, mx_status *st) {
    if (mx_image_alloc(out, gb->w, gb->h, 3, st)) return -1;
    float view[3] = {-gb->cam.forward[0], -gb->cam.forward[1], -gb->cam.forward[2]};
    for (size_t i = 0; i < (size_t)gb->w * gb->h; i++) {
        float *o = out->data + 3 * i;
        if (gb->face[i] < 0) {
            for (int k = 0; k < 3; k++) o[k] = background[k];
            continue;
        }
        float n[3];
        mx_gbuffer_normal(gb, (int64_t)i, n);
        float lit = fabsf(n[0] * view[0] + n[1] * view[1] + n[2] * view[2]);
        /* normal colour (n * 0.5 + 0.5) shaded by the head light */
        for (int k = 0; k < 3; k++) o[k] = (0.5f * n[k] + 0.5f) * (0.35f + 0.65f * lit);
    }
    return 0;
}
