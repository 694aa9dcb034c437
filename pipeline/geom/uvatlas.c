/* UV atlas: segment -> project (split until valid) -> merge small charts -> orient -> pack
 * -> write UVs.
 *
 * Segmentation grows charts breadth-first over edge-adjacent faces while a face's normal stays
 * within max_chart_angle of the chart's (area-weighted) mean normal. Each chart is projected
 * onto the plane of its mean normal; a chart whose projection tilts a face by more than
 * max_chart_angle + HARD_MARGIN_DEG or makes two triangles overlap is cut in two (median of the
 * face centroids along its longest 3D axis) until every chart projects injectively. Small
 * charts then join a neighbour when they fit on its plane (fewer seams). Each chart is turned
 * to its smallest bounding rectangle, and the charts are dropped onto a texel skyline by their
 * column profiles (tetris-like), all at one scale (uniform texel density): the largest scale
 * that fits, found by bisection. Everything is sequential and ordered by face index, so the
 * result is deterministic. */
#include "uvatlas.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "mesh.h"

/* A projected face may tilt at most max_chart_angle + HARD_MARGIN_DEG from its chart's plane
 * (the chart's mean normal drifts while it grows): 70 degrees by default, area stretch <= 2.9. */
#define HARD_MARGIN_DEG 10.0
#define MAX_CHART_ANGLE_DEG 75.0
#define ORIENT_STEPS 36      /* rotations tried (over 90 degrees) for the bounding rectangle */
#define PACK_BISECT_STEPS 10 /* scale bisection steps over [0, full]: 0.1% of the full scale */
#define DEGENERATE_AREA 1e-14 /* relative to the squared bounding-box diagonal */

typedef struct chart {
    int start, count;     /* range in atlas.order */
    int next, tail, total; /* merging: chain of absorbed charts, its last link, faces in all */
    double n[3], u[3], v[3]; /* projection normal and in-plane basis (u x v = n) */
    double cs, sn;        /* rotation to the smallest bounding rectangle */
    double x0, y0, w, h;  /* bounding rectangle in rotated plane coordinates */
    int seg_start, nseg;  /* boundary edges in atlas.seg */
    int px, py;           /* packed position (texels) */
    int turned;           /* packed turned by turned * 90 degrees */
} chart;

typedef struct atlas {
    const mx_mesh *m;
    double *fn;   /* [nfaces][3] unit face normals (0 for degenerate faces) */
    double *area; /* [nfaces] */
    int32_t *adj; /* [nfaces][3] neighbour across edge (k, k+1), -1 on a boundary */
    int32_t *order;   /* faces grouped by chart */
    chart *charts;
    int ncharts;
    double *xy;   /* [nfaces][3][2] scratch: projected corners, indexed by order position */
    int32_t *chart_of; /* [nfaces] chart index of each face */
    int32_t *weld;     /* [nverts] lowest vertex index at the same position */
    double *seg;  /* [3 * nfaces][4] chart boundary edges in rotated chart coordinates */
    double total_area;
} atlas;

/* ---------- small helpers ---------- */

/* fmin/fmax without the NaN rules, so that they inline (inputs here are finite). */
static inline double dmin(double a, double b) { return a < b ? a : b; }
static inline double dmax(double a, double b) { return a > b ? a : b; }

static double dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void cross3(const double *a, const double *b, double *out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static double normalize3(double *a) {
    double len = sqrt(dot3(a, a));
    if (len > 0) {
        a[0] /= len;
        a[1] /= len;
        a[2] /= len;
    }
    return len;
}

static void corner_pos(const mx_mesh *m, int f, int k, double *p) {
    const float *q = m->pos + 3 * (size_t)m->faces[3 * (size_t)f + k];
    p[0] = q[0];
    p[1] = q[1];
    p[2] = q[2];
}

/* ---------- input checks and face geometry ---------- */

static int check_mesh(const mx_mesh *m, mx_status *st) {
    if (m->nuv > 0 || m->uv || m->face_uv)
        return mx_fail(st, MX_EINPUT, "uv atlas: the mesh already has UVs (the atlas is for meshes without)");
    if (m->nfaces <= 0 || m->nverts <= 0 || !m->faces || !m->pos)
        return mx_fail(st, MX_EINPUT, "uv atlas: no faces to lay out");
    if (m->nfaces > INT32_MAX / 6)
        return mx_fail(st, MX_EINPUT, "uv atlas: %d faces is more than the atlas handles", m->nfaces);
    for (size_t i = 0; i < 3 * (size_t)m->nfaces; i++)
        if (m->faces[i] < 0 || m->faces[i] >= m->nverts)
            return mx_fail(st, MX_EINPUT, "uv atlas: face %zu has vertex index %d outside [0, %d)", i / 3,
                           (int)m->faces[i], m->nverts);
    for (size_t i = 0; i < 3 * (size_t)m->nverts; i++)
        if (!isfinite(m->pos[i])) return mx_fail(st, MX_EINPUT, "uv atlas: vertex %zu has a non-finite position", i / 3);
    return 0;
}

static void compute_face_geometry(atlas *a) {
    const mx_mesh *m = a->m;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY}, diag2 = 0;
    for (int v = 0; v < m->nverts; v++)
        for (int k = 0; k < 3; k++) {
            lo[k] = dmin(lo[k], m->pos[3 * (size_t)v + k]);
            hi[k] = dmax(hi[k], m->pos[3 * (size_t)v + k]);
        }
    for (int k = 0; k < 3; k++) diag2 += (hi[k] - lo[k]) * (hi[k] - lo[k]);
    a->total_area = 0;
    for (int f = 0; f < m->nfaces; f++) {
        double p0[3], p1[3], p2[3], e1[3], e2[3], *n = a->fn + 3 * (size_t)f;
        corner_pos(m, f, 0, p0);
        corner_pos(m, f, 1, p1);
        corner_pos(m, f, 2, p2);
        for (int i = 0; i < 3; i++) {
            e1[i] = p1[i] - p0[i];
            e2[i] = p2[i] - p0[i];
        }
        cross3(e1, e2, n);
        double len = normalize3(n);
        a->area[f] = 0.5 * len;
        if (a->area[f] <= DEGENERATE_AREA * diag2) n[0] = n[1] = n[2] = a->area[f] = 0;
        a->total_area += a->area[f];
    }
}

/* ---------- edge adjacency: an edge shared by exactly two faces links them ---------- */

/* Faces are neighbours across an edge of welded vertices (mx_mesh_weld_map), so that meshes
 * stored with split vertices (seams of an old layout, triangle soups) still have neighbours. */
static int build_adjacency(atlas *a, mx_status *st) {
    const mx_mesh *m = a->m;
    for (size_t c = 0; c < 3 * (size_t)m->nfaces; c++) a->adj[c] = -1;
    mx_mesh_edge *e;
    size_t ne;
    if (mx_mesh_weld_map(m, a->weld, st) || mx_mesh_sorted_edges(m, a->weld, &e, &ne, st)) return -1;
    for (size_t i = 0; i < ne;) {
        size_t j = mx_mesh_edge_run(e, ne, i);
        if (j - i == 2) { /* manifold edge; non-manifold ones stay seams */
            a->adj[e[i].corner] = e[i + 1].corner / 3;
            a->adj[e[i + 1].corner] = e[i].corner / 3;
        }
        i = j;
    }
    free(e);
    return 0;
}

