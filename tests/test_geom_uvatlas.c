/* UV atlas: on hand-made meshes (cube, sphere, capped cylinder, open height field, a helicoid
 * whose projection folds over itself, two disjoint parts with a degenerate face) and on the
 * shared assets without UVs, checks that every UV is in [0,1], that no texel centre lies inside
 * two triangles (no chart overlaps itself or another), that charts rasterised conservatively
 * are at least `gutter` empty texels apart, that the reported utilisation matches the UVs, and
 * that the result is deterministic. Prints charts / utilisation / stretch / time per mesh. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/uvatlas.h"
#include "../pipeline/io/mesh_load.h"
#include "util_test.h"

/* ---------- hand-made meshes ---------- */

typedef struct builder {
    mx_mesh m;
    int cap_v, cap_f;
} builder;

static int add_vertex(builder *b, double x, double y, double z) {
    if (b->m.nverts == b->cap_v) {
        b->cap_v = b->cap_v ? 2 * b->cap_v : 64;
        b->m.pos = realloc(b->m.pos, 3 * (size_t)b->cap_v * sizeof *b->m.pos);
    }
    float *p = b->m.pos + 3 * (size_t)b->m.nverts;
    p[0] = (float)x, p[1] = (float)y, p[2] = (float)z;
    return b->m.nverts++;
}

static void add_face(builder *b, int a, int c, int d) {
    if (b->m.nfaces == b->cap_f) {
        b->cap_f = b->cap_f ? 2 * b->cap_f : 64;
        b->m.faces = realloc(b->m.faces, 3 * (size_t)b->cap_f * sizeof *b->m.faces);
    }
    int32_t *f = b->m.faces + 3 * (size_t)b->m.nfaces++;
    f[0] = a, f[1] = c, f[2] = d;
}

/* Quad a-b-c-d (counter-clockwise) as two triangles. */
static void add_quad(builder *b, int a, int c, int d, int e) {
    add_face(b, a, c, d);
    add_face(b, a, d, e);
}

static mx_mesh make_cube(void) {
    builder b = {0};
    for (int i = 0; i < 8; i++) add_vertex(&b, i & 1, (i >> 1) & 1, (i >> 2) & 1);
    add_quad(&b, 0, 2, 3, 1); /* z = 0, facing -z */
    add_quad(&b, 4, 5, 7, 6); /* z = 1 */
    add_quad(&b, 0, 1, 5, 4); /* y = 0 */
    add_quad(&b, 2, 6, 7, 3); /* y = 1 */
    add_quad(&b, 0, 4, 6, 2); /* x = 0 */
    add_quad(&b, 1, 3, 7, 5); /* x = 1 */
    return b.m;
}

/* Latitude-longitude sphere with a single vertex at each pole. */
static mx_mesh make_sphere(int nlat, int nlon) {
    builder b = {0};
    int south = add_vertex(&b, 0, 0, -1);
    for (int i = 1; i < nlat; i++)
        for (int j = 0; j < nlon; j++) {
            double th = M_PI * i / nlat, ph = 2 * M_PI * j / nlon;
            add_vertex(&b, sin(th) * cos(ph), sin(th) * sin(ph), -cos(th));
        }
    int north = add_vertex(&b, 0, 0, 1);
#define RING(i, j) (1 + ((i) - 1) * nlon + ((j) % nlon))
    for (int j = 0; j < nlon; j++) add_face(&b, south, RING(1, j + 1), RING(1, j));
    for (int i = 1; i < nlat - 1; i++)
        for (int j = 0; j < nlon; j++) add_quad(&b, RING(i, j), RING(i, j + 1), RING(i + 1, j + 1), RING(i + 1, j));
    for (int j = 0; j < nlon; j++) add_face(&b, RING(nlat - 1, j), RING(nlat - 1, j + 1), north);
#undef RING
    return b.m;
}

