/* Mesh utilities: copy, validation, bbox, normalised copy for rendering, face normals, edge
 * connectivity (pipeline/geom/mesh.h). */
#include "mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* malloc'ed copy of n bytes of p (NULL stays NULL); *fail set when the copy fails. */
static void *dup_bytes(const void *p, size_t n, int *fail) {
    if (!p) return NULL;
    void *q = malloc(n ? n : 1);
    if (!q) *fail = 1;
    else memcpy(q, p, n);
    return q;
}

int mx_mesh_clone(const mx_mesh *src, mx_mesh *dst, mx_status *st) {
    size_t nf = (size_t)src->nfaces;
    int fail = 0;
    *dst = *src;
    dst->pos = dup_bytes(src->pos, (size_t)src->nverts * 3 * sizeof(float), &fail);
    dst->faces = dup_bytes(src->faces, nf * 3 * sizeof(int32_t), &fail);
    dst->uv = dup_bytes(src->uv, (size_t)src->nuv * 2 * sizeof(float), &fail);
    dst->face_uv = dup_bytes(src->face_uv, nf * 3 * sizeof(int32_t), &fail);
    dst->nrm = dup_bytes(src->nrm, (size_t)src->nnrm * 3 * sizeof(float), &fail);
    dst->face_nrm = dup_bytes(src->face_nrm, nf * 3 * sizeof(int32_t), &fail);
    dst->mats = dup_bytes(src->mats, (size_t)src->nmat * sizeof(mx_material), &fail);
    dst->face_mat = dup_bytes(src->face_mat, nf * sizeof(int32_t), &fail);
    if (!fail) return 0;
    mx_mesh_free(dst);
    return mx_fail(st, MX_ENOMEM, "%s: out of memory copying the mesh", src->source_path);
}

static int check_index_list(const mx_mesh *m, const int32_t *idx, int count, int allow_missing, const char *what,
                            mx_status *st) {
    for (size_t i = 0; i < (size_t)m->nfaces * 3; i++) {
        int32_t v = idx[i];
        if (v == -1 && allow_missing) continue;
        if (v < 0 || v >= count)
            return mx_fail(st, MX_EINPUT, "%s: face %zu: %s index %d out of range [0, %d)", m->source_path, i / 3,
                           what, v, count);
    }
    return 0;
}

int mx_mesh_validate(const mx_mesh *m, mx_status *st) {
    const char *src = m->source_path[0] ? m->source_path : "mesh";
    if (m->nverts <= 0 || m->nfaces <= 0 || !m->pos || !m->faces)
        return mx_fail(st, MX_EINPUT, "%s: empty mesh (%d vertices, %d faces)", src, m->nverts, m->nfaces);
    for (size_t i = 0; i < (size_t)m->nverts * 3; i++) {
        if (!isfinite(m->pos[i]))
            return mx_fail(st, MX_EINPUT, "%s: vertex %zu has a non-finite coordinate", src, i / 3);
        if (fabsf(m->pos[i]) > MX_MESH_MAX_COORD)
            return mx_fail(st, MX_EINPUT, "%s: vertex %zu: coordinate out of range (%g; at most %g in magnitude)", src,
                           i / 3, (double)m->pos[i], MX_MESH_MAX_COORD);
    }
    if (check_index_list(m, m->faces, m->nverts, 0, "vertex", st)) return -1;
    if (m->face_uv && (!m->uv || check_index_list(m, m->face_uv, m->nuv, 1, "uv", st))) {
        if (!m->uv) return mx_fail(st, MX_EINPUT, "%s: face UV indices without UVs", src);
        return -1;
    }
    if (m->face_nrm && (!m->nrm || check_index_list(m, m->face_nrm, m->nnrm, 1, "normal", st))) {
        if (!m->nrm) return mx_fail(st, MX_EINPUT, "%s: face normal indices without normals", src);
        return -1;
    }
    for (size_t i = 0; i < (size_t)m->nuv * 2; i++)
        if (!isfinite(m->uv[i])) return mx_fail(st, MX_EINPUT, "%s: UV %zu is NaN or infinite", src, i / 2);
    if (m->nmat < 1 || !m->mats) return mx_fail(st, MX_EINPUT, "%s: no material table", src);
    if (m->face_mat)
        for (int f = 0; f < m->nfaces; f++)
            if (m->face_mat[f] < 0 || m->face_mat[f] >= m->nmat)
                return mx_fail(st, MX_EINPUT, "%s: face %d: material %d out of range [0, %d)", src, f, m->face_mat[f],
                               m->nmat);
    return 0;
}