/* ---------- segmentation by region growing ---------- */

/* Grows one chart from `seed` breadth-first; returns the number of faces taken. chart_of marks
 * assigned faces; `queued` (stamped with the chart id) keeps a face from being queued twice. */
static int grow_chart(atlas *a, int seed, int id, double cos_max, int32_t *chart_of, int32_t *queued,
                      int32_t *out) {
    double sum[3] = {0, 0, 0}, mean[3] = {0, 0, 0};
    int head = 0, tail = 0;
    out[tail++] = seed;
    queued[seed] = id;
    int taken = 0;
    while (head < tail) {
        int f = out[head++];
        const double *n = a->fn + 3 * (size_t)f;
        int accept = taken == 0 || a->area[f] == 0 || dot3(mean, mean) == 0 || dot3(n, mean) >= cos_max;
        if (!accept) continue;
        chart_of[f] = id;
        out[taken++] = f; /* taken <= head - 1 < tail, so this never overwrites the queue ahead */
        for (int i = 0; i < 3; i++) {
            sum[i] += a->area[f] * n[i];
            mean[i] = sum[i];
        }
        normalize3(mean);
        for (int k = 0; k < 3; k++) {
            int g = a->adj[3 * (size_t)f + k];
            if (g >= 0 && chart_of[g] < 0 && queued[g] != id) {
                queued[g] = id;
                out[tail++] = g;
            }
        }
    }
    return taken;
}

static int segment(atlas *a, double max_angle_deg) {
    int nf = a->m->nfaces;
    int32_t *chart_of = a->chart_of, *queued = malloc((size_t)nf * sizeof *queued);
    if (!queued) return -1;
    for (int f = 0; f < nf; f++) chart_of[f] = queued[f] = -1;
    double cos_max = cos(max_angle_deg * M_PI / 180.0);
    int pos = 0;
    a->ncharts = 0;
    for (int seed = 0; seed < nf; seed++) {
        if (chart_of[seed] >= 0) continue;
        int id = a->ncharts++;
        int n = grow_chart(a, seed, id, cos_max, chart_of, queued, a->order + pos);
        a->charts[id] = (chart){.start = pos, .count = n};
        pos += n;
    }
    free(queued);
    return 0;
}

/* Region growing leaves saw-tooth chart borders (a face that two faces of another chart
 * surround). Such a face moves to that chart when its normal fits there; every move removes at
 * least one border edge, so this ends. The charts are then regrouped into ranges of `order`
 * (faces by index within a chart) without the ones left empty. */
static int smooth_boundaries(atlas *a, double max_angle_deg) {
    int nf = a->m->nfaces, nc = a->ncharts;
    double *sum = calloc(3 * (size_t)nc, sizeof *sum);
    int32_t *first = calloc((size_t)nc + 1, sizeof *first), *renum = malloc((size_t)nc * sizeof *renum);
    if (!sum || !first || !renum) {
        free(sum), free(first), free(renum);
        return -1;
    }
    for (int f = 0; f < nf; f++)
        for (int k = 0; k < 3; k++) sum[3 * (size_t)a->chart_of[f] + k] += a->area[f] * a->fn[3 * (size_t)f + k];
    double cos_max = cos(max_angle_deg * M_PI / 180.0);
    for (int moved = 1; moved;) {
        moved = 0;
        for (int f = 0; f < nf; f++) {
            const int32_t *adj = a->adj + 3 * (size_t)f;
            int c = a->chart_of[f], x = -1;
            for (int k = 0; k < 3 && x < 0; k++) {
                int ck = adj[k] >= 0 ? a->chart_of[adj[k]] : -1;
                int ck1 = adj[(k + 1) % 3] >= 0 ? a->chart_of[adj[(k + 1) % 3]] : -1;
                if (ck >= 0 && ck != c && ck == ck1) x = ck;
            }
            if (x < 0) continue;
            double mean[3] = {sum[3 * (size_t)x], sum[3 * (size_t)x + 1], sum[3 * (size_t)x + 2]};
            const double *n = a->fn + 3 * (size_t)f;
            if (normalize3(mean) > 0 && a->area[f] > 0 && dot3(n, mean) < cos_max) continue;
            for (int k = 0; k < 3; k++) {
                sum[3 * (size_t)c + k] -= a->area[f] * n[k];
                sum[3 * (size_t)x + k] += a->area[f] * n[k];
            }
            a->chart_of[f] = x;
            moved++;
        }
    }
    for (int f = 0; f < nf; f++) first[a->chart_of[f] + 1]++;
    int kept = 0;
    for (int c = 0; c < nc; c++) renum[c] = first[c + 1] ? kept++ : -1;
    for (int c = 0; c < nc; c++) first[c + 1] += first[c];
    for (int c = 0; c < nc; c++)
        if (renum[c] >= 0) a->charts[renum[c]] = (chart){.start = first[c], .count = first[c + 1] - first[c]};
    for (int f = 0; f < nf; f++) {
        int c = a->chart_of[f];
        a->order[first[c]++] = f;
        a->chart_of[f] = renum[c];
    }
    a->ncharts = kept;
    free(sum), free(first), free(renum);
    return 0;
}

/* ---------- projection and validation ---------- */

static void chart_basis(atlas *a, chart *c) {
    double sum[3] = {0, 0, 0};
    for (int i = 0; i < c->count; i++) {
        int f = a->order[c->start + i];
        for (int k = 0; k < 3; k++) sum[k] += a->area[f] * a->fn[3 * (size_t)f + k];
    }
    if (normalize3(sum) == 0) sum[0] = 0, sum[1] = 0, sum[2] = 1;
    memcpy(c->n, sum, sizeof sum);
    /* v: perpendicular to n and to the coordinate axis least aligned with n; u = v x n, so that
     * u x v = n and front faces keep their counter-clockwise order in the plane. */
    double axis[3] = {0, 0, 0};
    int least = fabs(sum[0]) <= fabs(sum[1]) ? (fabs(sum[0]) <= fabs(sum[2]) ? 0 : 2)
                                             : (fabs(sum[1]) <= fabs(sum[2]) ? 1 : 2);
    axis[least] = 1;
    cross3(axis, c->n, c->v);
    normalize3(c->v);
    cross3(c->v, c->n, c->u);
    normalize3(c->u);
}

static void project_chart(atlas *a, const chart *c) {
    for (int i = 0; i < c->count; i++) {
        int f = a->order[c->start + i];
        double *xy = a->xy + 6 * (size_t)(c->start + i);
        for (int k = 0; k < 3; k++) {
            double p[3];
            corner_pos(a->m, f, k, p);
            xy[2 * k] = dot3(p, c->u);
            xy[2 * k + 1] = dot3(p, c->v);
        }
    }
}

