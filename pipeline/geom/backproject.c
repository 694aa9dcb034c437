#include "backproject.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "masks.h"

#define BAND_ROWS 16  /* texture rows per band task */
#define CHUNK_ROWS 16 /* image rows per list-building task */

/* Per-view work lists. Each image chunk first stages a full splat record (texels,
 * fractions, colour, quality) for each of its used pixels, in pixel order, and counts
 * them per texture band; the records are then moved into one list grouped by band. The
 * band tasks stream through their records instead of gathering footprints, colours and
 * normals from all over the image. */
typedef struct bp_scratch {
    size_t count_cap, rec_cap, q_cap, bin_cap, staged_cap, nstaged_cap;
    int32_t *counts;          /* [nchunks][nbins] then write offsets */
    int32_t *bin_start;       /* [nbins + 1] */
    struct splat_rec *recs;   /* records grouped by bin, in pixel order */
    float *view_w;            /* [nlayers][h][w] this view's splat weight per texel */
    float *view_wc;           /* [nlayers][h][w][3] this view's sum(w colour) */
    float *view_q;            /* [nlayers][h][w] this view's best |n.v| */
    uint8_t *reach;           /* [nlayers][h][w] 1: the view reaches the texel with a full share */
    uint8_t *near_row, *near_col; /* [nlayers][h][w] reach within HOLE_TEXELS along the row / column */
    uint8_t *hole;            /* [nlayers][h][w] 1: an aliasing hole of this view, filled from its neighbours */
    uint8_t *claim;           /* [nlayers][h][w] this view's raw claim on known texels, 0..255 */
    struct splat_rec *staged; /* [image pixels]: chunk c's records from its first pixel on */
    int32_t *nstaged;         /* [nchunks] */
} bp_scratch;

int mx_bake_init(mx_bake *b, int w, int h, int nlayers, mx_status *st) {
    memset(b, 0, sizeof *b);
    if (w <= 0 || h <= 0 || w > 16384 || h > 16384 || nlayers <= 0 || nlayers > 256)
        return mx_fail(st, MX_EINPUT, "backprojection: bad texture size %dx%d x %d", w, h, nlayers);
    size_t n = (size_t)w * h * nlayers;
    b->w = w;
    b->h = h;
    b->nlayers = nlayers;
    b->eps = MX_BAKE_KNOWN_WEIGHT;
    b->overwrite_margin = 0.15f;
    b->sum_wc = calloc(3 * n, sizeof *b->sum_wc);
    b->sum_w = calloc(n, sizeof *b->sum_w);
    b->known = calloc(n, 1);
    b->quality = calloc(n, sizeof *b->quality);
    b->scratch = calloc(1, sizeof(bp_scratch));
    if (!b->sum_wc || !b->sum_w || !b->known || !b->quality || !b->scratch) {
        mx_bake_free(b);
        return mx_fail(st, MX_ENOMEM, "backprojection: out of memory for a %dx%d texture", w, h);
    }
    return 0;
}

/* The per-texel buffers of one view (allocated together, q_cap entries each). */
static void free_texel_buffers(bp_scratch *s) {
    free(s->view_w);
    free(s->view_wc);
    free(s->view_q);
    free(s->reach);
    free(s->near_row);
    free(s->near_col);
    free(s->hole);
    free(s->claim);
}

void mx_bake_free(mx_bake *b) {
    bp_scratch *s = b->scratch;
    if (s) {
        free(s->counts);
        free(s->bin_start);
        free(s->recs);
        free_texel_buffers(s);
        free(s->staged);
        free(s->nstaged);
        free(s);
    }
    free(b->sum_wc);
    free(b->sum_w);
    free(b->known);
    free(b->quality);
    memset(b, 0, sizeof *b);
}

void mx_bake_reset(mx_bake *b) {
    size_t n = (size_t)b->w * b->h * b->nlayers;
    memset(b->sum_wc, 0, 3 * n * sizeof *b->sum_wc);
    memset(b->sum_w, 0, n * sizeof *b->sum_w);
    memset(b->known, 0, n);
    memset(b->quality, 0, n * sizeof *b->quality);
}

