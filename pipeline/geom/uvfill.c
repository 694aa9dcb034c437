#include "uvfill.h"

#include "masks.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static void mark_texel(uint8_t *chart, int32_t *face_map, int32_t face, int w, int h, int x, int y) {
    x %= w;
    y %= h;
    if (x < 0) x += w;
    if (y < 0) y += h;
    chart[(size_t)y * w + x] = 1;
    if (face_map) face_map[(size_t)y * w + x] = face;
}

/* Marks texels whose centre lies within half a texel of the triangle (texel coordinates), and
 * records the face in face_map (may be NULL; the last face marking a texel wins). */
static void mark_triangle(uint8_t *chart, int32_t *face_map, int32_t face, int w, int h, const float p[3][2]) {
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
            if (in && area != 0) mark_texel(chart, face_map, face, w, h, x, y);
        }
}

/* 1 when face f belongs to texture layer `layer` (every face does with one layer). */
static int face_in_layer(const mx_mesh *m, int f, int layer, int nlayers) {
    int mat = m->face_mat ? m->face_mat[f] : 0;
    if (mat < 0 || mat >= nlayers) mat = 0;
    return nlayers <= 1 || mat == layer;
}

int mx_uv_chart_mask(const mx_mesh *m, int layer, int nlayers, int w, int h, uint8_t *chart,
                     mx_status *st) {
    return mx_uv_chart_faces(m, layer, nlayers, w, h, chart, NULL, st);
}

int mx_uv_chart_faces(const mx_mesh *m, int layer, int nlayers, int w, int h, uint8_t *chart, int32_t *face_map,
                      mx_status *st) {
    if (!m->face_uv) return mx_fail(st, MX_EINPUT, "%s: no UVs to find charts in", m->source_path);
    memset(chart, 0, (size_t)w * h);
    if (face_map)
        for (size_t i = 0; i < (size_t)w * h; i++) face_map[i] = -1;
    for (int f = 0; f < m->nfaces; f++) {
        if (!face_in_layer(m, f, layer, nlayers)) continue;
        const int32_t *fu = m->face_uv + 3 * (size_t)f;
        if (fu[0] < 0 || fu[1] < 0 || fu[2] < 0 || fu[0] >= m->nuv || fu[1] >= m->nuv || fu[2] >= m->nuv)
            continue;
        float p[3][2];
        for (int k = 0; k < 3; k++) {
            p[k][0] = m->uv[2 * (size_t)fu[k]] * (float)w;
            p[k][1] = (1.0f - m->uv[2 * (size_t)fu[k] + 1]) * (float)h;
        }
        mark_triangle(chart, face_map, f, w, h, p);
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

/* Rows of a dilation task (by size only: the same result on any pool). */
#define DILATE_ROWS_PER_TASK 32

typedef struct dilate_job {
    mx_image *tex;
    const uint8_t *valid;
    uint8_t *next;
} dilate_job;

/* The rows of one task: a texel reads only valid neighbours, which no task writes in this ring. */
static void dilate_rows(void *arg, int task, int thread) {
    (void)thread;
    const dilate_job *d = arg;
    mx_image *tex = d->tex;
    const uint8_t *valid = d->valid;
    int w = tex->w, h = tex->h;
    for (int y = task * DILATE_ROWS_PER_TASK; y < (task + 1) * DILATE_ROWS_PER_TASK && y < h; y++)
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
            d->next[i] = 1;
        }
}

/* One ring of dilation: texels not valid take the mean of their valid 8-neighbours (rows on pool). */
static void dilate_once(mx_image *tex, uint8_t *valid, uint8_t *next, mx_pool *pool) {
    size_t n = (size_t)tex->w * tex->h;
    dilate_job d = {tex, valid, next};
    memcpy(next, valid, n);
    mx_pool_for(pool, (tex->h + DILATE_ROWS_PER_TASK - 1) / DILATE_ROWS_PER_TASK, dilate_rows, &d);
    memcpy(valid, next, n);
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
        for (int g = 0; g < gutter; g++) dilate_once(tex, valid, next, NULL);
    }
    free(colour), free(valid), free(next);
    return rc;
}