static double tri_area2(const double *t) {
    return (t[2] - t[0]) * (t[5] - t[1]) - (t[4] - t[0]) * (t[3] - t[1]);
}

/* 1 if no edge normal of a or b separates them by more than eps: the interiors overlap. */
static int triangles_overlap(const double *a, const double *b, double eps) {
    const double *tris[2] = {a, b};
    for (int t = 0; t < 2; t++)
        for (int k = 0; k < 3; k++) {
            const double *p = tris[t] + 2 * k, *q = tris[t] + 2 * ((k + 1) % 3);
            double nx = q[1] - p[1], ny = p[0] - q[0];
            double len = sqrt(nx * nx + ny * ny);
            if (len == 0) return 0;
            nx /= len;
            ny /= len;
            double amin = INFINITY, amax = -INFINITY, bmin = INFINITY, bmax = -INFINITY;
            for (int j = 0; j < 3; j++) {
                double da = a[2 * j] * nx + a[2 * j + 1] * ny, db = b[2 * j] * nx + b[2 * j + 1] * ny;
                amin = dmin(amin, da), amax = dmax(amax, da);
                bmin = dmin(bmin, db), bmax = dmax(bmax, db);
            }
            if (amax <= bmin + eps || bmax <= amin + eps) return 0;
        }
    return 1;
}

typedef struct tri_box {
    double x0, y0, x1, y1;
} tri_box;

static tri_box triangle_box(const double *t) {
    return (tri_box){dmin(t[0], dmin(t[2], t[4])), dmin(t[1], dmin(t[3], t[5])),
                     dmax(t[0], dmax(t[2], t[4])), dmax(t[1], dmax(t[3], t[5]))};
}

/* Finds overlapping triangle pairs with a uniform grid over the chart (about one triangle per
 * cell). A pair is tested only in the cell holding the lower-left corner of the intersection of
 * their boxes, so each pair is tested once. Returns 1 on overlap, 0 if none, -1 on no memory. */
static int chart_self_overlaps(atlas *a, const chart *c) {
    int n = c->count;
    if (n < 2) return 0;
    const double *xy = a->xy + 6 * (size_t)c->start;
    tri_box all = triangle_box(xy);
    for (int i = 1; i < n; i++) {
        tri_box b = triangle_box(xy + 6 * (size_t)i);
        all.x0 = dmin(all.x0, b.x0), all.y0 = dmin(all.y0, b.y0);
        all.x1 = dmax(all.x1, b.x1), all.y1 = dmax(all.y1, b.y1);
    }
    double wx = all.x1 - all.x0, wy = all.y1 - all.y0, extent = dmax(wx, wy);
    if (extent <= 0) return 0;
    double cell = dmax(sqrt(wx * wy / n), extent / 1024.0);
    int gx = (int)dmin(wx / cell, 4096) + 1, gy = (int)dmin(wy / cell, 4096) + 1;
    double eps = 1e-9 * extent;
    size_t ncell = (size_t)gx * gy;
    int32_t *cstart = calloc(ncell + 1, sizeof *cstart);
    if (!cstart) return -1;
#define CELL_RANGE(b, cx0, cy0, cx1, cy1)                                           \
    int cx0 = (int)((b.x0 - all.x0) / cell), cx1 = (int)((b.x1 - all.x0) / cell);   \
    int cy0 = (int)((b.y0 - all.y0) / cell), cy1 = (int)((b.y1 - all.y0) / cell);   \
    cx0 = cx0 < gx ? cx0 : gx - 1, cx1 = cx1 < gx ? cx1 : gx - 1;                   \
    cy0 = cy0 < gy ? cy0 : gy - 1, cy1 = cy1 < gy ? cy1 : gy - 1
    size_t total = 0;
    for (int i = 0; i < n; i++) {
        tri_box b = triangle_box(xy + 6 * (size_t)i);
        CELL_RANGE(b, cx0, cy0, cx1, cy1);
        for (int y = cy0; y <= cy1; y++)
            for (int x = cx0; x <= cx1; x++) cstart[(size_t)y * gx + x + 1]++;
        total += (size_t)(cx1 - cx0 + 1) * (cy1 - cy0 + 1);
    }
    for (size_t i = 0; i < ncell; i++) cstart[i + 1] += cstart[i];
    int32_t *fill = malloc(ncell * sizeof *fill), *items = malloc((total ? total : 1) * sizeof *items);
    if (!fill || !items) {
        free(cstart), free(fill), free(items);
        return -1;
    }
    memcpy(fill, cstart, ncell * sizeof *fill);
    for (int i = 0; i < n; i++) {
        tri_box b = triangle_box(xy + 6 * (size_t)i);
        CELL_RANGE(b, cx0, cy0, cx1, cy1);
        for (int y = cy0; y <= cy1; y++)
            for (int x = cx0; x <= cx1; x++) items[fill[(size_t)y * gx + x]++] = i;
    }
    int found = 0;
    for (size_t cidx = 0; cidx < ncell && !found; cidx++) {
        int cx = (int)(cidx % gx), cy = (int)(cidx / gx);
        for (int p = cstart[cidx]; p < cstart[cidx + 1] && !found; p++)
            for (int q = p + 1; q < cstart[cidx + 1] && !found; q++) {
                const double *ta = xy + 6 * (size_t)items[p], *tb = xy + 6 * (size_t)items[q];
                tri_box ba = triangle_box(ta), bb = triangle_box(tb);
                tri_box in = {dmax(ba.x0, bb.x0), dmax(ba.y0, bb.y0), dmin(ba.x1, bb.x1), dmin(ba.y1, bb.y1)};
                if (in.x0 > in.x1 || in.y0 > in.y1) continue;
                CELL_RANGE(in, ix0, iy0, ix1, iy1);
                (void)ix1, (void)iy1;
                if (ix0 != cx || iy0 != cy) continue;
                found = triangles_overlap(ta, tb, eps);
            }
    }
#undef CELL_RANGE
    free(cstart), free(fill), free(items);
    return found;
}

/* 1 if the projection is injective and no face is tilted beyond the hard angle. A single
 * face always is (it lies in its own plane), which ends the splitting. */
static int chart_is_valid(atlas *a, const chart *c, double cos_hard, int *nomem) {
    if (c->count == 1) return 1;
    for (int i = 0; i < c->count; i++) {
        int f = a->order[c->start + i];
        if (a->area[f] == 0) continue;
        if (dot3(a->fn + 3 * (size_t)f, c->n) < cos_hard) return 0;
        if (tri_area2(a->xy + 6 * (size_t)(c->start + i)) <= 0) return 0;
    }
    int r = chart_self_overlaps(a, c);
    if (r < 0) *nomem = 1;
    return r == 0;
}

typedef struct keyed_face {
    double key;
    int32_t face;
} keyed_face;

static int keyed_face_cmp(const void *pa, const void *pb) {
    const keyed_face *a = pa, *b = pb;
    if (a->key != b->key) return a->key < b->key ? -1 : 1;
    return (a->face > b->face) - (a->face < b->face);
}