int mx_face_layer(const mx_mesh *m, int face, int nlayers) {
    int mat = m->face_mat ? m->face_mat[face] : 0;
    return mat >= 0 && mat < nlayers ? mat : 0;
}

typedef struct bp_job {
    mx_bake *b;
    const mx_gbuffer *gb;
    const mx_mesh *m;
    const mx_image *img;
    const uint8_t *mask;
    int flags;
    int nbands, nbins, nchunks;
    bp_scratch *s;
    const float *normals; /* the view's face normals (mx_gbuffer_face_normals) */
    float ortho_v[3];     /* orthographic view direction */
} bp_job;

/* A pixel's splat, as the band tasks read it (32 bytes): the 2 x 2 texels from (x0, y0)
 * (wrapping to column 0 / row 0 at the edge), the fractions, the material layer, the
 * colour and the quality |n . v| of the pixel's face. */
typedef struct splat_rec {
    uint16_t x0, y0, layer, unused;
    float fx, fy;
    float col[3];
    float q;
} splat_rec;

static int pixel_used(const bp_job *j, size_t i) {
    float u = j->gb->uv[2 * i], v = j->gb->uv[2 * i + 1];
    return j->gb->face[i] >= 0 && (!j->mask || j->mask[i]) && isfinite(u) && isfinite(v);
}

