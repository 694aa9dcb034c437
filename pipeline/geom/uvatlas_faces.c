/* mx_uvatlas_complete: UVs for the faces of a mesh that has some UVs but not on every face
 * (an OBJ whose faces of one material have no vt). The faces without UVs of each material get
 * an atlas of their own, laid out in the unit square like mx_uvatlas_build, so they get a
 * texture of their own: the material's when none of its faces had UVs, else a new material
 * "<name>_atlas" appended to the mesh. Faces that have UVs are never touched. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "uvatlas.h"

static int face_has_uvs(const mx_mesh *m, int f) {
    const int32_t *fu = m->face_uv + 3 * (size_t)f;
    return fu[0] >= 0 && fu[1] >= 0 && fu[2] >= 0;
}

static int face_material(const mx_mesh *m, int f) { return m->face_mat ? m->face_mat[f] : 0; }

/* Appends material "<name of base>_atlas"; faces keep their index until moved. */
static int add_material(mx_mesh *m, int base, mx_status *st) {
    int n = m->nmat;
    mx_material *mats = realloc(m->mats, (size_t)(n + 1) * sizeof *mats);
    if (!mats) return mx_fail(st, MX_ENOMEM, "%s: out of memory", m->source_path);
    m->mats = mats;
    memset(&mats[n], 0, sizeof mats[n]);
    snprintf(mats[n].name, sizeof mats[n].name, "%.100s_atlas", mats[base].name[0] ? mats[base].name : "material");
    if (!m->face_mat) {
        m->face_mat = calloc((size_t)m->nfaces, sizeof *m->face_mat);
        if (!m->face_mat) return mx_fail(st, MX_ENOMEM, "%s: out of memory", m->source_path);
    }
    m->nmat = n + 1;
    return n;
}

/* Atlas of the given faces (a mesh sharing m's positions), its UVs appended to m's. */
static int atlas_faces(mx_mesh *m, const int32_t *faces, int n, const mx_uvatlas_opts *o, mx_uvatlas_report *r,
                       mx_status *st) {
    mx_mesh sub = {.nverts = m->nverts, .nfaces = n, .pos = m->pos};
    memcpy(sub.source_path, m->source_path, sizeof sub.source_path);
    sub.faces = malloc(3 * (size_t)n * sizeof *sub.faces);
    if (!sub.faces) return mx_fail(st, MX_ENOMEM, "%s: out of memory", m->source_path);
    for (int i = 0; i < n; i++) memcpy(sub.faces + 3 * (size_t)i, m->faces + 3 * (size_t)faces[i], 3 * sizeof(int32_t));
    int rc = mx_uvatlas_build(&sub, o, r, st);
    float *uv = rc ? NULL : realloc(m->uv, 2 * ((size_t)m->nuv + sub.nuv) * sizeof *uv);
    if (!rc && !uv) rc = mx_fail(st, MX_ENOMEM, "%s: out of memory", m->source_path);
    if (!rc) {
        m->uv = uv;
        memcpy(m->uv + 2 * (size_t)m->nuv, sub.uv, 2 * (size_t)sub.nuv * sizeof *uv);
        for (int i = 0; i < n; i++)
            for (int k = 0; k < 3; k++) m->face_uv[3 * (size_t)faces[i] + k] = m->nuv + sub.face_uv[3 * (size_t)i + k];
        m->nuv += sub.nuv;
    }
    free(sub.faces), free(sub.uv), free(sub.face_uv);
    return rc;
}

/* Sums one atlas's report into the total (utilisation and stretch: means over atlases). */
static void add_report(mx_uvatlas_report *sum, const mx_uvatlas_report *r, int count) {
    sum->charts += r->charts;
    sum->utilisation += (r->utilisation - sum->utilisation) / count;
    sum->stretch_mean += (r->stretch_mean - sum->stretch_mean) / count;
    if (r->stretch_max > sum->stretch_max) sum->stretch_max = r->stretch_max;
    sum->seconds += r->seconds;
}

/* The faces of material k without UVs into list; *all_missing: none of k's faces has UVs. */
static int missing_of_material(const mx_mesh *m, int k, int32_t *list, int *all_missing) {
    int n = 0, with = 0;
    for (int f = 0; f < m->nfaces; f++) {
        if (face_material(m, f) != k) continue;
        if (face_has_uvs(m, f)) with++;
        else list[n++] = f;
    }
    *all_missing = with == 0;
    return n;
}

int mx_uvatlas_complete(mx_mesh *m, const mx_uvatlas_opts *o, mx_uvatlas_report *r, int *faces_done,
                        mx_status *st) {
    mx_uvatlas_report sum = {0}, one;
    *faces_done = 0;
    if (!m->face_uv || m->nuv <= 0) return mx_fail(st, MX_EINPUT, "%s: uv atlas: the mesh has no UVs", m->source_path);
    if (m->nmat < 1) { /* every face is material 0: give it a name */
        free(m->mats);
        m->mats = calloc(1, sizeof *m->mats);
        if (!m->mats) return mx_fail(st, MX_ENOMEM, "%s: out of memory", m->source_path);
        snprintf(m->mats[0].name, sizeof m->mats[0].name, "material");
        m->nmat = 1;
    }
    int32_t *list = malloc((size_t)m->nfaces * sizeof *list);
    if (!list) return mx_fail(st, MX_ENOMEM, "%s: out of memory", m->source_path);
    int nmat = m->nmat, natlas = 0, rc = 0;
    for (int k = 0; !rc && k < nmat; k++) {
        int all_missing, n = missing_of_material(m, k, list, &all_missing);
        if (n == 0) continue;
        int target = all_missing ? k : add_material(m, k, st);
        if (target < 0 || atlas_faces(m, list, n, o, &one, st)) {
            rc = -1;
            break;
        }
        for (int i = 0; m->face_mat && i < n; i++) m->face_mat[list[i]] = target;
        add_report(&sum, &one, ++natlas);
        *faces_done += n;
        mx_warn("%s: %d faces of material '%s' have no UVs: they get a UV atlas and a texture of their own ('%s')",
                m->source_path, n, m->mats[k].name, m->mats[target].name);
    }
    free(list);
    if (!rc && r) *r = sum;
    return rc;
}