/* Keeps the first edge-connected component of chart `id` and moves the other faces to a new
 * chart (which is peeled the same way when its turn comes), so every chart is one piece. */
static void peel_first_component(atlas *a, int id, int32_t *visit, int stamp, int32_t *buf) {
    chart *c = &a->charts[id];
    int head = 0, tail = 0, first = a->order[c->start];
    buf[tail++] = first;
    visit[first] = stamp;
    while (head < tail) {
        int f = buf[head++];
        for (int k = 0; k < 3; k++) {
            int g = a->adj[3 * (size_t)f + k];
            if (g >= 0 && a->chart_of[g] == id && visit[g] != stamp) {
                visit[g] = stamp;
                buf[tail++] = g;
            }
        }
    }
    if (tail == c->count) return;
    int rest = tail, nid = a->ncharts++;
    for (int i = 0; i < c->count; i++) {
        int f = a->order[c->start + i];
        if (visit[f] != stamp) {
            buf[rest++] = f;
            a->chart_of[f] = nid;
        }
    }
    memcpy(a->order + c->start, buf, (size_t)c->count * sizeof *buf);
    a->charts[nid] = (chart){.start = c->start + tail, .count = c->count - tail};
    c->count = tail;
}

/* Splits chart c at the median of its face centroids along its longest 3D axis; the second half
 * becomes a new chart (compact halves pack better than a split along normals). */
static void split_chart(atlas *a, chart *c, keyed_face *tmp) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < c->count; i++) {
        int f = a->order[c->start + i];
        for (int k = 0; k < 3; k++) {
            double p[3];
            corner_pos(a->m, f, k, p);
            for (int d = 0; d < 3; d++) lo[d] = dmin(lo[d], p[d]), hi[d] = dmax(hi[d], p[d]);
        }
    }
    int axis = 0;
    for (int d = 1; d < 3; d++)
        if (hi[d] - lo[d] > hi[axis] - lo[axis]) axis = d;
    for (int i = 0; i < c->count; i++) {
        int f = a->order[c->start + i];
        double s = 0;
        for (int k = 0; k < 3; k++) s += a->m->pos[3 * (size_t)a->m->faces[3 * (size_t)f + k] + axis];
        tmp[i] = (keyed_face){s, f};
    }
    qsort(tmp, c->count, sizeof *tmp, keyed_face_cmp);
    int half = c->count / 2, nid = a->ncharts++;
    for (int i = 0; i < c->count; i++) {
        a->order[c->start + i] = tmp[i].face;
        if (i >= half) a->chart_of[tmp[i].face] = nid;
    }
    a->charts[nid] = (chart){.start = c->start + half, .count = c->count - half};
    c->count = half;
}

/* Straightens the cut between chart `id` and its second half `nid` (adjacent ranges): a face
 * whose two neighbours lie in the other half moves there, until none does; then the range is
 * partitioned again. A median cut through a mesh is saw-toothed otherwise. */
static void smooth_cut(atlas *a, int id, int nid, int32_t *buf) {
    chart *c = &a->charts[id], *d = &a->charts[nid];
    int start = c->start, n = c->count + d->count;
    for (int moved = 1; moved;) {
        moved = 0;
        for (int i = 0; i < n; i++) {
            int f = a->order[start + i], other = a->chart_of[f] == id ? nid : id, near = 0;
            for (int k = 0; k < 3; k++) {
                int g = a->adj[3 * (size_t)f + k];
                near += g >= 0 && a->chart_of[g] == other;
            }
            if (near >= 2) a->chart_of[f] = other, moved++;
        }
    }
    int kept = 0, rest = n;
    for (int i = 0; i < n; i++) {
        int f = a->order[start + i];
        if (a->chart_of[f] == id) buf[kept++] = f;
        else buf[--rest] = f;
    }
    if (kept == 0 || kept == n) { /* both halves must stay non-empty: undo */
        for (int i = 0; i < n; i++) a->chart_of[a->order[start + i]] = i < c->count ? id : nid;
        return;
    }
    for (int i = 0; i < kept; i++) a->order[start + i] = buf[i];
    for (int i = kept; i < n; i++) a->order[start + i] = buf[n - 1 - (i - kept)];
    c->count = kept;
    d->start = start + kept, d->count = n - kept;
}

/* Projects every chart, splitting the ones that fold until all are valid. */
static int project_all(atlas *a, double max_angle_deg, mx_status *st) {
    double cos_hard = cos((max_angle_deg + HARD_MARGIN_DEG) * M_PI / 180.0);
    size_t nf = (size_t)a->m->nfaces;
    keyed_face *tmp = malloc(nf * sizeof *tmp);
    int32_t *visit = malloc(nf * sizeof *visit), *buf = malloc(nf * sizeof *buf);
    if (!tmp || !visit || !buf) {
        free(tmp), free(visit), free(buf);
        return mx_fail(st, MX_ENOMEM, "uv atlas: out of memory");
    }
    for (size_t f = 0; f < nf; f++) visit[f] = -1;
    int splits = 0, stamp = 0, grown = a->ncharts;
    for (int i = 0; i < a->ncharts; i++) {
        for (;;) {
            peel_first_component(a, i, visit, stamp++, buf);
            chart *c = &a->charts[i];
            chart_basis(a, c);
            project_chart(a, c);
            int nomem = 0;
            if (chart_is_valid(a, c, cos_hard, &nomem)) break;
            if (nomem) {
                free(tmp), free(visit), free(buf);
                return mx_fail(st, MX_ENOMEM, "uv atlas: out of memory checking chart overlap");
            }
            split_chart(a, c, tmp); /* count >= 2 here: one face is always valid */
            smooth_cut(a, i, a->ncharts - 1, buf);
            splits++;
        }
    }
    free(tmp), free(visit), free(buf);
    mx_debug("uv atlas: %d charts grown, %d after %d splits", grown, a->ncharts, splits);
    return 0;
}

/* ---------- merging small charts into a neighbour ----------
 * Splitting and growing leave many small charts, each costing a gutter ring in the atlas. A
 * chart is merged into a neighbouring chart (most shared edges first) when, projected onto that
 * chart's plane, its faces stay within the growing angle, keep their orientation and overlap
 * nothing. The neighbour keeps its basis, so its own projection does not change. Merged charts
 * form chains (chart.next) that are gathered into ranges again at the end. */

#define MERGE_MAX_FACES 20 /* larger charts are left alone (their projection is good) */

typedef struct merge_scratch {
    double *xy;          /* [MERGE_MAX_FACES][6] the small chart on the neighbour's plane */
    int32_t *near;       /* [nfaces] the neighbour's triangles (order positions) near it */
    int32_t *nb, *shared; /* [MERGE_MAX_FACES * 3] neighbour charts and shared edge counts */
} merge_scratch;