static float pixel_quality(const bp_job *j, size_t i) {
    const mx_gbuffer *gb = j->gb;
    const float *n = j->normals + 3 * (size_t)gb->face[i];
    if (gb->cam.ortho) /* one view direction for every pixel */
        return fabsf(n[0] * j->ortho_v[0] + n[1] * j->ortho_v[1] + n[2] * j->ortho_v[2]);
    float p[3], v[3];
    int x = (int)(i % (size_t)gb->w), y = (int)(i / (size_t)gb->w);
    mx_camera_unproject(&gb->cam, (float)x + 0.5f, (float)y + 0.5f, gb->depth[i], gb->w, gb->h, p);
    mx_camera_view_dir(&gb->cam, p, v);
    return fabsf(n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
}

/* floorf without the library call (the build targets plain x86-64); identical results,
 * signed zeros included. */
static float floor_fast(float x) {
    if (!(fabsf(x) < 8388608.0f)) return floorf(x); /* 2^23: larger floats are integers */
    float t = (float)(int32_t)x;
    if (t == x) return x;
    return t > x ? t - 1.0f : t;
}

static splat_rec pixel_splat(const bp_job *j, size_t i) {
    const mx_bake *b = j->b;
    float tx = j->gb->uv[2 * i] * (float)b->w - 0.5f;
    float ty = (1.0f - j->gb->uv[2 * i + 1]) * (float)b->h - 0.5f;
    float flx = floor_fast(tx), fly = floor_fast(ty);
    splat_rec s;
    s.fx = tx - flx;
    s.fy = ty - fly;
    int x0 = (int)flx, y0 = (int)fly;
    /* repeat wrapping; fmod only for the rare far-away UV, to keep the int conversion valid */
    if (x0 < -1 || x0 >= b->w) x0 = (int)fmodf(flx, (float)b->w);
    if (y0 < -1 || y0 >= b->h) y0 = (int)fmodf(fly, (float)b->h);
    if (x0 < 0) x0 += b->w;
    if (y0 < 0) y0 += b->h;
    s.x0 = (uint16_t)x0;
    s.y0 = (uint16_t)y0;
    s.layer = (uint16_t)mx_face_layer(j->m, j->gb->face[i], b->nlayers);
    s.unused = 0;
    const float *col = j->img->data + i * (size_t)j->img->c;
    s.col[0] = col[0];
    s.col[1] = col[1];
    s.col[2] = col[2];
    s.q = pixel_quality(j, i);
    return s;
}

/* The bins (layer, band) of a splat's two texel rows; b1 == b0 when both lie in one band. */
static void splat_bins(const bp_job *j, const splat_rec *r, int *b0, int *b1) {
    int y1 = r->y0 + 1 == j->b->h ? 0 : r->y0 + 1;
    *b0 = r->layer * j->nbands + r->y0 / BAND_ROWS;
    *b1 = r->layer * j->nbands + y1 / BAND_ROWS;
}

static void stage_task(void *ctx, int task, int thread) {
    (void)thread;
    bp_job *j = ctx;
    int32_t *cnt = j->s->counts + (size_t)task * j->nbins;
    memset(cnt, 0, (size_t)j->nbins * sizeof *cnt);
    int y0 = task * CHUNK_ROWS, y1 = y0 + CHUNK_ROWS < j->gb->h ? y0 + CHUNK_ROWS : j->gb->h;
    splat_rec *out = j->s->staged + (size_t)y0 * j->gb->w;
    int32_t n = 0;
    for (size_t i = (size_t)y0 * j->gb->w; i < (size_t)y1 * j->gb->w; i++) {
        if (!pixel_used(j, i)) continue;
        out[n] = pixel_splat(j, i);
        int b0, b1;
        splat_bins(j, &out[n++], &b0, &b1);
        cnt[b0]++;
        if (b1 != b0) cnt[b1]++;
    }
    j->s->nstaged[task] = n;
}

static void fill_task(void *ctx, int task, int thread) {
    (void)thread;
    bp_job *j = ctx;
    int32_t *off = j->s->counts + (size_t)task * j->nbins;
    const splat_rec *in = j->s->staged + (size_t)task * CHUNK_ROWS * j->gb->w;
    for (int32_t k = 0; k < j->s->nstaged[task]; k++) {
        int b0, b1;
        splat_bins(j, &in[k], &b0, &b1);
        j->s->recs[off[b0]++] = in[k];
        if (b1 != b0) j->s->recs[off[b1]++] = in[k];
    }
}

/* The 4 texels and weights of a splat, restricted to rows [r0, r1). */
static int splat_texels(const splat_rec *sp, int w, int h, int r0, int r1, size_t *tex, float *wt) {
    int n = 0;
    int ys[2] = {sp->y0, sp->y0 + 1 == h ? 0 : sp->y0 + 1};
    int xs[2] = {sp->x0, sp->x0 + 1 == w ? 0 : sp->x0 + 1};
    float wy[2] = {1 - sp->fy, sp->fy}, wx[2] = {1 - sp->fx, sp->fx};
    for (int a = 0; a < 2; a++) {
        if (ys[a] < r0 || ys[a] >= r1) continue;
        for (int c = 0; c < 2; c++) {
            float wgt = wy[a] * wx[c];
            if (wgt <= 0) continue;
            tex[n] = (size_t)ys[a] * w + xs[c];
            wt[n++] = wgt;
        }
    }
    return n;
}

/* Each view is first splatted into its own accumulators (view_w, view_wc, view_q), then merged
 * into the bake texel by texel (issue 24 item 2: no screen-door stipple where views overlap):
 * - aliasing holes: where the view's pixels are coarser than the texels (a surface seen at a
 *   slant, or a texture finer than the render), bilinear splats leave single texels with no or
 *   little weight inside the view's footprint (runs of up to 2-3 texels at the slant the frontal
 *   filter allows); they would be painted by a later view, its texels in a grid over this
 *   one. A texel without a full share (weight <= eps) surrounded by texels that have one
 *   (within HOLE_TEXELS on its left, right, above and below) takes their mean (weights and
 *   colours), as if splatted by them;
 * - texels not in T^B take the view's splat (added to what they had);
 * - texels in T^B (angle-aware, MX_BACKPROJECT_OVERWRITE) blend towards the view by its claim:
 *   the claim rises from 0 to 1 as the view's |n.v| exceeds the texel's quality by
 *   overwrite_margin -/+ CLAIM_RAMP / 2, and is then averaged over the texels the view reaches
 *   within FEATHER_TEXELS, so the source of a texel changes over a feathered border instead of
 *   texel by texel (an isolated claim is averaged away, as is an isolated refusal); a texel
 *   between the view's pixels takes their mean colour. The texel keeps its weight: only its
 *   colour and quality move. */
#define CLAIM_RAMP 0.1f
#define FEATHER_TEXELS 2
#define HOLE_TEXELS 3

/* A band task's layer and texture rows [r0, r1). */
static void task_rows(const bp_job *j, int task, int *layer, int *r0, int *r1) {
    *layer = task / j->nbands;
    *r0 = (task % j->nbands) * BAND_ROWS;
    *r1 = *r0 + BAND_ROWS < j->b->h ? *r0 + BAND_ROWS : j->b->h;
}

/* Pass 1, one bin: the view's splats of its rows, in pixel order; reach[t] = the view reaches
 * texel t with a full share (weight > eps). */
static void splat_view_task(void *ctx, int task, int thread) {
    (void)thread;
    bp_job *j = ctx;
    mx_bake *b = j->b;
    bp_scratch *s = j->s;
    int layer, r0, r1;
    task_rows(j, task, &layer, &r0, &r1);
    size_t plane = (size_t)layer * b->w * b->h, t0 = plane + (size_t)r0 * b->w, t1 = plane + (size_t)r1 * b->w;
    int32_t k0 = s->bin_start[task], k1 = s->bin_start[task + 1];
    if (k0 == k1) { /* the accumulators of an empty bin are never read (reach is 0, bin_empty) */
        memset(s->reach + t0, 0, t1 - t0);
        return;
    }
    memset(s->view_w + t0, 0, (t1 - t0) * sizeof *s->view_w);
    memset(s->view_wc + 3 * t0, 0, 3 * (t1 - t0) * sizeof *s->view_wc);
    memset(s->view_q + t0, 0, (t1 - t0) * sizeof *s->view_q);
    for (int32_t k = k0; k < k1; k++) {
        const splat_rec *r = &s->recs[k];
        size_t tex[4];
        float wt[4];
        int n = splat_texels(r, b->w, b->h, r0, r1, tex, wt);
        for (int e = 0; e < n; e++) {
            size_t t = plane + tex[e];
            s->view_w[t] += wt[e];
            s->view_wc[3 * t] += wt[e] * r->col[0];
            s->view_wc[3 * t + 1] += wt[e] * r->col[1];
            s->view_wc[3 * t + 2] += wt[e] * r->col[2];
            if (r->q > s->view_q[t]) s->view_q[t] = r->q;
        }
    }
    for (size_t t = t0; t < t1; t++) s->reach[t] = s->view_w[t] > b->eps;
}

static int bin_empty(const bp_job *j, int layer, int y) {
    int bin = layer * j->nbands + y / BAND_ROWS;
    return j->s->bin_start[bin] == j->s->bin_start[bin + 1];
}

/* Pass 2, one bin: near_row[t] / near_col[t] = some texel within HOLE_TEXELS along the row /
 * the column of t is reached (separable, so the hole test reads 12 bytes, not a window). */
static void mark_near_task(void *ctx, int task, int thread) {
    (void)thread;
    bp_job *j = ctx;
    const mx_bake *b = j->b;
    bp_scratch *s = j->s;
    int layer, r0, r1;
    task_rows(j, task, &layer, &r0, &r1);
    const uint8_t *reach = s->reach + (size_t)layer * b->w * b->h;
    for (int y = r0; y < r1; y++)
        for (int x = 0; x < b->w; x++) {
            uint8_t row = 0, col = 0;
            for (int d = -HOLE_TEXELS; d <= HOLE_TEXELS; d++) {
                if (x + d >= 0 && x + d < b->w) row |= reach[(size_t)y * b->w + x + d];
                if (y + d >= 0 && y + d < b->h) col |= reach[(size_t)(y + d) * b->w + x];
            }
            s->near_row[(size_t)layer * b->w * b->h + (size_t)y * b->w + x] = row;
            s->near_col[(size_t)layer * b->w * b->h + (size_t)y * b->w + x] = col;
        }
}

/* Some texel of `near` (near_col or near_row of a layer) at 1..HOLE_TEXELS steps (dx, dy) from
 * (x, y) is set. */
static int near_towards(const mx_bake *b, const uint8_t *near, int x, int y, int dx, int dy) {
    for (int k = 1; k <= HOLE_TEXELS; k++) {
        int u = x + k * dx, v = y + k * dy;
        if (u >= 0 && v >= 0 && u < b->w && v < b->h && near[(size_t)v * b->w + u]) return 1;
    }
    return 0;
}

/* Pass 3, one bin: marks the aliasing holes: texels not reached that have reached texels within
 * HOLE_TEXELS on their left and on their right, above and below (surrounded; a texel beside a
 * straight border of the footprint is not). 0 in an empty bin. */
static void mark_holes_task(void *ctx, int task, int thread) {
    (void)thread;
    bp_job *j = ctx;
    const mx_bake *b = j->b;
    const bp_scratch *s = j->s;
    int layer, r0, r1;
    task_rows(j, task, &layer, &r0, &r1);
    size_t plane = (size_t)layer * b->w * b->h;
    const uint8_t *reach = s->reach + plane, *row = s->near_row + plane, *col = s->near_col + plane;
    uint8_t *hole = s->hole + plane;
    int empty = bin_empty(j, layer, r0);
    for (int y = r0; y < r1; y++)
        for (int x = 0; x < b->w; x++) {
            size_t t = (size_t)y * b->w + x;
            hole[t] = (uint8_t)(!empty && !reach[t] && near_towards(b, col, x, y, -1, 0) &&
                                near_towards(b, col, x, y, 1, 0) && near_towards(b, row, x, y, 0, -1) &&
                                near_towards(b, row, x, y, 0, 1));
        }
}

/* The view has a splat at (x, y): it reaches the texel (reach, pass 1) or, after pass 4, fills
 * it as a hole. */
static int reached(const bp_job *j, int layer, int x, int y, int with_holes) {
    const mx_bake *b = j->b;
    if (x < 0 || y < 0 || x >= b->w || y >= b->h) return 0;
    size_t t = (size_t)layer * b->w * b->h + (size_t)y * b->w + x;
    return j->s->reach[t] || (with_holes && j->s->hole[t]);
}

/* The raw claim (0..255) of the view on a texel from its best |n.v| there. */
static uint8_t texel_claim(const bp_job *j, size_t t) {
    const mx_bake *b = j->b;
    const bp_scratch *s = j->s;
    if (!(j->flags & MX_BACKPROJECT_OVERWRITE) || !b->known[t] || !(s->view_w[t] > b->eps)) return 0;
    float gain = s->view_q[t] - b->quality[t];
    float c = (gain - (b->overwrite_margin - 0.5f * CLAIM_RAMP)) / CLAIM_RAMP;
    c = c < 0 ? 0 : c > 1 ? 1 : c;
    return (uint8_t)lroundf(255.0f * c);
}

/* The view's splats summed over the texels within `radius` of (x, y) that it reaches (holes
 * excluded with `solid`, in pass 4): weights, colours, the best |n.v|, their count and (not
 * `solid`, pass 5) their raw claims. */
typedef struct window_sum {
    float w, wc[3], q;
    int claim, n;
} window_sum;

static window_sum sum_window(const bp_job *j, int layer, int x, int y, int radius, int solid) {
    const mx_bake *b = j->b;
    const bp_scratch *s = j->s;
    size_t plane = (size_t)layer * b->w * b->h;
    window_sum a = {.w = 0};
    for (int v = y - radius; v <= y + radius; v++)
        for (int u = x - radius; u <= x + radius; u++) {
            if (!reached(j, layer, u, v, !solid)) continue;
            size_t o = plane + (size_t)v * b->w + u;
            a.w += s->view_w[o];
            for (int c = 0; c < 3; c++) a.wc[c] += s->view_wc[3 * o + c];
            if (s->view_q[o] > a.q) a.q = s->view_q[o];
            if (!solid) a.claim += s->claim[o]; /* pass 4 writes the claims while filling holes */
            a.n++;
        }
    return a;
}

/* A hole takes the mean of the reached texels within HOLE_TEXELS (weights, colours; the best
 * |n.v| among them): as if their pixels had splatted into it. Other holes, filled in the same
 * pass, are not read. */
static void fill_hole(const bp_job *j, int layer, int x, int y) {
    const mx_bake *b = j->b;
    bp_scratch *s = j->s;
    size_t t = (size_t)layer * b->w * b->h + (size_t)y * b->w + x;
    window_sum a = sum_window(j, layer, x, y, HOLE_TEXELS, 1);
    s->view_w[t] = a.w / (float)a.n;
    for (int c = 0; c < 3; c++) s->view_wc[3 * t + c] = a.wc[c] / (float)a.n;
    s->view_q[t] = a.q;
}

/* Pass 4, one bin: fills the holes from the reached texels around (not holes, so not written
 * in this pass), then the raw claims. */
static void fill_holes_task(void *ctx, int task, int thread) {
    (void)thread;
    bp_job *j = ctx;
    const mx_bake *b = j->b;
    int layer, r0, r1;
    task_rows(j, task, &layer, &r0, &r1);
    if (bin_empty(j, layer, r0)) return;
    size_t plane = (size_t)layer * b->w * b->h;
    for (int y = r0; y < r1; y++)
        for (int x = 0; x < b->w; x++) {
            size_t t = plane + (size_t)y * b->w + x;
            if (j->s->hole[t]) fill_hole(j, layer, x, y);
            j->s->claim[t] = texel_claim(j, t);
        }
}

/* What the view offers a texel in T^B, from the reached texels within FEATHER_TEXELS: the mean
 * of their claims (the feathered claim), and the colour and |n.v| of the texel's own splat, or
 * of their mean where the view does not reach the texel itself (its pixels sparser than the
 * texels). Returns the claim, 0 when there is nothing to take. */
static float texel_offer(const bp_job *j, int layer, int x, int y, float col[3], float *q) {
    const mx_bake *b = j->b;
    const bp_scratch *s = j->s;
    size_t t = (size_t)layer * b->w * b->h + (size_t)y * b->w + x;
    window_sum a = sum_window(j, layer, x, y, FEATHER_TEXELS, 0);
    if (a.n == 0 || a.claim == 0) return 0.0f;
    if (reached(j, layer, x, y, 1)) {
        a.w = s->view_w[t];
        for (int c = 0; c < 3; c++) a.wc[c] = s->view_wc[3 * t + c];
        a.q = s->view_q[t];
    }
    for (int c = 0; c < 3; c++) col[c] = a.wc[c] / a.w;
    *q = a.q;
    return (float)a.claim / (255.0f * (float)a.n);
}

/* A texel in T^B moves towards the view's colour and |n.v| by `a`. */
static void blend_texel(mx_bake *b, size_t t, float a, const float col[3], float q) {
    for (int c = 0; c < 3; c++)
        b->sum_wc[3 * t + c] += a * (col[c] * b->sum_w[t] - b->sum_wc[3 * t + c]);
    b->quality[t] += a * (q - b->quality[t]);
}

/* A texel not in T^B takes the view's splat. */
static void add_texel(mx_bake *b, const bp_scratch *s, size_t t) {
    float w = s->view_w[t];
    b->sum_w[t] += w;
    for (int c = 0; c < 3; c++) b->sum_wc[3 * t + c] += s->view_wc[3 * t + c];
    if (s->view_q[t] > b->quality[t]) b->quality[t] = s->view_q[t];
    b->known[t] = b->sum_w[t] > b->eps;
}

/* Pass 5, one bin: the merge. */
static void merge_view_task(void *ctx, int task, int thread) {
    (void)thread;
    bp_job *j = ctx;
    mx_bake *b = j->b;
    const bp_scratch *s = j->s;
    int layer, r0, r1;
    task_rows(j, task, &layer, &r0, &r1);
    if (bin_empty(j, layer, r0)) return;
    size_t plane = (size_t)layer * b->w * b->h;
    for (int y = r0; y < r1; y++)
        for (int x = 0; x < b->w; x++) {
            size_t t = plane + (size_t)y * b->w + x;
            if (!b->known[t]) {
                if (s->view_w[t] > 0) add_texel(b, s, t);
                continue;
            }
            if (!(j->flags & MX_BACKPROJECT_OVERWRITE)) continue;
            float col[3], q, a = texel_offer(j, layer, x, y, col, &q);
            if (a > 0) blend_texel(b, t, a, col, q);
        }
}

static int reserve(bp_job *j, mx_status *st) {
    bp_scratch *s = j->s;
    size_t need_counts = (size_t)j->nchunks * j->nbins;
    size_t npix = (size_t)j->gb->w * j->gb->h;
    size_t need_q = (size_t)j->b->w * j->b->h * j->b->nlayers;
    if (need_counts > s->count_cap) {
        free(s->counts);
        s->counts = malloc(need_counts * sizeof *s->counts);
        s->count_cap = s->counts ? need_counts : 0;
    }
    if ((size_t)j->nbins + 1 > s->bin_cap) {
        free(s->bin_start);
        s->bin_start = malloc(((size_t)j->nbins + 1) * sizeof *s->bin_start);
        s->bin_cap = s->bin_start ? (size_t)j->nbins + 1 : 0;
    }
    if (need_q > s->q_cap) {
        free_texel_buffers(s);
        s->view_w = malloc(need_q * sizeof *s->view_w);
        s->view_wc = malloc(3 * need_q * sizeof *s->view_wc);
        s->view_q = malloc(need_q * sizeof *s->view_q);
        s->reach = malloc(need_q);
        s->near_row = malloc(need_q);
        s->near_col = malloc(need_q);
        s->hole = malloc(need_q);
        s->claim = malloc(need_q);
        s->q_cap = s->view_w && s->view_wc && s->view_q && s->reach && s->near_row && s->near_col && s->hole && s->claim
                       ? need_q
                       : 0;
    }
    if (npix > s->staged_cap) {
        free(s->staged);
        s->staged = malloc(npix * sizeof *s->staged);
        s->staged_cap = s->staged ? npix : 0;
    }
    if ((size_t)j->nchunks > s->nstaged_cap) {
        free(s->nstaged);
        s->nstaged = malloc((size_t)j->nchunks * sizeof *s->nstaged);
        s->nstaged_cap = s->nstaged ? (size_t)j->nchunks : 0;
    }
    if (!s->counts || !s->bin_start || !s->staged || !s->nstaged || !s->q_cap)
        return mx_fail(st, MX_ENOMEM, "backprojection: out of memory");
    return 0;
}

int mx_backproject(mx_bake *b, const mx_gbuffer *gb, const mx_mesh *m, const mx_image *img,
                   const uint8_t *mask, int flags, mx_pool *pool, mx_status *st) {
    if (!gb->uv) return mx_fail(st, MX_EINPUT, "backprojection: the view has no UVs (mesh without UVs?)");
    if (img->w != gb->w || img->h != gb->h || img->c < 3)
        return mx_fail(st, MX_EINPUT, "backprojection: image %dx%dx%d does not match the %dx%d view",
                       img->w, img->h, img->c, gb->w, gb->h);
    bp_job j = {b, gb, m, img, mask, flags, 0, 0, 0, b->scratch, mx_gbuffer_face_normals(gb),
                {-gb->cam.forward[0], -gb->cam.forward[1], -gb->cam.forward[2]}};
    j.nbands = (b->h + BAND_ROWS - 1) / BAND_ROWS;
    j.nbins = j.nbands * b->nlayers;
    j.nchunks = (gb->h + CHUNK_ROWS - 1) / CHUNK_ROWS;
    if (reserve(&j, st)) return -1;
    mx_pool_for(pool, j.nchunks, stage_task, &j);
    /* counts[chunk][bin] -> write offsets: bins in order, chunks in order inside a bin */
    int64_t total = 0;
    for (int bin = 0; bin < j.nbins; bin++) {
        j.s->bin_start[bin] = (int32_t)total;
        for (int c = 0; c < j.nchunks; c++) {
            int32_t n = j.s->counts[(size_t)c * j.nbins + bin];
            j.s->counts[(size_t)c * j.nbins + bin] = (int32_t)total;
            total += n;
        }
    }
    j.s->bin_start[j.nbins] = (int32_t)total;
    if ((size_t)total + 1 > j.s->rec_cap) { /* sized by this view's pixels, not the worst case */
        free(j.s->recs);
        j.s->recs = malloc(((size_t)total + 1) * sizeof *j.s->recs);
        j.s->rec_cap = j.s->recs ? (size_t)total + 1 : 0;
        if (!j.s->recs) return mx_fail(st, MX_ENOMEM, "backprojection: out of memory");
    }
    mx_pool_for(pool, j.nchunks, fill_task, &j);
    mx_pool_for(pool, j.nbins, splat_view_task, &j);
    mx_pool_for(pool, j.nbins, mark_near_task, &j);
    mx_pool_for(pool, j.nbins, mark_holes_task, &j);
    mx_pool_for(pool, j.nbins, fill_holes_task, &j);
    mx_pool_for(pool, j.nbins, merge_view_task, &j);
    return 0;
}

void mx_bake_open_texels(const mx_bake *b, const mx_gbuffer *gb, const mx_mesh *m, const uint8_t *mask,
                         uint8_t *out) {
    size_t plane = (size_t)b->w * b->h;
    memcpy(out, b->known, plane * (size_t)b->nlayers);
    if (!gb->uv) return;
    bp_job j = {(mx_bake *)b, gb, m, NULL, mask, 0, 0, 0, 0, NULL, mx_gbuffer_face_normals(gb),
                {-gb->cam.forward[0], -gb->cam.forward[1], -gb->cam.forward[2]}};
    for (size_t i = 0; i < (size_t)gb->w * gb->h; i++) {
        if (!pixel_used(&j, i)) continue;
        size_t t = (size_t)mx_face_layer(m, gb->face[i], b->nlayers) * plane +
                   (size_t)mx_uv_texel(gb->uv[2 * i], gb->uv[2 * i + 1], b->w, b->h);
        if (b->known[t] && pixel_quality(&j, i) > b->quality[t] + b->overwrite_margin) out[t] = 0;
    }
}

/* Texels of a mx_bake_texture task (by size only: the same texture on any pool). */
#define BAKE_TEXELS_PER_TASK 16384

typedef struct bake_texture_job {
    const mx_bake *b;
    size_t layer_start;
    const float *fill;
    mx_image *out;
} bake_texture_job;

static void bake_texels(void *arg, int task, int thread) {
    (void)thread;
    const bake_texture_job *j = arg;
    const mx_bake *b = j->b;
    size_t plane = j->layer_start, n = (size_t)b->w * b->h;
    for (size_t t = (size_t)task * BAKE_TEXELS_PER_TASK; t < (size_t)(task + 1) * BAKE_TEXELS_PER_TASK && t < n; t++) {
        float w = b->sum_w[plane + t];
        for (int c = 0; c < 3; c++)
            j->out->data[3 * t + c] = b->known[plane + t] ? b->sum_wc[3 * (plane + t) + c] / w : j->fill[c];
    }
}

int mx_bake_texture(const mx_bake *b, int layer, const float fill[3], mx_pool *pool, mx_image *out, mx_status *st) {
    if (layer < 0 || layer >= b->nlayers)
        return mx_fail(st, MX_EINPUT, "backprojection: no texture layer %d", layer);
    if (mx_image_alloc(out, b->w, b->h, 3, st)) return -1;
    bake_texture_job j = {b, (size_t)layer * b->w * b->h, fill, out};
    size_t n = (size_t)b->w * b->h;
    mx_pool_for(pool, (int)((n + BAKE_TEXELS_PER_TASK - 1) / BAKE_TEXELS_PER_TASK), bake_texels, &j);
    return 0;
}

int64_t mx_bake_known_count(const mx_bake *b) {
    int64_t n = 0;
    for (size_t t = 0; t < (size_t)b->w * b->h * b->nlayers; t++) n += b->known[t];
    return n;
}