void mx_mesh_bbox(const mx_mesh *m, float lo[3], float hi[3]) {
    for (int k = 0; k < 3; k++) lo[k] = hi[k] = m->nverts > 0 ? m->pos[k] : 0.f;
    for (int v = 1; v < m->nverts; v++)
        for (int k = 0; k < 3; k++) {
            float x = m->pos[3 * v + k];
            if (x < lo[k]) lo[k] = x;
            if (x > hi[k]) hi[k] = x;
        }
}

/* A malloc'ed copy of the positions turned y-up. */
static float *rotated_copy(const mx_mesh *m, mx_up_axis up, mx_status *st) {
    size_t n = (size_t)m->nverts;
    float *p = malloc(n * 3 * sizeof(float) + 1);
    if (!p) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory normalising %zu vertices", m->source_path, n);
        return NULL;
    }
    for (size_t v = 0; v < n; v++) {
        const float *q = m->pos + 3 * v;
        /* z-up -> y-up: a rotation of -90 degrees about x, (x, y, z) -> (x, z, -y). */
        p[3 * v] = q[0];
        p[3 * v + 1] = up == MX_UP_Z ? q[2] : q[1];
        p[3 * v + 2] = up == MX_UP_Z ? -q[1] : q[2];
    }
    return p;
}

static void move_and_scale(float *p, size_t n, const float c[3], float s) {
    for (size_t v = 0; v < n; v++)
        for (int k = 0; k < 3; k++) p[3 * v + k] = (p[3 * v + k] - c[k]) * s;
}

int mx_mesh_normalized(const mx_mesh *m, mx_up_axis up, float **pos_out, float center[3], float *scale,
                       mx_status *st) {
    size_t n = (size_t)m->nverts;
    float *p = *pos_out = rotated_copy(m, up, st);
    if (!p) return -1;
    mx_mesh tmp = *m;
    tmp.pos = p;
    float lo[3], hi[3], c[3];
    mx_mesh_bbox(&tmp, lo, hi);
    for (int k = 0; k < 3; k++) c[k] = 0.5f * (lo[k] + hi[k]);
    double r2 = 0;
    for (size_t v = 0; v < n; v++) {
        double d = 0;
        for (int k = 0; k < 3; k++) d += (double)(p[3 * v + k] - c[k]) * (p[3 * v + k] - c[k]);
        if (d > r2) r2 = d;
    }
    float s = r2 > 0 ? (float)(1.0 / sqrt(r2)) : 1.f;
    move_and_scale(p, n, c, s);
    if (center)
        for (int k = 0; k < 3; k++) center[k] = c[k];
    if (scale) *scale = s;
    return 0;
}

int mx_mesh_placed(const mx_mesh *m, mx_up_axis up, const float center[3], float scale, float **pos_out,
                   mx_status *st) {
    float *p = *pos_out = rotated_copy(m, up, st);
    if (!p) return -1;
    move_and_scale(p, (size_t)m->nverts, center, scale);
    return 0;
}

/* Unnormalised normal (cross product) of face f; its length is twice the area. */
static void face_cross(const float *pos, const int32_t *t, double n[3]) {
    const float *a = pos + 3 * (size_t)t[0], *b = pos + 3 * (size_t)t[1], *c = pos + 3 * (size_t)t[2];
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
}