/* Neighbour charts of chart `id` (its chain), sorted by shared edges, most first. */
static int chart_neighbours(const atlas *a, int id, merge_scratch *ms) {
    int n = 0;
    for (int ci = id; ci >= 0; ci = a->charts[ci].next) {
        const chart *c = &a->charts[ci];
        for (int i = 0; i < c->count; i++) {
            int f = a->order[c->start + i];
            for (int k = 0; k < 3; k++) {
                int g = a->adj[3 * (size_t)f + k];
                if (g < 0 || a->chart_of[g] == id) continue;
                int j = 0;
                while (j < n && ms->nb[j] != a->chart_of[g]) j++;
                if (j == n) ms->nb[n] = a->chart_of[g], ms->shared[n++] = 0;
                ms->shared[j]++;
            }
        }
    }
    for (int i = 1; i < n; i++) /* insertion sort: shared desc, id asc */
        for (int j = i; j > 0 && (ms->shared[j] > ms->shared[j - 1] ||
                                  (ms->shared[j] == ms->shared[j - 1] && ms->nb[j] < ms->nb[j - 1]));
             j--) {
            int t = ms->nb[j];
            ms->nb[j] = ms->nb[j - 1], ms->nb[j - 1] = t;
            t = ms->shared[j], ms->shared[j] = ms->shared[j - 1], ms->shared[j - 1] = t;
        }
    return n;
}

/* 1 if chart `small` (chain) can join chart `big`: fills ms->xy with its projection. */
static int merge_fits(const atlas *a, int big, int small, double cos_max, merge_scratch *ms) {
    const chart *d = &a->charts[big];
    int n = 0;
    tri_box box = {INFINITY, INFINITY, -INFINITY, -INFINITY};
    for (int ci = small; ci >= 0; ci = a->charts[ci].next) {
        const chart *c = &a->charts[ci];
        for (int i = 0; i < c->count; i++, n++) {
            int f = a->order[c->start + i];
            if (a->area[f] > 0 && dot3(a->fn + 3 * (size_t)f, d->n) < cos_max) return 0;
            double *t = ms->xy + 6 * (size_t)n;
            for (int k = 0; k < 3; k++) {
                double p[3];
                corner_pos(a->m, f, k, p);
                t[2 * k] = dot3(p, d->u), t[2 * k + 1] = dot3(p, d->v);
            }
            if (a->area[f] > 0 && tri_area2(t) <= 0) return 0;
            tri_box b = triangle_box(t);
            box.x0 = dmin(box.x0, b.x0), box.y0 = dmin(box.y0, b.y0);
            box.x1 = dmax(box.x1, b.x1), box.y1 = dmax(box.y1, b.y1);
        }
    }
    double eps = 1e-9 * dmax(dmax(fabs(box.x0), fabs(box.x1)), dmax(fabs(box.y0), fabs(box.y1)));
    int nnear = 0;
    for (int ci = big; ci >= 0; ci = a->charts[ci].next) {
        const chart *c = &a->charts[ci];
        for (int i = 0; i < c->count; i++) {
            tri_box b = triangle_box(a->xy + 6 * (size_t)(c->start + i));
            if (b.x0 <= box.x1 && b.x1 >= box.x0 && b.y0 <= box.y1 && b.y1 >= box.y0) ms->near[nnear++] = c->start + i;
        }
    }
    for (int i = 0; i < n; i++) {
        const double *t = ms->xy + 6 * (size_t)i;
        for (int j = 0; j < nnear; j++)
            if (triangles_overlap(t, a->xy + 6 * (size_t)ms->near[j], eps)) return 0;
        for (int j = i + 1; j < n; j++)
            if (triangles_overlap(t, ms->xy + 6 * (size_t)j, eps)) return 0;
    }
    return 1;
}

static void merge_commit(atlas *a, int big, int small, const merge_scratch *ms) {
    int n = 0;
    for (int ci = small; ci >= 0; ci = a->charts[ci].next) {
        const chart *c = &a->charts[ci];
        memcpy(a->xy + 6 * (size_t)c->start, ms->xy + 6 * (size_t)n, 6 * (size_t)c->count * sizeof *a->xy);
        n += c->count;
        for (int i = 0; i < c->count; i++) a->chart_of[a->order[c->start + i]] = big;
    }
    a->charts[a->charts[big].tail].next = small;
    a->charts[big].tail = a->charts[small].tail;
    a->charts[big].total += a->charts[small].total;
    a->charts[small].total = 0; /* absorbed */
}

/* Gathers every remaining chain into one range of a fresh face order and renumbers the charts. */
static int gather_chains(atlas *a) {
    size_t nf = (size_t)a->m->nfaces;
    int32_t *order = malloc(nf * sizeof *order);
    double *xy = malloc(6 * nf * sizeof *xy);
    chart *charts = malloc(nf * sizeof *charts);
    if (!order || !xy || !charts) {
        free(order), free(xy), free(charts);
        return -1;
    }
    int pos = 0, kept = 0;
    for (int id = 0; id < a->ncharts; id++) {
        if (a->charts[id].total == 0) continue;
        chart head = a->charts[id];
        for (int ci = id; ci >= 0; ci = a->charts[ci].next) {
            const chart *c = &a->charts[ci];
            memcpy(order + pos, a->order + c->start, (size_t)c->count * sizeof *order);
            memcpy(xy + 6 * (size_t)pos, a->xy + 6 * (size_t)c->start, 6 * (size_t)c->count * sizeof *xy);
            pos += c->count;
        }
        head.start = pos - head.total, head.count = head.total, head.next = -1, head.tail = kept;
        for (int i = head.start; i < pos; i++) a->chart_of[order[i]] = kept;
        charts[kept++] = head;
    }
    free(a->order), free(a->xy), free(a->charts);
    a->order = order, a->xy = xy, a->charts = charts, a->ncharts = kept;
    return 0;
}

static int merge_small_charts(atlas *a, double max_angle_deg, mx_status *st) {
    size_t nf = (size_t)a->m->nfaces;
    merge_scratch ms = {malloc(6 * (size_t)MERGE_MAX_FACES * sizeof *ms.xy), malloc(nf * sizeof *ms.near),
                        malloc(3 * (size_t)MERGE_MAX_FACES * sizeof *ms.nb),
                        malloc(3 * (size_t)MERGE_MAX_FACES * sizeof *ms.shared)};
    keyed_face *by_size = malloc((size_t)a->ncharts * sizeof *by_size);
    int rc = 0, before = a->ncharts;
    if (!ms.xy || !ms.near || !ms.nb || !ms.shared || !by_size) rc = -1;
    for (int i = 0; !rc && i < a->ncharts; i++) {
        chart *c = &a->charts[i];
        c->next = -1, c->tail = i, c->total = c->count;
        by_size[i] = (keyed_face){c->count, i};
    }
    if (!rc) qsort(by_size, a->ncharts, sizeof *by_size, keyed_face_cmp);
    double cos_max = cos(max_angle_deg * M_PI / 180.0);
    for (int r = 0; !rc && r < a->ncharts; r++) {
        int small = by_size[r].face;
        if (a->charts[small].total == 0 || a->charts[small].total > MERGE_MAX_FACES) continue;
        int nn = chart_neighbours(a, small, &ms);
        for (int j = 0; j < nn; j++)
            if (merge_fits(a, ms.nb[j], small, cos_max, &ms)) {
                merge_commit(a, ms.nb[j], small, &ms);
                break;
            }
    }
    if (!rc) rc = gather_chains(a);
    free(ms.xy), free(ms.near), free(ms.nb), free(ms.shared), free(by_size);
    if (rc) return mx_fail(st, MX_ENOMEM, "uv atlas: out of memory merging charts");
    mx_debug("uv atlas: %d charts merged into %d", before, a->ncharts);
    return 0;
}