/* Closed cylinder of radius 0.3 and height 2 (a long thin shape), caps fanned from a centre. */
static mx_mesh make_cylinder(int nseg, int nrings) {
    builder b = {0};
    for (int i = 0; i <= nrings; i++)
        for (int j = 0; j < nseg; j++) {
            double ph = 2 * M_PI * j / nseg;
            add_vertex(&b, 0.3 * cos(ph), 0.3 * sin(ph), 2.0 * i / nrings - 1);
        }
    int bottom = add_vertex(&b, 0, 0, -1), top = add_vertex(&b, 0, 0, 1);
    for (int i = 0; i < nrings; i++)
        for (int j = 0; j < nseg; j++) {
            int a = i * nseg + j, c = i * nseg + (j + 1) % nseg;
            add_quad(&b, a, c, c + nseg, a + nseg);
        }
    for (int j = 0; j < nseg; j++) {
        add_face(&b, bottom, (j + 1) % nseg, j);
        add_face(&b, top, nrings * nseg + j, nrings * nseg + (j + 1) % nseg);
    }
    return b.m;
}

/* Open height field z = bumps(x, y) over a square grid. */
static mx_mesh make_terrain(int n) {
    builder b = {0};
    for (int i = 0; i <= n; i++)
        for (int j = 0; j <= n; j++) {
            double x = (double)j / n, y = (double)i / n;
            add_vertex(&b, x, y, 0.15 * sin(9 * x) * cos(7 * y) + 0.05 * sin(31 * x + 17 * y));
        }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            int a = i * (n + 1) + j;
            add_quad(&b, a, a + 1, a + n + 2, a + n + 1);
        }
    return b.m;
}

/* A flat-ish spiral ramp of three turns: every normal is within 10 degrees of +z, so normal
 * growing makes one chart, but its planar projection covers the same ring three times. */
static mx_mesh make_helicoid(int nseg_per_turn, int turns) {
    builder b = {0};
    int n = nseg_per_turn * turns;
    for (int j = 0; j <= n; j++) {
        double ph = 2 * M_PI * j / nseg_per_turn, z = 0.05 * ph;
        add_vertex(&b, 0.5 * cos(ph), 0.5 * sin(ph), z);
        add_vertex(&b, 1.0 * cos(ph), 1.0 * sin(ph), z);
    }
    for (int j = 0; j < n; j++) add_quad(&b, 2 * j, 2 * j + 1, 2 * j + 3, 2 * j + 2);
    return b.m;
}

/* Two separate open squares, one with a degenerate (zero-area) face, and an unused vertex. */
static mx_mesh make_two_parts(void) {
    builder b = {0};
    for (int part = 0; part < 2; part++) {
        double z = part * 3.0;
        int a = add_vertex(&b, 0, 0, z), c = add_vertex(&b, 1, 0, z), d = add_vertex(&b, 1, 1, z),
            e = add_vertex(&b, 0, 1, z);
        add_quad(&b, a, c, d, e);
        if (part == 1) add_face(&b, a, c, c);
    }
    add_vertex(&b, 9, 9, 9);
    return b.m;
}

/* The same mesh with every corner its own vertex (a triangle soup, as some files store it). */
static mx_mesh unwelded(const mx_mesh *src) {
    builder b = {0};
    for (int f = 0; f < src->nfaces; f++) {
        int v[3];
        for (int k = 0; k < 3; k++) {
            const float *p = src->pos + 3 * (size_t)src->faces[3 * f + k];
            v[k] = add_vertex(&b, p[0], p[1], p[2]);
        }
        add_face(&b, v[0], v[1], v[2]);
    }
    return b.m;
}

/* ---------- checks on the UVs ---------- */

/* Charts as the UVs show them: faces sharing a UV index belong together (union-find). */
static int find_root(int *parent, int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
}

