#include "raster.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/backend.h"
#include "raster_tri.h"

/* Sub-pixel precision of snapped vertices: 8 bits. Vertices farther than GUARD image
 * sizes from the image are not rasterized (their faces are dropped), which keeps the
 * integer edge functions far from overflow; a normalised mesh seen by a fitted camera
 * never comes near it. Perspective faces with a corner behind the eye are dropped too
 * (no near clipping: cameras orbit outside the unit sphere). */
#define SUBPIX_BITS 8
#define SUBPIX (1 << SUBPIX_BITS)
#define GUARD 16
#define TILE 32 /* a multiple of 8: raster_avx2.c steps stay inside a tile */
#define FACES_PER_CHUNK 4096
_Static_assert(TILE % 8 == 0, "AVX2 steps must not cross tiles");
#define ROWS_PER_TASK 16

/* A face as drawn, with everything drawing and resolving need (so that those passes read
 * one record per face instead of gathering vertices from all over memory): corners ordered
 * so that the snapped area is positive (inside: w > 0), their snapped positions (within
 * the guard band, so they fit in 32 bits) and depths, the pixel bounding box, and whether
 * it is a back face. x0 > x1 when the face is not drawn. Tiles get copies in their bins. */
typedef struct face_setup {
    int32_t face;
    int32_t x[3], y[3];
    float z[3]; /* depth (perspective: inverse depth) */
    int32_t uv_index[3]; /* the mesh's face_uv entries (read in face order, with MX_RASTER_UV) */
    int16_t x0, y0, x1, y1;
    uint8_t swapped, back, has_uv;
    uint8_t small; /* snapped box within RASTER_SMALL_EXTENT: the 32-bit SIMD kernel may draw it */
} face_setup;
_Static_assert(sizeof(face_setup) == 64, "a bin entry is one cache line");

typedef struct raster_scratch {
    size_t vert_cap, face_cap, count_cap, bin_cap, tile_cap;
    float *vz;          /* [nverts] depth (perspective: its inverse) */
    int32_t *vxy;       /* [nverts][2] snapped position (within the guard band: fits) */
    uint8_t *vok;       /* [nverts] projected inside the guard band */
    face_setup *faces;  /* [nfaces] */
    float *fnormal;     /* [nfaces][3] unit geometric normals of drawn faces */
    int32_t *counts;    /* [nchunks][ntiles] */
    uint8_t *chunk_bad; /* [nchunks] a face of the chunk has an index out of range */
    size_t chunk_cap;
    int32_t *bin_start; /* [ntiles + 1] */
    face_setup *bins;   /* [total] faces per tile, ascending face id */
} raster_scratch;

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
        free(s->faces);
        free(s->fnormal);
        free(s->counts);
        free(s->chunk_bad);
        free(s->bin_start);
        free(s->bins);
        free(s);
    }
    free(gb->face);
    free(gb->depth);
    free(gb->depth_unculled);
    free(gb->bary);
    free(gb->uv);
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
    int simd; /* draw small triangles with the AVX2 kernel */
} raster_job;

/* llround without the library call, for |v| < 2^52 (the guard band keeps it far below):
 * truncation and the remainder v - t are exact there. */
static int64_t round_half_away(double v) {
    int64_t t = (int64_t)v;
    double frac = v - (double)t;
    return t + (frac >= 0.5) - (frac <= -0.5); /* branch-free: the fraction is random */
}

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
        s->vz[v] = j->cam->ortho ? p[2] : 1.0f / p[2];
        s->vxy[2 * (size_t)v] = ok ? (int32_t)round_half_away((double)p[0] * SUBPIX) : 0;
        s->vxy[2 * (size_t)v + 1] = ok ? (int32_t)round_half_away((double)p[1] * SUBPIX) : 0;
    }
}