/* ---------- orientation: smallest bounding rectangle over a few rotations ---------- */

static void orient_chart(atlas *a, chart *c) {
    const double *xy = a->xy + 6 * (size_t)c->start;
    double best = INFINITY;
    for (int s = 0; s < ORIENT_STEPS; s++) {
        double ang = 0.5 * M_PI * s / ORIENT_STEPS, cs = cos(ang), sn = sin(ang);
        double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
        for (int i = 0; i < 3 * c->count; i++) {
            double x = cs * xy[2 * i] - sn * xy[2 * i + 1], y = sn * xy[2 * i] + cs * xy[2 * i + 1];
            x0 = dmin(x0, x), x1 = dmax(x1, x), y0 = dmin(y0, y), y1 = dmax(y1, y);
        }
        double area = (x1 - x0) * (y1 - y0);
        if (area < best) {
            best = area;
            c->cs = cs, c->sn = sn, c->x0 = x0, c->y0 = y0, c->w = x1 - x0, c->h = y1 - y0;
        }
    }
}

/* ---------- packing: charts dropped onto a texel skyline (tetris-like) ----------
 * At a given scale each chart, in each of its four 90-degree turns, is reduced to the texel
 * columns its conservative raster covers: per column the lowest and the highest covered row.
 * The atlas keeps, per texel column, the first free row (everything below counts as used).
 * A chart goes where the top of its box is lowest; the skyline is then raised to its top
 * profile dilated by the gutter, so charts interlock without ever coming closer than the
 * gutter. Positions are whole texels, so the UVs rasterise exactly as the profiles did. */

#define PROFILE_EPS 0.01 /* texels: profiles are taken this much wider than the triangles */

typedef struct profile {
    int width;          /* columns, from 0 */
    int first, last;    /* non-empty columns */
    int height;         /* max of top */
    int *bottom, *top;  /* [width] lowest covered row, highest covered row + 1 */
} profile;

/* Rotated chart coordinates (X, Y) in [0, w] x [0, h] to texels for turn k: scaled, turned by
 * k * 90 degrees counter-clockwise (orientation kept), moved back into the positive quadrant,
 * plus a one-texel margin so that nothing lands on a negative column. */
static void turn_point(const chart *c, int k, double scale, double X, double Y, double *tx, double *ty) {
    double W = c->w * scale, H = c->h * scale;
    X *= scale, Y *= scale;
    switch (k) {
    case 0: *tx = X, *ty = Y; break;
    case 1: *tx = H - Y, *ty = X; break;
    case 2: *tx = W - X, *ty = H - Y; break;
    default: *tx = Y, *ty = W - X; break;
    }
    *tx += 1, *ty += 1;
}

static void rotate_point(const chart *c, double x, double y, double *X, double *Y) {
    *X = c->cs * x - c->sn * y - c->x0;
    *Y = c->sn * x + c->cs * y - c->y0;
}

/* The chart's boundary edges (no neighbour in the same chart): the column extents of a chart
 * are those of its boundary, a few edges instead of all its triangles. */
static void collect_boundary(atlas *a) {
    int n = 0;
    for (int ci = 0; ci < a->ncharts; ci++) {
        chart *c = &a->charts[ci];
        c->seg_start = n;
        for (int i = 0; i < c->count; i++) {
            int f = a->order[c->start + i];
            const double *xy = a->xy + 6 * (size_t)(c->start + i);
            for (int k = 0; k < 3; k++) {
                int g = a->adj[3 * (size_t)f + k], k1 = (k + 1) % 3;
                if (g >= 0 && a->chart_of[g] == ci) continue;
                double *sg = a->seg + 4 * (size_t)n++;
                rotate_point(c, xy[2 * k], xy[2 * k + 1], &sg[0], &sg[1]);
                rotate_point(c, xy[2 * k1], xy[2 * k1 + 1], &sg[2], &sg[3]);
            }
        }
        c->nseg = n - c->seg_start;
    }
}

static int profile_width(const chart *c, int k, double scale) {
    double w = (k & 1 ? c->h : c->w) * scale;
    return (int)floor(w + 2 + PROFILE_EPS) + 1;
}

/* Marks rows lo..hi (texels, widened by PROFILE_EPS) as covered in column col. */
static void profile_cover(profile *pr, int col, double lo, double hi) {
    int r0 = (int)floor(lo - PROFILE_EPS), r1 = (int)floor(hi + PROFILE_EPS) + 1;
    if (r0 < 0) r0 = 0;
    if (r0 < pr->bottom[col]) pr->bottom[col] = r0;
    if (r1 > pr->top[col]) pr->top[col] = r1;
}

static void build_profile(const atlas *a, const chart *c, int k, double scale, profile *pr) {
    for (int i = 0; i < pr->width; i++) pr->bottom[i] = INT32_MAX, pr->top[i] = INT32_MIN;
    for (int i = 0; i < c->nseg; i++) {
        const double *sg = a->seg + 4 * (size_t)(c->seg_start + i);
        double px, py, qx, qy;
        turn_point(c, k, scale, sg[0], sg[1], &px, &py);
        turn_point(c, k, scale, sg[2], sg[3], &qx, &qy);
        if (px > qx) {
            double t = px;
            px = qx, qx = t, t = py, py = qy, qy = t;
        }
        int c0 = (int)floor(px - PROFILE_EPS), c1 = (int)floor(qx + PROFILE_EPS);
        if (c0 < 0) c0 = 0;
        if (c1 >= pr->width) c1 = pr->width - 1;
        for (int col = c0; col <= c1; col++) {
            /* The segment's y over the strip [col, col + 1] (widened), clipped to its ends. */
            double xa = dmax(px, col - PROFILE_EPS), xb = dmin(qx, col + 1 + PROFILE_EPS);
            double ya = py, yb = qy;
            if (qx > px) {
                double slope = (qy - py) / (qx - px);
                ya = py + slope * (xa - px), yb = py + slope * (xb - px);
            }
            profile_cover(pr, col, dmin(ya, yb), dmax(ya, yb));
        }
    }
    pr->first = -1, pr->last = -1, pr->height = 0;
    for (int i = 0; i < pr->width; i++) {
        if (pr->top[i] == INT32_MIN) continue;
        if (pr->first < 0) pr->first = i;
        pr->last = i;
        pr->height = pr->top[i] > pr->height ? pr->top[i] : pr->height;
    }
}

typedef struct placement {
    int x, y, top; /* top = y + profile height; INT32_MAX when it does not fit */
} placement;