static int *uv_components(const mx_mesh *m, int *count) {
    int *parent = malloc((size_t)m->nuv * sizeof *parent), *comp = malloc((size_t)m->nfaces * sizeof *comp);
    for (int i = 0; i < m->nuv; i++) parent[i] = i;
    for (int f = 0; f < m->nfaces; f++)
        for (int k = 1; k < 3; k++) {
            int a = find_root(parent, m->face_uv[3 * f]), b = find_root(parent, m->face_uv[3 * f + k]);
            if (a != b) parent[a < b ? b : a] = a < b ? a : b;
        }
    int *label = malloc((size_t)m->nuv * sizeof *label);
    for (int i = 0; i < m->nuv; i++) label[i] = -1;
    *count = 0;
    for (int f = 0; f < m->nfaces; f++) {
        int r = find_root(parent, m->face_uv[3 * f]);
        if (label[r] < 0) label[r] = (*count)++;
        comp[f] = label[r];
    }
    free(parent), free(label);
    return comp;
}

static void face_texels(const mx_mesh *m, int f, int size, double t[6]) {
    for (int k = 0; k < 3; k++) {
        const float *uv = m->uv + 2 * (size_t)m->face_uv[3 * f + k];
        t[2 * k] = uv[0] * (double)size;
        t[2 * k + 1] = uv[1] * (double)size;
    }
}

/* Edge function of edge k at (x, y), sign-normalised so that the interior is positive. */
static double edge_fn(const double t[6], int k, double orient, double x, double y) {
    const double *p = t + 2 * k, *q = t + 2 * ((k + 1) % 3);
    return orient * ((q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]));
}

static int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Conservative: marks every texel whose closed square meets the triangle; returns the number of
 * texels already marked by another chart. */
static long raster_conservative(const double t[6], int size, int comp, int *owner) {
    double orient = (t[2] - t[0]) * (t[5] - t[1]) - (t[4] - t[0]) * (t[3] - t[1]) >= 0 ? 1 : -1;
    int x0 = clampi((int)floor(fmin(t[0], fmin(t[2], t[4]))), 0, size - 1);
    int x1 = clampi((int)floor(fmax(t[0], fmax(t[2], t[4]))), 0, size - 1);
    int y0 = clampi((int)floor(fmin(t[1], fmin(t[3], t[5]))), 0, size - 1);
    int y1 = clampi((int)floor(fmax(t[1], fmax(t[3], t[5]))), 0, size - 1);
    long clashes = 0;
    for (int y = y0; y <= y1; y++)
        for (int x = x0; x <= x1; x++) {
            int inside = 1;
            for (int k = 0; k < 3 && inside; k++) {
                double best = -INFINITY;
                for (int c = 0; c < 4; c++) best = fmax(best, edge_fn(t, k, orient, x + (c & 1), y + (c >> 1)));
                inside = best >= 0;
            }
            if (!inside) continue;
            int *o = &owner[(size_t)y * size + x];
            if (*o >= 0 && *o != comp) clashes++;
            else *o = comp;
        }
    return clashes;
}

/* Counts texel centres strictly inside the triangle into `hits`. */
static void raster_centres(const double t[6], int size, unsigned char *hits) {
    double orient = (t[2] - t[0]) * (t[5] - t[1]) - (t[4] - t[0]) * (t[3] - t[1]) >= 0 ? 1 : -1;
    int x0 = clampi((int)floor(fmin(t[0], fmin(t[2], t[4]))), 0, size - 1);
    int x1 = clampi((int)floor(fmax(t[0], fmax(t[2], t[4]))), 0, size - 1);
    int y0 = clampi((int)floor(fmin(t[1], fmin(t[3], t[5]))), 0, size - 1);
    int y1 = clampi((int)floor(fmax(t[1], fmax(t[3], t[5]))), 0, size - 1);
    for (int y = y0; y <= y1; y++)
        for (int x = x0; x <= x1; x++) {
            int inside = 1;
            for (int k = 0; k < 3 && inside; k++) inside = edge_fn(t, k, orient, x + 0.5, y + 0.5) > 0;
            if (inside && hits[(size_t)y * size + x] < 255) hits[(size_t)y * size + x]++;
        }
}