static int64_t edge_fn(int64_t ax, int64_t ay, int64_t bx, int64_t by, int64_t px, int64_t py) {
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

static int64_t min3(int64_t a, int64_t b, int64_t c) {
    return a < b ? (a < c ? a : c) : (b < c ? b : c);
}
static int64_t max3(int64_t a, int64_t b, int64_t c) {
    return a > b ? (a > c ? a : c) : (b > c ? b : c);
}

/* Pixel-centre range [p0, p1] covered by the snapped interval [lo, hi]. */
static void pixel_range(int64_t lo, int64_t hi, int n, int *p0, int *p1) {
    /* floor division by SUBPIX, made branch-free by an offset that keeps the dividend
     * positive (snapped coordinates stay within the guard band, far below 2^40) */
    const int64_t off = (int64_t)1 << 40;
    int64_t a = (lo - SUBPIX / 2 + SUBPIX - 1 + off) / SUBPIX - off / SUBPIX;
    int64_t b = (hi - SUBPIX / 2 + off) / SUBPIX - off / SUBPIX;
    if (a < 0) a = 0;
    if (b > n - 1) b = n - 1;
    *p0 = (int)a;
    *p1 = (int)b;
}

/* Decides whether and how a face is drawn. The signed doubled area of the snapped
 * triangle is > 0 when it is clockwise as the camera sees it (image y points down),
 * i.e. a back face for counter-clockwise front faces. */
static void setup_face(const raster_job *j, int f, face_setup *fs) {
    const raster_scratch *s = j->s;
    const int32_t *fv = j->m->faces + 3 * (size_t)f;
    fs->x0 = 1;
    fs->x1 = 0;
    if (!s->vok[fv[0]] || !s->vok[fv[1]] || !s->vok[fv[2]]) return;
    const int32_t *a = s->vxy + 2 * (size_t)fv[0], *b = s->vxy + 2 * (size_t)fv[1],
                  *c = s->vxy + 2 * (size_t)fv[2];
    int64_t area = edge_fn(a[0], a[1], b[0], b[1], c[0], c[1]);
    int keep_back = !(j->flags & MX_RASTER_CULL_BACK) || (j->flags & MX_RASTER_DEPTH_UNCULLED);
    if (area == 0 || (area > 0 && !keep_back)) return;
    int x0, x1, y0, y1;
    int64_t lo_x = min3(a[0], b[0], c[0]), hi_x = max3(a[0], b[0], c[0]);
    int64_t lo_y = min3(a[1], b[1], c[1]), hi_y = max3(a[1], b[1], c[1]);
    pixel_range(lo_x, hi_x, j->gb->w, &x0, &x1);
    pixel_range(lo_y, hi_y, j->gb->h, &y0, &y1);
    if (x0 > x1 || y0 > y1) return;
    fs->small = hi_x - lo_x <= RASTER_SMALL_EXTENT && hi_y - lo_y <= RASTER_SMALL_EXTENT;
    /* make the area positive: swap corners 1 and 2 of front faces */
    fs->face = f;
    fs->swapped = area < 0;
    fs->back = area > 0 && (j->flags & MX_RASTER_CULL_BACK);
    int32_t v[3] = {fv[0], fs->swapped ? fv[2] : fv[1], fs->swapped ? fv[1] : fv[2]};
    for (int k = 0; k < 3; k++) {
        fs->x[k] = s->vxy[2 * (size_t)v[k]];
        fs->y[k] = s->vxy[2 * (size_t)v[k] + 1];
        fs->z[k] = s->vz[v[k]];
    }
    fs->has_uv = 0;
    if ((j->flags & MX_RASTER_UV) && j->m->face_uv) {
        const int32_t *fu = j->m->face_uv + 3 * (size_t)f;
        memcpy(fs->uv_index, fu, sizeof fs->uv_index);
        fs->has_uv = fu[0] >= 0 && fu[1] >= 0 && fu[2] >= 0; /* a face without UVs: no texel */
    }
    fs->x0 = (int16_t)x0;
    fs->y0 = (int16_t)y0;
    fs->x1 = (int16_t)x1;
    fs->y1 = (int16_t)y1;
}

static void face_normal(const raster_job *j, int f, float *out) {
    const int32_t *fv = j->m->faces + 3 * (size_t)f;
    const float *a = j->pos + 3 * (size_t)fv[0], *b = j->pos + 3 * (size_t)fv[1],
                *c = j->pos + 3 * (size_t)fv[2];
    float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    float e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                  e1[0] * e2[1] - e1[1] * e2[0]};
    float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; k++) out[k] = len > 0 ? n[k] / len : 0.0f;
}

/* Whether face f's vertex and UV indices are in range: checked here, where the face is
 * read anyway, instead of in a separate pass over the mesh on every render. */