int mx_uv_dilate(mx_image *tex, const uint8_t *known, int rings, mx_pool *pool, mx_status *st) {
    if (tex->c != 3) return mx_fail(st, MX_EINPUT, "uv dilate: texture must be RGB (has %d channels)", tex->c);
    size_t n = (size_t)tex->w * tex->h;
    uint8_t *valid = malloc(n), *next = malloc(n);
    if (!valid || !next) {
        free(valid), free(next);
        return mx_fail(st, MX_ENOMEM, "uv dilate: out of memory");
    }
    memcpy(valid, known, n);
    for (int r = 0; r < rings; r++) dilate_once(tex, valid, next, pool);
    free(valid), free(next);
    return 0;
}

/* ---- harmonic fill over a texel graph that crosses UV seams ---- */

typedef struct texel_link {
    int32_t from, to;
} texel_link;

typedef struct link_list {
    texel_link *v;
    size_t n, cap;
} link_list;

static int link_push(link_list *l, int32_t a, int32_t b) {
    if (l->n + 2 > l->cap) {
        size_t cap = l->cap ? 2 * l->cap : 4096;
        texel_link *v = realloc(l->v, cap * sizeof *v);
        if (!v) return -1;
        l->v = v;
        l->cap = cap;
    }
    l->v[l->n++] = (texel_link){a, b};
    l->v[l->n++] = (texel_link){b, a};
    return 0;
}

static int cmp_link(const void *x, const void *y) {
    const texel_link *a = x, *b = y;
    if (a->from != b->from) return a->from < b->from ? -1 : 1;
    return (a->to > b->to) - (a->to < b->to);
}

/* One face edge under welded vertex ids a < b, with the UV indices at a and b. */
typedef struct uv_edge {
    int32_t face, ua, ub;
} uv_edge;

/* The UV indices of edge e at its lo and hi ends. */
static uv_edge uv_edge_of(const mx_mesh *m, const int32_t *canon, const mx_mesh_edge *e) {
    int32_t f = e->corner / 3, k = e->corner % 3, k1 = (k + 1) % 3;
    const int32_t *fu = m->face_uv + 3 * (size_t)f;
    int forward = canon[m->faces[3 * (size_t)f + k]] == e->lo;
    return (uv_edge){.face = f, .ua = forward ? fu[k] : fu[k1], .ub = forward ? fu[k1] : fu[k]};
}

static int same_uv(const mx_mesh *m, int32_t i, int32_t j) {
    return i == j || (m->uv[2 * (size_t)i] == m->uv[2 * (size_t)j] && m->uv[2 * (size_t)i + 1] == m->uv[2 * (size_t)j + 1]);
}

static int64_t texel_at(const mx_mesh *m, int32_t u0, int32_t u1, float t, int w, int h) {
    const float *p = m->uv + 2 * (size_t)u0, *q = m->uv + 2 * (size_t)u1;
    return mx_uv_texel(p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]), w, h);
}

/* Links, along a seam edge seen by faces e and f, the texels at the same points of the edge. */
static int link_seam(const mx_mesh *m, const uv_edge *e, const uv_edge *f, int w, int h, const uint8_t *chart,
                     link_list *l) {
    float len = 0;
    const uv_edge *side[2] = {e, f};
    for (int s = 0; s < 2; s++) {
        const float *p = m->uv + 2 * (size_t)side[s]->ua, *q = m->uv + 2 * (size_t)side[s]->ub;
        float d = hypotf((q[0] - p[0]) * (float)w, (q[1] - p[1]) * (float)h);
        if (d > len) len = d;
    }
    if (!(len < 4.0f * (float)(w + h))) return 0; /* NaN or absurd */
    int K = (int)ceilf(2.0f * len) + 1;
    for (int k = 0; k < K; k++) {
        float t = ((float)k + 0.5f) / (float)K;
        int64_t ta = texel_at(m, e->ua, e->ub, t, w, h), tb = texel_at(m, f->ua, f->ub, t, w, h);
        if (ta != tb && chart[ta] && chart[tb] && link_push(l, (int32_t)ta, (int32_t)tb)) return -1;
    }
    return 0;
}

/* An edge of face f takes part in the seams of this layer: f is in it and has UVs. */
static int edge_in_layer(const mx_mesh *m, const mx_mesh_edge *e, int layer, int nlayers) {
    int f = e->corner / 3;
    const int32_t *fu = m->face_uv + 3 * (size_t)f;
    return face_in_layer(m, f, layer, nlayers) && fu[0] >= 0 && fu[1] >= 0 && fu[2] >= 0;
}