/* Texels owned by one chart that have a texel of another chart within `gutter` (Chebyshev). */
static long gutter_violations(const int *owner, int size, int gutter) {
    long bad = 0;
    for (int y = 0; y < size; y++)
        for (int x = 0; x < size; x++) {
            int o = owner[(size_t)y * size + x];
            if (o < 0) continue;
            for (int dy = -gutter; dy <= gutter; dy++)
                for (int dx = -gutter; dx <= gutter; dx++) {
                    int yy = y + dy, xx = x + dx;
                    if (yy < 0 || yy >= size || xx < 0 || xx >= size) continue;
                    int q = owner[(size_t)yy * size + xx];
                    if (q >= 0 && q != o) bad++;
                }
        }
    return bad;
}

typedef struct defects {
    long clashes; /* texels that two charts' conservative rasters share */
    long doubles; /* texel centres strictly inside two triangles */
    long near;    /* texels with another chart's texel within the gutter */
    int pieces;   /* charts as the UVs show them */
    double utilisation;
} defects;

/* Rasterises the atlas at size x size and counts what must not happen. UVs must be in range. */
static defects atlas_defects(const mx_mesh *m, int size, int gutter) {
    defects d = {0};
    int *comp = uv_components(m, &d.pieces);
    int *owner = malloc((size_t)size * size * sizeof *owner);
    unsigned char *hits = calloc((size_t)size * size, 1);
    for (size_t i = 0; i < (size_t)size * size; i++) owner[i] = -1;
    double covered = 0;
    for (int f = 0; f < m->nfaces; f++) {
        double t[6];
        face_texels(m, f, size, t);
        covered += 0.5 * fabs((t[2] - t[0]) * (t[5] - t[1]) - (t[4] - t[0]) * (t[3] - t[1]));
        d.clashes += raster_conservative(t, size, comp[f], owner);
        raster_centres(t, size, hits);
    }
    for (size_t i = 0; i < (size_t)size * size; i++) d.doubles += hits[i] > 1;
    d.near = gutter_violations(owner, size, gutter);
    d.utilisation = covered / ((double)size * size);
    free(comp), free(owner), free(hits);
    return d;
}

static int uvs_in_range(const mx_mesh *m) {
    if (!(m->nuv > 0 && m->uv && m->face_uv)) return 0;
    for (size_t i = 0; i < 3 * (size_t)m->nfaces; i++)
        if (m->face_uv[i] < 0 || m->face_uv[i] >= m->nuv) return 0;
    for (size_t i = 0; i < 2 * (size_t)m->nuv; i++)
        if (!(m->uv[i] >= 0.0f && m->uv[i] <= 1.0f)) return 0;
    return 1;
}

static void check_atlas(const char *name, const mx_mesh *m, const mx_uvatlas_report *r, int size, int gutter) {
    int ok = uvs_in_range(m);
    CHECK(ok);
    if (!ok) return;
    defects d = atlas_defects(m, size, gutter);
    printf("%-10s %7d faces %5d charts (%5d pieces)  utilisation %.3f  stretch mean %.3f max %.2f  %.3f s\n",
           name, m->nfaces, r->charts, d.pieces, r->utilisation, r->stretch_mean, r->stretch_max, r->seconds);
    if (d.clashes || d.doubles || d.near)
        printf("  %s: %ld texels shared by two charts, %ld texel centres in two triangles, %ld gutter violations\n",
               name, d.clashes, d.doubles, d.near);
    CHECK(d.clashes == 0);
    CHECK(d.doubles == 0);
    CHECK(d.near == 0);
    CHECK(d.pieces == r->charts); /* every chart is one edge-connected piece with its own UVs */
    CHECK(fabs(d.utilisation - r->utilisation) < 1e-3);
    CHECK(r->stretch_mean >= 1 - 1e-3 && r->stretch_mean <= r->stretch_max + 1e-9);
}