/* Rest height of profile pr with its column 0 at x, or `limit` as soon as it reaches it. */
static int rest_height(const int *sky, const profile *pr, int x, int limit) {
    int y = 0;
    for (int i = pr->first; i <= pr->last && y < limit; i++) {
        int need = sky[x + i] - pr->bottom[i]; /* empty columns: bottom = INT32_MAX */
        if (pr->top[i] != INT32_MIN && need > y) y = need;
    }
    return y;
}

/* Lowest-top position of profile pr on the skyline if better than `best`. Wide charts are
 * tried every `step` columns first, then column by column around the best of those. */
static placement best_position(const int *sky, int size, const profile *pr, placement best) {
    if (pr->first < 0) return (placement){0, 0, 0};
    int xmin = -pr->first, xmax = size - 1 - pr->last, step = 1 + (pr->last - pr->first) / 24;
    if (xmax < xmin) return best;
    int coarse_x = xmin;
    placement coarse = best;
    for (int x = xmin;; x = x + step < xmax ? x + step : xmax) {
        int y = rest_height(sky, pr, x, coarse.top - pr->height);
        if (y < coarse.top - pr->height) coarse = (placement){x, y, y + pr->height}, coarse_x = x;
        if (x == xmax) break;
    }
    if (coarse.top == best.top) return best; /* nothing better on the coarse grid */
    best = coarse;
    int lo = coarse_x - step + 1 > xmin ? coarse_x - step + 1 : xmin;
    int hi = coarse_x + step - 1 < xmax ? coarse_x + step - 1 : xmax;
    for (int x = lo; x <= hi; x++) {
        int y = rest_height(sky, pr, x, best.top - pr->height);
        if (y < best.top - pr->height) best = (placement){x, y, y + pr->height};
    }
    return best;
}

static void raise_skyline(int *sky, int size, const profile *pr, placement p, int gutter) {
    for (int i = pr->first; i <= pr->last; i++) {
        if (pr->top[i] == INT32_MIN) continue;
        int h = p.y + pr->top[i] + gutter;
        for (int j = p.x + i - gutter; j <= p.x + i + gutter; j++)
            if (j >= 0 && j < size && sky[j] < h) sky[j] = h;
    }
}

typedef struct packing {
    int *sky;      /* [size] */
    int *columns;  /* profile storage */
    size_t ncolumns;
} packing;

/* Packs every chart at `scale`; returns 1 if all fit in size x size, 0 if not, -1 without
 * memory. With commit, records each chart's turn and position. */
static int pack_at_scale(atlas *a, const int32_t *order, double scale, int size, int gutter, packing *pk,
                         int commit) {
    /* The four turns of one chart at a time: bottom and top rows of each turn's columns. */
    size_t need = 0;
    for (int i = 0; i < a->ncharts; i++) {
        size_t chart_need = 0;
        for (int k = 0; k < 4; k++) chart_need += 2 * (size_t)profile_width(&a->charts[i], k, scale);
        if (chart_need > need) need = chart_need;
    }
    if (need > pk->ncolumns) {
        free(pk->columns);
        pk->columns = malloc(need * sizeof *pk->columns);
        pk->ncolumns = pk->columns ? need : 0;
        if (!pk->columns) return -1;
    }
    for (int i = 0; i < size; i++) pk->sky[i] = 0;
    for (int r = 0; r < a->ncharts; r++) {
        chart *c = &a->charts[order[r]];
        profile pr[4];
        placement best = {0, 0, INT32_MAX};
        int best_k = 0;
        for (int k = 0; k < 4; k++) {
            pr[k].width = profile_width(c, k, scale);
            pr[k].bottom = pk->columns + (k == 0 ? 0 : (size_t)(pr[k - 1].top - pk->columns) + pr[k - 1].width);
            pr[k].top = pr[k].bottom + pr[k].width;
            build_profile(a, c, k, scale, &pr[k]);
            placement p = best_position(pk->sky, size, &pr[k], best);
            if (p.top < best.top) best = p, best_k = k;
        }
        if (best.top > size) return 0;
        raise_skyline(pk->sky, size, &pr[best_k], best, gutter);
        if (commit) c->px = best.x, c->py = best.y, c->turned = best_k;
    }
    return 1;
}

static int32_t *chart_order_by_size(atlas *a) {
    keyed_face *k = malloc((size_t)a->ncharts * sizeof *k);
    int32_t *order = malloc((size_t)a->ncharts * sizeof *order);
    if (!k || !order) {
        free(k), free(order);
        return NULL;
    }
    for (int i = 0; i < a->ncharts; i++) k[i] = (keyed_face){-dmax(a->charts[i].w, a->charts[i].h), i};
    qsort(k, a->ncharts, sizeof *k, keyed_face_cmp);
    for (int i = 0; i < a->ncharts; i++) order[i] = k[i].face;
    free(k);
    return order;
}

/* Bisection on the common scale: the largest one whose packing fits in size x size. The upper
 * bound is the scale at which the charts alone would fill the square. */
static int pack_charts(atlas *a, int size, int gutter, double *scale_out, mx_status *st) {
    double area2d = 0;
    for (int i = 0; i < a->ncharts; i++) {
        const chart *c = &a->charts[i];
        for (int j = 0; j < c->count; j++) area2d += 0.5 * tri_area2(a->xy + 6 * (size_t)(c->start + j));
    }
    int32_t *order = chart_order_by_size(a);
    packing pk = {malloc((size_t)size * sizeof *pk.sky), NULL, 0};
    if (!order || !pk.sky) {
        free(order), free(pk.sky);
        return mx_fail(st, MX_ENOMEM, "uv atlas: out of memory packing %d charts", a->ncharts);
    }
    int fits = 1;
    double lo = 0, hi = area2d > 0 ? size / sqrt(area2d) : 1.0;
    for (int s = 0; fits >= 0 && s < PACK_BISECT_STEPS; s++) {
        double mid = 0.5 * (lo + hi);
        fits = pack_at_scale(a, order, mid, size, gutter, &pk, 0);
        if (fits > 0) lo = mid;
        else hi = mid;
    }
    if (fits >= 0 && lo > 0) fits = pack_at_scale(a, order, lo, size, gutter, &pk, 1);
    int rc = 0;
    if (fits < 0) rc = mx_fail(st, MX_ENOMEM, "uv atlas: out of memory packing %d charts", a->ncharts);
    else if (lo == 0 || fits == 0) /* (the final packing repeats a successful one: it fits) */
        rc = mx_fail(st, MX_EINPUT, "uv atlas: %d charts do not fit in a %dx%d texture with a %d-texel gutter",
                     a->ncharts, size, size, gutter);
    *scale_out = lo;
    free(order), free(pk.sky), free(pk.columns);
    return rc;
}

/* ---------- output ---------- */

static void chart_to_uv(const chart *c, double x, double y, double scale, double size, float *uv) {
    double X, Y, tx, ty;
    rotate_point(c, x, y, &X, &Y);
    turn_point(c, c->turned, scale, X, Y, &tx, &ty);
    uv[0] = (float)((c->px + tx) / size);
    uv[1] = (float)((c->py + ty) / size);
}