/* Links the texels along edge p and q when their faces give it different UVs. */
static int link_if_seam(const mx_mesh *m, const int32_t *canon, const mx_mesh_edge *p, const mx_mesh_edge *q, int w,
                        int h, const uint8_t *chart, link_list *l) {
    uv_edge a = uv_edge_of(m, canon, p), b = uv_edge_of(m, canon, q);
    if (same_uv(m, a.ua, b.ua) && same_uv(m, a.ub, b.ub)) return 0;
    return link_seam(m, &a, &b, w, h, chart, l);
}

/* Seam links of one layer: every welded edge whose faces give it different UVs. */
static int seam_links(const mx_mesh *m, const int32_t *canon, int layer, int nlayers, int w, int h,
                      const uint8_t *chart, link_list *l, mx_status *st) {
    mx_mesh_edge *e;
    size_t n;
    if (mx_mesh_sorted_edges(m, canon, &e, &n, st)) return -1;
    int rc = 0;
    for (size_t i = 0; i < n && !rc;) {
        size_t j = mx_mesh_edge_run(e, n, i);
        for (size_t p = i; p < j && !rc; p++)
            for (size_t q = p + 1; q < j && !rc; q++)
                if (edge_in_layer(m, &e[p], layer, nlayers) && edge_in_layer(m, &e[q], layer, nlayers) &&
                    link_if_seam(m, canon, &e[p], &e[q], w, h, chart, l))
                    rc = mx_fail(st, MX_ENOMEM, "uv fill: out of memory");
        i = j;
    }
    free(e);
    return rc;
}

/* Faces f and g touch in 3D: the same face, or a shared welded vertex. */
static int faces_touch(const mx_mesh *m, const int32_t *canon, int32_t f, int32_t g) {
    if (f == g) return 1;
    if (f < 0 || g < 0) return 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            if (canon[m->faces[3 * (size_t)f + i]] == canon[m->faces[3 * (size_t)g + j]]) return 1;
    return 0;
}

/* The graph's neighbours of every unknown chart texel, as CSR over the unknown texels. */
typedef struct fill_graph {
    int32_t *unknown; /* [nu] texel ids */
    int32_t *start;   /* [nu + 1] */
    int32_t *nbr;     /* neighbour texel ids */
    size_t nu;
} fill_graph;

/* Frees and empties g, so that a second call (build_graph's failure, then the caller's
 * cleanup) frees nothing twice: found by the allocation fault sweep. */
static void fill_graph_free(fill_graph *g) {
    free(g->unknown);
    free(g->start);
    free(g->nbr);
    memset(g, 0, sizeof *g);
}

/* Neighbours of texel t (x, y): written to out (NULL: only counted). */
static int texel_neighbours(const mx_mesh *m, const int32_t *canon, const int32_t *face, const uint8_t *chart,
                            const link_list *l, const size_t *link_start, int w, int h, int32_t t, int32_t *out) {
    int x = t % w, y = t / w, n = 0;
    int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
    for (int k = 0; k < 4; k++) {
        if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
        int32_t o = ny[k] * w + nx[k];
        if (!chart[o] || !faces_touch(m, canon, face[t], face[o])) continue;
        if (out) out[n] = o;
        n++;
    }
    for (size_t i = link_start[t]; i < link_start[t + 1]; i++) {
        if (out) out[n] = l->v[i].to;
        n++;
    }
    return n;
}