/* Builds the atlas twice (the second on a copy) and checks both runs agree bit for bit. */
static void run_case(const char *name, mx_mesh *m, const mx_uvatlas_opts *o, double min_util) {
    mx_mesh copy = *m;
    copy.pos = malloc(3 * (size_t)m->nverts * sizeof *copy.pos);
    copy.faces = malloc(3 * (size_t)m->nfaces * sizeof *copy.faces);
    memcpy(copy.pos, m->pos, 3 * (size_t)m->nverts * sizeof *copy.pos);
    memcpy(copy.faces, m->faces, 3 * (size_t)m->nfaces * sizeof *copy.faces);
    copy.nrm = NULL, copy.face_nrm = NULL, copy.mats = NULL, copy.face_mat = NULL;
    copy.nnrm = 0, copy.nmat = 0;
    mx_status st = {0};
    mx_uvatlas_report r = {0}, r2 = {0};
    int rc = mx_uvatlas_build(m, o, &r, &st);
    if (rc) fprintf(stderr, "%s: %s\n", name, st.msg);
    CHECK(rc == 0);
    if (rc == 0) {
        check_atlas(name, m, &r, o->texture_size, o->gutter);
        CHECK(r.utilisation >= min_util);
        CHECK(mx_uvatlas_build(&copy, o, &r2, &st) == 0);
        CHECK(copy.nuv == m->nuv && r2.charts == r.charts);
        if (copy.nuv == m->nuv && copy.uv) {
            CHECK(memcmp(copy.uv, m->uv, 2 * (size_t)m->nuv * sizeof *m->uv) == 0);
            CHECK(memcmp(copy.face_uv, m->face_uv, 3 * (size_t)m->nfaces * sizeof *m->face_uv) == 0);
        }
    }
    mx_mesh_free(&copy);
}

static void test_hand_made(void) {
    struct {
        const char *name;
        mx_mesh m;
        double min_util;
    } cases[] = {
        {"cube", make_cube(), 0.5},           {"sphere", make_sphere(24, 48), 0.5},
        {"cylinder", make_cylinder(48, 20), 0.5}, {"terrain", make_terrain(80), 0.5},
        {"helicoid", make_helicoid(64, 3), 0.3}, {"two parts", make_two_parts(), 0.3},
    };
    mx_uvatlas_opts o = mx_uvatlas_defaults();
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        run_case(cases[i].name, &cases[i].m, &o, cases[i].min_util);
        mx_mesh_free(&cases[i].m);
    }
    /* A triangle soup is welded by position: as few charts as the shared-vertex sphere. */
    mx_mesh welded = make_sphere(24, 48), soup = unwelded(&welded);
    mx_uvatlas_report rw = {0}, rs = {0};
    mx_status st = {0};
    CHECK(mx_uvatlas_build(&welded, &o, &rw, &st) == 0);
    CHECK(mx_uvatlas_build(&soup, &o, &rs, &st) == 0);
    CHECK(rs.charts == rw.charts);
    mx_mesh_free(&soup);
    soup = unwelded(&welded);
    run_case("sphere soup", &soup, &o, 0.5);
    mx_mesh_free(&soup), mx_mesh_free(&welded);
    /* Other sizes and gutters are honoured too. */
    o.texture_size = 512, o.gutter = 5;
    mx_mesh sphere = make_sphere(16, 32);
    run_case("sphere 512 gutter 5", &sphere, &o, 0.4);
    mx_mesh_free(&sphere);
}

/* Moves every UV of piece `piece` by (dx, dy) texels. */
static void shift_piece(mx_mesh *m, const int *comp, int piece, double dx, double dy, int size) {
    unsigned char *moved = calloc((size_t)m->nuv, 1);
    for (int f = 0; f < m->nfaces; f++)
        for (int k = 0; k < 3 && comp[f] == piece; k++) {
            int i = m->face_uv[3 * f + k];
            if (moved[i]) continue;
            moved[i] = 1;
            m->uv[2 * i] += (float)(dx / size);
            m->uv[2 * i + 1] += (float)(dy / size);
        }
    free(moved);
}