/* One UV per (chart, welded vertex): vertices on a chart boundary get one UV in each chart. */
static int write_uvs(atlas *a, mx_mesh *m, double scale, int size, mx_status *st) {
    int32_t *slot = malloc((size_t)m->nverts * sizeof *slot), *stamp = malloc((size_t)m->nverts * sizeof *stamp);
    int32_t *face_uv = malloc(3 * (size_t)m->nfaces * sizeof *face_uv);
    float *uv = malloc(6 * (size_t)m->nfaces * sizeof *uv); /* at most 3 per face; trimmed below */
    if (!slot || !stamp || !face_uv || !uv) {
        free(slot), free(stamp), free(face_uv), free(uv);
        return mx_fail(st, MX_ENOMEM, "uv atlas: out of memory for the UVs");
    }
    for (int v = 0; v < m->nverts; v++) stamp[v] = -1;
    int nuv = 0;
    for (int ci = 0; ci < a->ncharts; ci++) {
        const chart *c = &a->charts[ci];
        for (int i = 0; i < c->count; i++) {
            int f = a->order[c->start + i];
            const double *xy = a->xy + 6 * (size_t)(c->start + i);
            for (int k = 0; k < 3; k++) {
                int v = a->weld[m->faces[3 * (size_t)f + k]];
                if (stamp[v] != ci) {
                    stamp[v] = ci;
                    slot[v] = nuv;
                    chart_to_uv(c, xy[2 * k], xy[2 * k + 1], scale, size, uv + 2 * (size_t)nuv);
                    nuv++;
                }
                face_uv[3 * (size_t)f + k] = slot[v];
            }
        }
    }
    free(slot), free(stamp);
    float *trimmed = realloc(uv, 2 * (size_t)nuv * sizeof *uv);
    m->uv = trimmed ? trimmed : uv;
    m->nuv = nuv;
    m->face_uv = face_uv;
    return 0;
}

static void measure(const atlas *a, const mx_mesh *m, double scale, int size, mx_uvatlas_report *r) {
    double covered = 0, weighted = 0, smax = 0;
    for (int f = 0; f < m->nfaces; f++) {
        const float *p = m->uv + 2 * (size_t)m->face_uv[3 * (size_t)f];
        const float *q = m->uv + 2 * (size_t)m->face_uv[3 * (size_t)f + 1];
        const float *s = m->uv + 2 * (size_t)m->face_uv[3 * (size_t)f + 2];
        double uv_area = 0.5 * fabs((double)(q[0] - p[0]) * (s[1] - p[1]) - (double)(s[0] - p[0]) * (q[1] - p[1]));
        covered += uv_area;
        if (a->area[f] == 0 || uv_area == 0) continue;
        double stretch = a->area[f] * scale * scale / (uv_area * (double)size * size);
        weighted += a->area[f] * stretch;
        smax = dmax(smax, stretch);
    }
    r->charts = a->ncharts;
    r->utilisation = covered;
    r->stretch_mean = a->total_area > 0 ? weighted / a->total_area : 1;
    r->stretch_max = smax;
}

/* ---------- entry points ---------- */

mx_uvatlas_opts mx_uvatlas_defaults(void) {
    return (mx_uvatlas_opts){.texture_size = 1024, .gutter = 2, .max_chart_angle = 60.0f};
}

static int resolve_opts(const mx_uvatlas_opts *o, mx_uvatlas_opts *out, mx_status *st) {
    *out = mx_uvatlas_defaults();
    if (!o) return 0;
    if (o->texture_size) out->texture_size = o->texture_size;
    if (o->gutter) out->gutter = o->gutter;
    if (o->max_chart_angle != 0) out->max_chart_angle = o->max_chart_angle;
    if (out->texture_size < 16 || out->texture_size > 65536)
        return mx_fail(st, MX_EUSAGE, "uv atlas: texture size %d outside [16, 65536]", out->texture_size);
    if (out->gutter < 0 || out->gutter > out->texture_size / 8)
        return mx_fail(st, MX_EUSAGE, "uv atlas: gutter %d outside [0, %d]", out->gutter, out->texture_size / 8);
    if (!(out->max_chart_angle > 0 && out->max_chart_angle <= MAX_CHART_ANGLE_DEG))
        return mx_fail(st, MX_EUSAGE, "uv atlas: max chart angle %g outside (0, %g] degrees",
                       (double)out->max_chart_angle, MAX_CHART_ANGLE_DEG);
    return 0;
}

static void free_atlas(atlas *a) {
    free(a->fn), free(a->area), free(a->adj), free(a->order), free(a->charts), free(a->xy);
    free(a->chart_of), free(a->seg), free(a->weld);
}

int mx_uvatlas_build(mx_mesh *m, const mx_uvatlas_opts *o, mx_uvatlas_report *r, mx_status *st) {
    double t0 = mx_now();
    const char *name = m->source_path[0] ? m->source_path : "mesh";
    mx_uvatlas_opts opt;
    if (resolve_opts(o, &opt, st) || check_mesh(m, st)) return mx_fail_prefix(st, "%s", name);
    size_t nf = (size_t)m->nfaces;
    atlas a = {.m = m};
    a.fn = malloc(3 * nf * sizeof *a.fn);
    a.area = malloc(nf * sizeof *a.area);
    a.adj = malloc(3 * nf * sizeof *a.adj);
    a.order = malloc(nf * sizeof *a.order);
    a.charts = malloc(nf * sizeof *a.charts);
    a.xy = malloc(6 * nf * sizeof *a.xy);
    a.chart_of = malloc(nf * sizeof *a.chart_of);
    a.seg = malloc(12 * nf * sizeof *a.seg);
    a.weld = malloc((size_t)m->nverts * sizeof *a.weld);
    if (!a.fn || !a.area || !a.adj || !a.order || !a.charts || !a.xy || !a.chart_of || !a.seg || !a.weld) {
        free_atlas(&a);
        return mx_fail(st, MX_ENOMEM, "%s: uv atlas: out of memory for %zu faces", name, nf);
    }
    compute_face_geometry(&a);
    double scale = 0;
    int rc = build_adjacency(&a, st);
    if (!rc && (segment(&a, opt.max_chart_angle) < 0 || smooth_boundaries(&a, opt.max_chart_angle) < 0))
        rc = mx_fail(st, MX_ENOMEM, "uv atlas: out of memory");
    if (!rc) rc = project_all(&a, opt.max_chart_angle, st);
    if (!rc) rc = merge_small_charts(&a, opt.max_chart_angle, st);
    for (int i = 0; !rc && i < a.ncharts; i++) orient_chart(&a, &a.charts[i]);
    if (!rc) collect_boundary(&a);
    if (!rc) rc = pack_charts(&a, opt.texture_size, opt.gutter, &scale, st);
    if (!rc) rc = write_uvs(&a, m, scale, opt.texture_size, st);
    if (!rc && r) {
        measure(&a, m, scale, opt.texture_size, r);
        r->seconds = mx_now() - t0;
    }
    if (rc) mx_fail_prefix(st, "%s", name);
    free_atlas(&a);
    return rc;
}