static int build_graph(const mx_mesh *m, const int32_t *canon, const int32_t *face, const uint8_t *chart,
                       const uint8_t *known, const link_list *l, int w, int h, fill_graph *g, mx_status *st) {
    size_t n = (size_t)w * h, nu = 0, nn = 0;
    size_t *link_start = calloc(n + 1, sizeof *link_start);
    memset(g, 0, sizeof *g);
    if (!link_start) return mx_fail(st, MX_ENOMEM, "uv fill: out of memory");
    for (size_t i = 0; i < l->n; i++) link_start[l->v[i].from + 1]++;
    for (size_t t = 0; t < n; t++) link_start[t + 1] += link_start[t];
    for (size_t t = 0; t < n; t++)
        if (chart[t] && !known[t]) {
            nu++;
            nn += (size_t)texel_neighbours(m, canon, face, chart, l, link_start, w, h, (int32_t)t, NULL);
        }
    g->unknown = malloc((nu + 1) * sizeof *g->unknown);
    g->start = malloc((nu + 1) * sizeof *g->start);
    g->nbr = malloc((nn + 1) * sizeof *g->nbr);
    if (!g->unknown || !g->start || !g->nbr || nn > INT32_MAX) {
        free(link_start);
        fill_graph_free(g);
        return mx_fail(st, MX_ENOMEM, "uv fill: out of memory");
    }
    size_t u = 0, k = 0;
    for (size_t t = 0; t < n; t++)
        if (chart[t] && !known[t]) {
            g->unknown[u] = (int32_t)t;
            g->start[u++] = (int32_t)k;
            k += (size_t)texel_neighbours(m, canon, face, chart, l, link_start, w, h, (int32_t)t, g->nbr + k);
        }
    g->start[u] = (int32_t)k;
    g->nu = nu;
    free(link_start);
    return 0;
}

static int tick(const mx_uv_fill_ticker *t, double done, mx_status *st) {
    if (t && t->tick && t->tick(t->user, done)) return mx_fail(st, MX_ECANCEL, "interrupted");
    return 0;
}

/* Successive over-relaxation of the graph Laplace equation over the unknown texels. */
static int solve_harmonic(const fill_graph *g, float *col, const mx_uv_fill_ticker *ticker, mx_status *st) {
    const float omega = 1.9f;
    for (int it = 0; it < MX_UV_HARMONIC_ITERS; it++) {
        if (it % MX_UV_TICK_SWEEPS == 0 && tick(ticker, (double)it / MX_UV_HARMONIC_ITERS, st)) return -1;
        for (size_t u = 0; u < g->nu; u++) {
            int32_t s = g->start[u], e = g->start[u + 1];
            if (s == e) continue;
            float sum[3] = {0, 0, 0};
            for (int32_t k = s; k < e; k++)
                for (int c = 0; c < 3; c++) sum[c] += col[3 * (size_t)g->nbr[k] + c];
            float *x = col + 3 * (size_t)g->unknown[u];
            for (int c = 0; c < 3; c++) x[c] += omega * (sum[c] / (float)(e - s) - x[c]);
        }
    }
    return tick(ticker, 1.0, st);
}

int mx_uv_fill_harmonic(mx_image *tex, const uint8_t *known, const mx_mesh *m, int layer, int nlayers, int gutter,
                        const mx_uv_fill_ticker *ticker, mx_status *st) {
    if (tex->c != 3) return mx_fail(st, MX_EINPUT, "uv fill: texture must be RGB (has %d channels)", tex->c);
    if (!m->face_uv) return mx_fail(st, MX_EINPUT, "%s: no UVs to fill along", m->source_path);
    int w = tex->w, h = tex->h;
    size_t n = (size_t)w * h;
    uint8_t *chart = malloc(n), *valid = malloc(n), *next = malloc(n);
    int32_t *face = malloc(n * sizeof *face), *canon = malloc(((size_t)m->nverts + 1) * sizeof *canon);
    link_list links = {0};
    fill_graph g = {0};
    int rc = -1;
    if (!chart || !valid || !next || !face || !canon) {
        mx_fail(st, MX_ENOMEM, "uv fill: out of memory");
        goto done;
    }
    if (mx_uv_chart_faces(m, layer, nlayers, w, h, chart, face, st) || mx_mesh_weld_map(m, canon, st) ||
        seam_links(m, canon, layer, nlayers, w, h, chart, &links, st) || mx_uv_fill(tex, known, chart, 0, st))
        goto done;
    if (links.n) qsort(links.v, links.n, sizeof *links.v, cmp_link); /* links.v is NULL when there are none */
    if (build_graph(m, canon, face, chart, known, &links, w, h, &g, st)) goto done;
    if (solve_harmonic(&g, tex->data, ticker, st)) goto done;
    for (size_t i = 0; i < n; i++) valid[i] = known[i] || chart[i];
    for (int r = 0; r < gutter; r++) dilate_once(tex, valid, next, NULL);
    rc = 0;
done:
    fill_graph_free(&g);
    free(links.v);
    free(chart), free(valid), free(next), free(face), free(canon);
    return rc;
}