static void piece_min(const mx_mesh *m, const int *comp, int piece, double *x, double *y) {
    *x = *y = INFINITY;
    for (int f = 0; f < m->nfaces; f++)
        for (int k = 0; k < 3 && comp[f] == piece; k++) {
            const float *uv = m->uv + 2 * (size_t)m->face_uv[3 * f + k];
            *x = fmin(*x, uv[0]), *y = fmin(*y, uv[1]);
        }
}

/* The checker itself must see overlaps and charts that come too close. */
static void test_checker_detects_defects(void) {
    mx_mesh m = make_cube();
    mx_status st = {0};
    mx_uvatlas_report r = {0};
    CHECK(mx_uvatlas_build(&m, NULL, &r, &st) == 0);
    int pieces = 0;
    int *comp = uv_components(&m, &pieces);
    CHECK(pieces == 6);
    defects clean = atlas_defects(&m, 1024, 2);
    CHECK(clean.clashes == 0 && clean.doubles == 0 && clean.near == 0);
    /* Piece 1 laid exactly over piece 0: both kinds of overlap. */
    double x0, y0, x1, y1;
    piece_min(&m, comp, 0, &x0, &y0);
    piece_min(&m, comp, 1, &x1, &y1);
    shift_piece(&m, comp, 1, (x0 - x1) * 1024, (y0 - y1) * 1024, 1024);
    defects over = atlas_defects(&m, 1024, 2);
    CHECK(over.clashes > 0 && over.doubles > 0);
    free(comp);
    mx_mesh_free(&m);

    /* Two unit squares laid out side by side 1.5 texels apart: no overlap, but too close. */
    builder b = {0};
    for (int i = 0; i < 8; i++) add_vertex(&b, 0, 0, 0);
    add_quad(&b, 0, 1, 2, 3);
    add_quad(&b, 4, 5, 6, 7);
    b.m.nuv = 8;
    b.m.uv = malloc(16 * sizeof *b.m.uv);
    b.m.face_uv = malloc(12 * sizeof *b.m.face_uv);
    const float square[8] = {0, 0, 1, 0, 1, 1, 0, 1};
    for (int i = 0; i < 8; i++) {
        float x = (100 + square[2 * (i % 4)] * 50 + (i >= 4 ? 51.5f : 0)) / 1024, y = (100 + square[2 * (i % 4) + 1] * 50) / 1024;
        b.m.uv[2 * i] = x, b.m.uv[2 * i + 1] = y;
    }
    memcpy(b.m.face_uv, b.m.faces, 12 * sizeof *b.m.face_uv);
    defects near = atlas_defects(&b.m, 1024, 2);
    CHECK(near.clashes == 0 && near.doubles == 0 && near.near > 0);
    mx_mesh_free(&b.m);
}

/* The helicoid has to be split: a single chart would cover its ring three times. */
static void test_fold_is_split(void) {
    mx_mesh m = make_helicoid(64, 3);
    mx_uvatlas_report r = {0};
    mx_status st = {0};
    CHECK(mx_uvatlas_build(&m, NULL, &r, &st) == 0);
    CHECK(r.charts >= 3);
    mx_mesh_free(&m);
}