static int face_indices_ok(const mx_mesh *m, int f) {
    const int32_t *fv = m->faces + 3 * (size_t)f;
    int ok = (uint32_t)fv[0] < (uint32_t)m->nverts && (uint32_t)fv[1] < (uint32_t)m->nverts &&
             (uint32_t)fv[2] < (uint32_t)m->nverts;
    if (m->face_uv) { /* -1: corner without UV */
        const int32_t *fu = m->face_uv + 3 * (size_t)f;
        ok = ok && fu[0] >= -1 && fu[0] < m->nuv && fu[1] >= -1 && fu[1] < m->nuv && fu[2] >= -1 &&
             fu[2] < m->nuv;
    }
    return ok;
}

/* Adds a face to the tile counts (most faces touch one tile: no loop for them). */
static void count_face_tiles(const raster_job *j, const face_setup *fs, int32_t *cnt) {
    int tx0 = fs->x0 / TILE, tx1 = fs->x1 / TILE, ty0 = fs->y0 / TILE, ty1 = fs->y1 / TILE;
    if (tx0 == tx1 && ty0 == ty1) {
        cnt[ty0 * j->tiles_x + tx0]++;
        return;
    }
    for (int ty = ty0; ty <= ty1; ty++)
        for (int tx = tx0; tx <= tx1; tx++) cnt[ty * j->tiles_x + tx]++;
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
    s->chunk_bad[task] = 0;
    for (int f = f0; f < f1; f++) {
        face_setup *fs = s->faces + f;
        if (!face_indices_ok(j->m, f)) {
            s->chunk_bad[task] = 1;
            fs->x0 = 1;
            fs->x1 = 0;
            continue;
        }
        setup_face(j, f, fs);
        if (fs->x0 > fs->x1) continue;
        if (!fs->back) face_normal(j, f, s->fnormal + 3 * (size_t)f); /* culled faces never show */
        count_face_tiles(j, fs, cnt);
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
    const face_setup *faces = j->s->faces;
    face_setup *bins = j->s->bins;
    int ntiles = j->tiles_x * j->tiles_y, tiles_x = j->tiles_x;
    int32_t *off = j->s->counts + (size_t)task * ntiles;
    int f0 = task * FACES_PER_CHUNK, f1 = f0 + FACES_PER_CHUNK;
    if (f1 > j->m->nfaces) f1 = j->m->nfaces;
    for (int f = f0; f < f1; f++) {
        const face_setup *fs = faces + f;
        if (fs->x0 > fs->x1) continue;
        int tx0 = fs->x0 / TILE, tx1 = fs->x1 / TILE, ty0 = fs->y0 / TILE, ty1 = fs->y1 / TILE;
        for (int ty = ty0; ty <= ty1; ty++)
            for (int tx = tx0; tx <= tx1; tx++) bins[off[ty * tiles_x + tx]++] = *fs;
    }
}

/* Scalar reference kernel (and the path for large triangles): depth test, then face id
 * and depth (back faces of a culled pass only reach depth_all). */
static void draw_tri_scalar(const raster_tri *t, const raster_target *o) {
    int64_t row[3] = {t->row[0], t->row[1], t->row[2]};
    for (int y = t->y0; y <= t->y1; y++) {
        int64_t w0 = row[0], w1 = row[1], w2 = row[2];
        size_t i = (size_t)y * o->w + t->x0;
        for (int x = t->x0; x <= t->x1; x++, i++) {
            if (w0 >= t->bias[0] && w1 >= t->bias[1] && w2 >= t->bias[2]) {
                /* orthographic: depth is affine in the image; perspective: its inverse is */
                float z = t->z0 + (float)w1 * t->inv_area * t->dz1 + (float)w2 * t->inv_area * t->dz2;
                if (t->persp) z = 1.0f / z;
                if (o->depth_all && z < o->depth_all[i]) o->depth_all[i] = z;
                if (!t->back && z < o->depth[i]) {
                    o->depth[i] = z;
                    o->face[i] = t->face;
                }
            }
            w0 += t->step_x[0];
            w1 += t->step_x[1];
            w2 += t->step_x[2];
        }
        for (int k = 0; k < 3; k++) row[k] += t->step_y[k];
    }
}

/* Sets up one face clipped to the tile [tx0, tx1] x [ty0, ty1]; 0 when nothing is left. */
static int clip_face(const raster_job *j, const face_setup *f, int tx0, int ty0, int tx1, int ty1,
                     raster_tri *t) {
    t->tile_x0 = tx0;
    t->tile_x1 = tx1;
    t->x0 = f->x0 > tx0 ? f->x0 : tx0;
    t->y0 = f->y0 > ty0 ? f->y0 : ty0;
    t->x1 = f->x1 < tx1 ? f->x1 : tx1;
    t->y1 = f->y1 < ty1 ? f->y1 : ty1;
    if (t->x0 > t->x1 || t->y0 > t->y1) return 0;
    /* edge k is opposite corner k; w_k(p) = (e.dx)(p.y - e.y) - (e.dy)(p.x - e.x) */
    static const int ea[3] = {1, 2, 0}, eb[3] = {2, 0, 1};
    int64_t px = (int64_t)t->x0 * SUBPIX + SUBPIX / 2, py = (int64_t)t->y0 * SUBPIX + SUBPIX / 2;
    for (int k = 0; k < 3; k++) {
        int64_t ax = f->x[ea[k]], ay = f->y[ea[k]];
        int64_t dx = f->x[eb[k]] - ax, dy = f->y[eb[k]] - ay;
        t->row[k] = dx * (py - ay) - dy * (px - ax);
        t->step_x[k] = -dy * SUBPIX;
        t->step_y[k] = dx * SUBPIX;
        /* top-left rule: pixel centres exactly on a top or left edge belong to the face */
        t->bias[k] = dy < 0 || (dy == 0 && dx > 0) ? 0 : 1;
    }
    /* most faces of a small render cover at most one pixel centre: test it before the setup */
    if (t->x0 == t->x1 && t->y0 == t->y1 &&
        (t->row[0] < t->bias[0] || t->row[1] < t->bias[1] || t->row[2] < t->bias[2]))
        return 0;
    int64_t area = t->row[0] + t->row[1] + t->row[2]; /* the sum of the edge functions is constant */
    t->inv_area = (float)(1.0 / (double)area);
    t->z0 = f->z[0];
    t->dz1 = f->z[1] - f->z[0];
    t->dz2 = f->z[2] - f->z[0];
    t->persp = !j->cam->ortho;
    t->back = f->back;
    return 1;
}

/* Draws bin entry `slot` (its index is what the face buffer holds until the tile is
 * resolved, so that resolving finds the setup in the tile's own, cache-warm bin). */
static void draw_face(const raster_job *j, int32_t slot, int tx0, int ty0, int tx1, int ty1) {
    const face_setup *f = &j->s->bins[slot];
    raster_tri t;
    if (!clip_face(j, f, tx0, ty0, tx1, ty1, &t)) return;
    t.face = slot;
    raster_target o = {j->gb->w, j->gb->face, j->gb->depth, j->gb->depth_unculled};
    int one_pixel = t.x0 == t.x1 && t.y0 == t.y1; /* there the vector setup would dominate */
#ifndef MX_NO_X86_SIMD /* non-x86 builds have no raster_avx2.c (Makefile): the scalar kernel only */
    if (j->simd && f->small && !one_pixel) {
        mx_raster_draw_small_avx2(&t, &o);
        return;
    }
#else
    (void)one_pixel;
#endif
    draw_tri_scalar(&t, &o);
}

/* Barycentrics (perspective-correct) of pixel i for its face, in the face's corner order,
 * from the snapped corners: the same numbers the coverage test used. */
static void resolve_bary(const raster_job *j, size_t i, const face_setup *fs) {
    mx_gbuffer *gb = j->gb;
    int64_t px = (int64_t)(i % (size_t)gb->w) * SUBPIX + SUBPIX / 2;
    int64_t py = (int64_t)(i / (size_t)gb->w) * SUBPIX + SUBPIX / 2;
    double w1 = (double)edge_fn(fs->x[2], fs->y[2], fs->x[0], fs->y[0], px, py);
    double w2 = (double)edge_fn(fs->x[0], fs->y[0], fs->x[1], fs->y[1], px, py);
    double w0 = (double)edge_fn(fs->x[1], fs->y[1], fs->x[2], fs->y[2], px, py);
    double sum = w0 + w1 + w2;
    double b1 = w1 / sum, b2 = w2 / sum;
    if (!j->cam->ortho) {
        /* weights of 1/z, renormalised */
        double q0 = (1 - b1 - b2) * fs->z[0], q1 = b1 * fs->z[1], q2 = b2 * fs->z[2];
        double q = q0 + q1 + q2;
        b1 = q1 / q;
        b2 = q2 / q;
    }
    gb->bary[2 * i] = (float)(fs->swapped ? b2 : b1);
    gb->bary[2 * i + 1] = (float)(fs->swapped ? b1 : b2);
}

static void resolve_uv(const raster_job *j, size_t i, const face_setup *fs) {
    mx_gbuffer *gb = j->gb;
    if (!fs->has_uv) {
        gb->uv[2 * i] = gb->uv[2 * i + 1] = NAN;
        return;
    }
    const float *u0 = j->m->uv + 2 * (size_t)fs->uv_index[0], *u1 = j->m->uv + 2 * (size_t)fs->uv_index[1],
                *u2 = j->m->uv + 2 * (size_t)fs->uv_index[2];
    float b1 = gb->bary[2 * i], b2 = gb->bary[2 * i + 1], b0 = 1.0f - b1 - b2;
    gb->uv[2 * i] = b0 * u0[0] + b1 * u1[0] + b2 * u2[0];
    gb->uv[2 * i + 1] = b0 * u0[1] + b1 * u1[1] + b2 * u2[1];
}

/* Turns the tile's bin slots into face ids and fills barycentrics (and UVs). */
/* Turns the tile's bin slots into face ids and fills barycentrics (and UVs); background
 * pixels get zeros, written row by row with memset (0.0f is all zero bytes). */
static void resolve_tile(const raster_job *j, int x0, int y0, int x1, int y1) {
    mx_gbuffer *gb = j->gb;
    int with_uv = (j->flags & MX_RASTER_UV) && j->m->face_uv;
    size_t n = (size_t)(x1 - x0 + 1);
    for (int y = y0; y <= y1; y++) {
        size_t row = (size_t)y * gb->w + x0;
        memset(gb->bary + 2 * row, 0, 2 * n * sizeof *gb->bary);
        if (with_uv) memset(gb->uv + 2 * row, 0, 2 * n * sizeof *gb->uv);
        for (size_t i = row; i < row + n; i++) {
            int32_t slot = gb->face[i];
            if (slot < 0) continue;
            const face_setup *fs = &j->s->bins[slot];
            gb->face[i] = fs->face;
            resolve_bary(j, i, fs);
            if (with_uv) resolve_uv(j, i, fs);
        }
    }
}

/* Background values for the tile: face -1 (all one bytes), depths INFINITY. */
static void clear_tile(mx_gbuffer *gb, int x0, int y0, int x1, int y1) {
    size_t n = (size_t)(x1 - x0 + 1);
    for (int y = y0; y <= y1; y++) {
        size_t row = (size_t)y * gb->w + x0;
        memset(gb->face + row, 0xff, n * sizeof *gb->face);
        for (size_t i = row; i < row + n; i++) gb->depth[i] = INFINITY;
        if (gb->depth_unculled)
            for (size_t i = row; i < row + n; i++) gb->depth_unculled[i] = INFINITY;
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
    clear_tile(gb, x0, y0, x1, y1);
    const raster_scratch *s = j->s;
    for (int32_t k = s->bin_start[task]; k < s->bin_start[task + 1]; k++) draw_face(j, k, x0, y0, x1, y1);
    resolve_tile(j, x0, y0, x1, y1);
}

/* The message for the first out-of-range index (the count pass found one). */
static int report_bad_face(const mx_mesh *m, mx_status *st) {
    size_t n = 3 * (size_t)m->nfaces;
    for (size_t k = 0; k < n; k++)
        if (m->faces[k] < 0 || m->faces[k] >= m->nverts)
            return mx_fail(st, MX_EINPUT, "%s: face %zu uses vertex %d of %d", m->source_path, k / 3,
                           m->faces[k], m->nverts);
    for (size_t k = 0; m->face_uv && k < n; k++)
        if (m->face_uv[k] < -1 || m->face_uv[k] >= m->nuv) /* -1: corner without UV */
            return mx_fail(st, MX_EINPUT, "%s: face %zu uses UV %d of %d", m->source_path, k / 3,
                           m->face_uv[k], m->nuv);
    return mx_fail(st, MX_EINPUT, "%s: a face index is out of range", m->source_path);
}

static int reserve_scratch(raster_job *j, mx_status *st) {
    raster_scratch *s = j->s;
    size_t nv = (size_t)j->m->nverts + 1, nf = (size_t)j->m->nfaces + 1;
    size_t ntiles = (size_t)j->tiles_x * j->tiles_y, ncounts = (size_t)j->nchunks * ntiles + 1;
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
    if (nf > s->face_cap) {
        free(s->faces);
        free(s->fnormal);
        s->faces = malloc(nf * sizeof *s->faces);
        s->fnormal = malloc(3 * nf * sizeof *s->fnormal);
        s->face_cap = s->faces && s->fnormal ? nf : 0;
        if (!s->face_cap) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    if (ncounts > s->count_cap) {
        free(s->counts);
        s->counts = malloc(ncounts * sizeof *s->counts);
        s->count_cap = s->counts ? ncounts : 0;
        if (!s->counts) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    if ((size_t)j->nchunks > s->chunk_cap) {
        free(s->chunk_bad);
        s->chunk_bad = malloc((size_t)j->nchunks);
        s->chunk_cap = s->chunk_bad ? (size_t)j->nchunks : 0;
        if (!s->chunk_bad) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    if (ntiles + 1 > s->tile_cap) {
        free(s->bin_start);
        s->bin_start = malloc((ntiles + 1) * sizeof *s->bin_start);
        s->tile_cap = s->bin_start ? ntiles + 1 : 0;
        if (!s->bin_start) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    return 0;
}

static int reserve_outputs(raster_job *j, mx_status *st) {
    mx_gbuffer *gb = j->gb;
    size_t n = (size_t)gb->w * gb->h;
    if ((j->flags & MX_RASTER_UV) && j->m->face_uv && !gb->uv) {
        gb->uv = malloc(2 * n * sizeof *gb->uv);
        if (!gb->uv) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    int want_unculled = (j->flags & MX_RASTER_DEPTH_UNCULLED) && (j->flags & MX_RASTER_CULL_BACK);
    if (!want_unculled) {
        free(gb->depth_unculled); /* NULL tells the reader it was not filled */
        gb->depth_unculled = NULL;
    } else if (!gb->depth_unculled) {
        gb->depth_unculled = malloc(n * sizeof *gb->depth_unculled);
        if (!gb->depth_unculled) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    return 0;
}

int mx_rasterize(const mx_mesh *m, const float *pos, const mx_camera *cam, int flags,
                 mx_pool *pool, mx_gbuffer *gb, mx_status *st) {
    raster_job j = {m, pos ? pos : m->pos, cam, flags, gb, gb->scratch, 0, 0, 0,
                    mx_cpu_best_isa() >= MX_ISA_AVX2};
    j.tiles_x = (gb->w + TILE - 1) / TILE;
    j.tiles_y = (gb->h + TILE - 1) / TILE;
    j.nchunks = m->nfaces / FACES_PER_CHUNK + 1;
    if (reserve_scratch(&j, st) || reserve_outputs(&j, st)) return -1;
    gb->cam = *cam;
    mx_pool_for(pool, m->nverts / FACES_PER_CHUNK + 1, project_vertices_task, &j);
    mx_pool_for(pool, j.nchunks, count_bins_task, &j);
    for (int c = 0; c < j.nchunks; c++)
        if (j.s->chunk_bad[c]) return report_bad_face(m, st);
    int64_t total = prefix_bins(&j);
    if (total < 0) return mx_fail(st, MX_EINPUT, "%s: too many face-tile pairs", m->source_path);
    if ((size_t)total + 1 > j.s->bin_cap) {
        free(j.s->bins);
        j.s->bins = malloc(((size_t)total + 1) * sizeof *j.s->bins);
        j.s->bin_cap = j.s->bins ? (size_t)total + 1 : 0;
        if (!j.s->bins) return mx_fail(st, MX_ENOMEM, "rasterizer: out of memory");
    }
    mx_pool_for(pool, j.nchunks, fill_bins_task, &j);
    mx_pool_for(pool, j.tiles_x * j.tiles_y, draw_tile_task, &j);
    return 0;
}

void mx_gbuffer_normal(const mx_gbuffer *gb, int64_t i, float out[3]) {
    int f = gb->face[i];
    const raster_scratch *s = gb->scratch;
    for (int k = 0; k < 3; k++) out[k] = f >= 0 ? s->fnormal[3 * (size_t)f + k] : 0.0f;
}

const float *mx_gbuffer_face_normals(const mx_gbuffer *gb) {
    const raster_scratch *s = gb->scratch;
    return s->fnormal;
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
    int y0 = task * ROWS_PER_TASK, y1 = y0 + ROWS_PER_TASK < gb->h ? y0 + ROWS_PER_TASK : gb->h;
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
    mx_pool_for(pool, (gb->h + ROWS_PER_TASK - 1) / ROWS_PER_TASK, render_textured_task, &j);
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