int mx_mesh_face_normals(const mx_mesh *m, const float *pos, float **nrm_out, mx_status *st) {
    float *nrm = malloc((size_t)m->nfaces * 3 * sizeof(float) + 1);
    *nrm_out = NULL;
    if (!nrm) return mx_fail(st, MX_ENOMEM, "%s: out of memory for face normals", m->source_path);
    for (int f = 0; f < m->nfaces; f++) {
        double n[3];
        face_cross(pos, m->faces + 3 * (size_t)f, n);
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int k = 0; k < 3; k++) nrm[3 * f + k] = len > 0 ? (float)(n[k] / len) : 0.f;
    }
    *nrm_out = nrm;
    return 0;
}

/* ---- topology ---- */

typedef struct {
    int32_t v;
    uint32_t key[3];
} weld_rec;

static int cmp_weld(const void *x, const void *y) {
    const weld_rec *e = x, *f = y;
    for (int k = 0; k < 3; k++)
        if (e->key[k] != f->key[k]) return e->key[k] < f->key[k] ? -1 : 1;
    return (e->v > f->v) - (e->v < f->v);
}

static int identity_map(const mx_mesh *m, int32_t *canon) {
    for (int v = 0; v < m->nverts; v++) canon[v] = v;
    return 0;
}

/* The bits of a coordinate with -0 made +0, so that equal keys are equal values (positions are
 * finite: mx_mesh_validate). */
static uint32_t weld_key(float x) {
    float z = x + 0.0f; /* -0 + 0 = +0; every other value unchanged */
    uint32_t k;
    memcpy(&k, &z, sizeof k);
    return k;
}

int mx_mesh_weld_map(const mx_mesh *m, int32_t *canon, mx_status *st) {
    identity_map(m, canon);
    weld_rec *w = malloc((size_t)m->nverts * sizeof *w + 1);
    if (!w) return mx_fail(st, MX_ENOMEM, "%s: out of memory welding vertices", m->source_path);
    for (int v = 0; v < m->nverts; v++) {
        w[v].v = v;
        for (int k = 0; k < 3; k++) w[v].key[k] = weld_key(m->pos[3 * (size_t)v + k]);
    }
    qsort(w, (size_t)m->nverts, sizeof *w, cmp_weld);
    for (int i = 1; i < m->nverts; i++)
        if (!memcmp(w[i].key, w[i - 1].key, sizeof w[i].key)) canon[w[i].v] = canon[w[i - 1].v];
    free(w);
    return 0;
}

static int cmp_edge(const void *x, const void *y) {
    const mx_mesh_edge *e = x, *f = y;
    if (e->lo != f->lo) return e->lo < f->lo ? -1 : 1;
    if (e->hi != f->hi) return e->hi < f->hi ? -1 : 1;
    return (e->corner > f->corner) - (e->corner < f->corner);
}

int mx_mesh_sorted_edges(const mx_mesh *m, const int32_t *canon, mx_mesh_edge **out, size_t *n, mx_status *st) {
    size_t nc = 3 * (size_t)m->nfaces, ne = 0;
    mx_mesh_edge *e = malloc(nc * sizeof *e + 1);
    if (!e) return mx_fail(st, MX_ENOMEM, "%s: out of memory for edge connectivity", m->source_path);
    for (size_t c = 0; c < nc; c++) {
        int32_t a = canon[m->faces[c]], b = canon[m->faces[c % 3 == 2 ? c - 2 : c + 1]];
        if (a == b) continue; /* collapsed edge of a degenerate face */
        e[ne++] = (mx_mesh_edge){.lo = a < b ? a : b, .hi = a < b ? b : a, .corner = (int32_t)c};
    }
    qsort(e, ne, sizeof *e, cmp_edge);
    *out = e;
    *n = ne;
    return 0;
}