static void test_bad_input(void) {
    mx_status st = {0};
    mx_mesh m = make_cube();
    m.faces[5] = 8; /* out of range */
    CHECK(mx_uvatlas_build(&m, NULL, NULL, &st) == -1 && st.code == MX_EINPUT && strstr(st.msg, "face 1"));
    CHECK(m.uv == NULL && m.face_uv == NULL && m.nuv == 0);
    m.faces[5] = 3;
    m.pos[4] = NAN;
    CHECK(mx_uvatlas_build(&m, NULL, NULL, &st) == -1 && strstr(st.msg, "vertex 1"));
    m.pos[4] = 0;
    CHECK(mx_uvatlas_build(&m, NULL, NULL, &st) == 0);
    CHECK(mx_uvatlas_build(&m, NULL, NULL, &st) == -1 && strstr(st.msg, "already has UVs"));
    mx_mesh_free(&m);

    mx_mesh sphere = make_sphere(8, 16);
    mx_uvatlas_opts o = mx_uvatlas_defaults();
    o.gutter = -1;
    CHECK(mx_uvatlas_build(&sphere, &o, NULL, &st) == -1 && st.code == MX_EUSAGE);
    o = mx_uvatlas_defaults();
    o.max_chart_angle = 95;
    CHECK(mx_uvatlas_build(&sphere, &o, NULL, &st) == -1 && st.code == MX_EUSAGE);
    mx_mesh_free(&sphere);
    /* Too many charts for the texture: 16x16 texels with a 2-texel gutter hold at most 16
     * charts (each takes at least 4x4 with its gutter), the terrain makes more than 16. */
    mx_mesh terrain = make_terrain(80);
    o = mx_uvatlas_defaults();
    o.texture_size = 16;
    CHECK(mx_uvatlas_build(&terrain, &o, NULL, &st) == -1 && st.code == MX_EINPUT && strstr(st.msg, "do not fit"));
    CHECK(terrain.uv == NULL && terrain.face_uv == NULL);
    mx_mesh_free(&terrain);

    /* Only zero-area faces (all corners on one point): a valid, empty-looking atlas. */
    builder b = {0};
    for (int i = 0; i < 6; i++) add_vertex(&b, 0.5, 0.5, 0.5);
    add_face(&b, 0, 1, 2);
    add_face(&b, 3, 4, 5);
    add_face(&b, 0, 0, 0);
    mx_uvatlas_report r = {0};
    CHECK(mx_uvatlas_build(&b.m, NULL, &r, &st) == 0);
    CHECK(uvs_in_range(&b.m) && r.utilisation == 0);
    mx_mesh_free(&b.m);

    mx_mesh empty = {0};
    CHECK(mx_uvatlas_build(&empty, NULL, NULL, &st) == -1 && st.code == MX_EINPUT);
}

/* The shared meshes that come without UVs (assets/MANIFEST.md). */
static void test_assets(void) {
    static const char *const files[][2] = {
        {"spot_ply", "spot_ply/spot.ply"}, {"boot", "boot/boot.obj"},       {"koala", "koala/koala.obj"},
        {"mountain", "mountain/mountain.obj"}, {"hammer", "hammer/hammer.obj"},
    };
    for (size_t i = 0; i < sizeof files / sizeof *files; i++) {
        char path[2048];
        if (!mx_test_need(path, sizeof path, "assets/%s", files[i][1])) continue;
        mx_mesh m = {0};
        mx_status st = {0};
        int rc = mx_mesh_load(path, &m, &st);
        if (rc) fprintf(stderr, "%s\n", st.msg);
        CHECK(rc == 0);
        mx_uvatlas_opts o = mx_uvatlas_defaults();
        if (rc == 0) run_case(files[i][0], &m, &o, 0.5);
        mx_mesh_free(&m);
    }
}

/* Flat, single-face and degenerate meshes (issue 12: one chart overflowed the packer's profile
 * storage): a quad, one triangle, a 10x10 grid plane, at several texture sizes. */
static void test_flat_and_single_face(void) {
    static const int sizes[] = {16, 64, 1024};
    for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++) {
        mx_uvatlas_opts o = mx_uvatlas_defaults();
        o.texture_size = sizes[i];
        builder quad = {0}, tri = {0}, grid = {0};
        for (int k = 0; k < 4; k++) add_vertex(&quad, k == 1 || k == 2, k >= 2, 0);
        add_quad(&quad, 0, 1, 2, 3);
        add_vertex(&tri, 0, 0, 0), add_vertex(&tri, 1, 0, 0), add_vertex(&tri, 0, 1, 0);
        add_face(&tri, 0, 1, 2);
        for (int y = 0; y <= 10; y++)
            for (int x = 0; x <= 10; x++) add_vertex(&grid, x, y, 0);
        for (int y = 0; y < 10; y++)
            for (int x = 0; x < 10; x++) add_quad(&grid, y * 11 + x, y * 11 + x + 1, y * 11 + x + 12, y * 11 + x + 11);
        run_case("quad", &quad.m, &o, sizes[i] >= 64 ? 0.8 : 0.3);
        run_case("triangle", &tri.m, &o, sizes[i] >= 64 ? 0.4 : 0.1);
        run_case("grid plane", &grid.m, &o, sizes[i] >= 64 ? 0.8 : 0.3);
        CHECK(quad.m.nuv > 0 && tri.m.nuv > 0 && grid.m.nuv > 0);
        mx_mesh_free(&quad.m), mx_mesh_free(&tri.m), mx_mesh_free(&grid.m);
        /* one zero-area triangle (collinear corners) */
        builder zero = {0};
        add_vertex(&zero, 0, 0, 0), add_vertex(&zero, 1, 0, 0), add_vertex(&zero, 2, 0, 0);
        add_face(&zero, 0, 1, 2);
        mx_status st = {0};
        mx_uvatlas_report r = {0};
        CHECK(mx_uvatlas_build(&zero.m, &o, &r, &st) == 0 && uvs_in_range(&zero.m) && r.charts == 1);
        mx_mesh_free(&zero.m);
    }
}

/* mx_uvatlas_complete: a cube whose material 0 has UVs on 4 of its 6 faces (quads 0, 1) and
 * none on 2 (quad 2), and whose material 1 (quads 3-5) has none at all. */
static void test_complete_missing_uvs(void) {
    mx_mesh m = make_cube();
    m.nmat = 2;
    m.mats = calloc(2, sizeof *m.mats);
    snprintf(m.mats[0].name, sizeof m.mats[0].name, "wood");
    snprintf(m.mats[1].name, sizeof m.mats[1].name, "metal");
    m.face_mat = calloc((size_t)m.nfaces, sizeof *m.face_mat);
    for (int f = 6; f < 12; f++) m.face_mat[f] = 1;
    m.nuv = 4;
    m.uv = malloc(8 * sizeof *m.uv);
    const float corners[8] = {0, 0, 1, 0, 1, 1, 0, 1};
    memcpy(m.uv, corners, sizeof corners);
    m.face_uv = malloc(3 * (size_t)m.nfaces * sizeof *m.face_uv);
    for (int f = 0; f < m.nfaces; f++)
        for (int k = 0; k < 3; k++) m.face_uv[3 * f + k] = f < 4 ? (f & 1 ? (int[]){0, 2, 3}[k] : k) : -1;
    int32_t before[12];
    memcpy(before, m.face_uv, sizeof before);
    mx_status st = {0};
    mx_uvatlas_report r = {0};
    int done = 0;
    CHECK(mx_uvatlas_complete(&m, NULL, &r, &done, &st) == 0);
    CHECK(done == 8 && r.charts >= 2);
    CHECK(m.nmat == 3 && !strcmp(m.mats[2].name, "wood_atlas"));
    CHECK(memcmp(m.face_uv, before, sizeof before) == 0); /* faces with UVs untouched */
    for (int f = 0; f < m.nfaces; f++) {
        int want = f < 4 ? 0 : f < 6 ? 2 : 1; /* the mixed material's faces move, metal keeps its */
        CHECK(m.face_mat[f] == want);
        for (int k = 0; k < 3; k++) CHECK(m.face_uv[3 * f + k] >= 0 && m.face_uv[3 * f + k] < m.nuv);
    }
    CHECK(uvs_in_range(&m));
    mx_mesh_free(&m);
    /* every face already has UVs: nothing to do */
    mx_mesh q = make_cube();
    CHECK(mx_uvatlas_build(&q, NULL, NULL, &st) == 0);
    int nuv = q.nuv;
    CHECK(mx_uvatlas_complete(&q, NULL, NULL, &done, &st) == 0 && done == 0 && q.nuv == nuv);
    mx_mesh_free(&q);
}

int main(void) {
    test_checker_detects_defects();
    test_hand_made();
    test_fold_is_split();
    test_bad_input();
    test_flat_and_single_face();
    test_complete_missing_uvs();
    test_assets();
    return mx_test_finish("geom_uvatlas");
}