size_t mx_mesh_edge_run(const mx_mesh_edge *e, size_t n, size_t i) {
    size_t j = i + 1;
    while (j < n && e[j].lo == e[i].lo && e[j].hi == e[i].hi) j++;
    return j;
}

static int32_t uf_find(int32_t *parent, int32_t x) {
    while (parent[x] != x) {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    return x;
}

static void uf_union(int32_t *parent, int32_t a, int32_t b) {
    a = uf_find(parent, a);
    b = uf_find(parent, b);
    if (a != b) parent[a < b ? b : a] = a < b ? a : b;
}

static int is_degenerate(const mx_mesh *m, const int32_t *canon, int f) {
    const int32_t *t = m->faces + 3 * (size_t)f;
    int32_t a = canon[t[0]], b = canon[t[1]], c = canon[t[2]];
    if (a == b || b == c || a == c) return 1;
    double n[3];
    face_cross(m->pos, t, n);
    return n[0] == 0 && n[1] == 0 && n[2] == 0;
}

/* Counts edges, boundary (one face) and non-manifold (more than two faces) edges. */
static void count_edges(const mx_mesh_edge *e, size_t ne, mx_mesh_topology *t) {
    for (size_t i = 0; i < ne;) {
        size_t j = mx_mesh_edge_run(e, ne, i);
        t->edges++;
        if (j - i == 1) t->boundary_edges++;
        if (j - i > 2) t->nonmanifold_edges++;
        i = j;
    }
}

/* Components of faces joined through shared (welded) vertices, numbered in order of their
 * first face; parent[] is a union-find forest over vertices, comp_of_root scratch [nverts]. */
static int label_components(const mx_mesh *m, const int32_t *canon, int32_t *parent, int32_t *comp_of_root,
                            int32_t *face_comp) {
    for (int v = 0; v < m->nverts; v++) parent[v] = v, comp_of_root[v] = -1;
    for (size_t f = 0; f < (size_t)m->nfaces; f++)
        for (int k = 1; k < 3; k++) uf_union(parent, canon[m->faces[3 * f]], canon[m->faces[3 * f + k]]);
    int ncomp = 0;
    for (size_t f = 0; f < (size_t)m->nfaces; f++) {
        int32_t r = uf_find(parent, canon[m->faces[3 * f]]);
        if (comp_of_root[r] < 0) comp_of_root[r] = ncomp++;
        if (face_comp) face_comp[f] = comp_of_root[r];
    }
    return ncomp;
}

int mx_mesh_topology_compute(const mx_mesh *m, int weld, mx_mesh_topology *t, int32_t *face_comp,
                             mx_status *st) {
    memset(t, 0, sizeof *t);
    size_t nf = (size_t)m->nfaces, nv = (size_t)m->nverts;
    int32_t *canon = malloc(nv * sizeof *canon + 1);
    int32_t *parent = malloc(nv * sizeof *parent + 1);
    int32_t *comp_of_root = malloc(nv * sizeof *comp_of_root + 1);
    mx_mesh_edge *e = NULL;
    size_t ne = 0;
    int rc = -1;
    if (!canon || !parent || !comp_of_root) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory for edge connectivity", m->source_path);
        goto done;
    }
    if (weld ? mx_mesh_weld_map(m, canon, st) : identity_map(m, canon)) goto done;
    for (size_t f = 0; f < nf; f++)
        if (is_degenerate(m, canon, (int)f)) t->degenerate_faces++;
    if (mx_mesh_sorted_edges(m, canon, &e, &ne, st)) goto done;
    count_edges(e, ne, t);
    t->watertight = t->boundary_edges == 0 && t->nonmanifold_edges == 0;
    t->components = label_components(m, canon, parent, comp_of_root, face_comp);
    rc = 0;
done:
    free(canon);
    free(parent);
    free(comp_of_root);
    free(e);
    return rc;
}
