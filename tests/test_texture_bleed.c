/* No background colour in transferred textures (issue 13, edges): every shared asset gets a
 * procedural texture (an atlas first when it has no UVs) and is written as a textured mesh;
 * the transfer (mx_transfer_run, the library) then moves that texture onto the same mesh
 * twice, the source rendered once over magenta and once over green, each render going through
 * the texture job's model image (through_model_image: crop, resize, paste back, which blends
 * background into silhouette pixels). A texel whose colour differs between the two results
 * took colour from the background: there must be none. */
#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/geom/mesh.h"
#include "../pipeline/geom/uvatlas.h"
#include "../pipeline/io/export.h"
#include "../pipeline/io/io.h"
#include "../pipeline/io/mesh_load.h"
#include "../pipeline/texture/texture.h"
#include "../runtime/log.h"
#include "util_test.h"

#define TEX 128

static char tmpdir[256];

static void procedural(float u, float v, int layer, float out[3]) {
    const float tau = 6.28318530718f;
    out[0] = 0.5f + 0.4f * sinf(tau * (3 * u + 1 * v) + 0.3f * layer);
    out[1] = 0.5f + 0.4f * sinf(tau * (1 * u - 2 * v) + 2.1f + 0.7f * layer);
    out[2] = 0.5f + 0.4f * cosf(tau * (2 * u + 3 * v) + 4.2f + 1.1f * layer);
}

/* The asset with a procedural texture per layer, written to dir (mesh.obj + textures). */
static int write_source(const char *rel, const char *dir, mx_status *st) {
    char path[2048];
    mx_test_path(path, sizeof path, rel);
    mx_mesh m = {0};
    mx_image tex[64] = {{0}};
    if (mx_mesh_load(path, &m, st)) return -1;
    int rc = 0;
    if (!m.face_uv) {
        mx_uvatlas_opts o = mx_uvatlas_defaults();
        mx_uvatlas_report r;
        o.texture_size = TEX;
        rc = mx_uvatlas_build(&m, &o, &r, st);
        free(m.face_mat);
        m.face_mat = NULL;
    }
    int nlayers = m.nmat > 1 && m.face_mat ? m.nmat : 1;
    for (int l = 0; !rc && l < nlayers && l < 64; l++) {
        rc = mx_image_alloc(&tex[l], TEX, TEX, 3, st);
        for (int y = 0; !rc && y < TEX; y++)
            for (int x = 0; x < TEX; x++)
                procedural((x + 0.5f) / TEX, 1.0f - (y + 0.5f) / TEX, l, tex[l].data + 3 * ((size_t)y * TEX + x));
    }
    if (!rc) rc = nlayers > 64 ? mx_fail(st, MX_EINPUT, "too many layers") : mx_write_outputs(dir, &m, tex, nlayers, NULL, st);
    for (int l = 0; l < 64; l++) mx_image_free(&tex[l]);
    mx_mesh_free(&m);
    return rc;
}

/* Texels that differ between the same-named PNGs of two folders; -1 on a read error. */
static int64_t differing_texels(const char *a, const char *b, int64_t *total) {
    DIR *d = opendir(a);
    if (!d) return -1;
    struct dirent *e;
    int64_t diff = 0;
    while ((e = readdir(d)) && diff >= 0) {
        size_t len = strlen(e->d_name);
        if (len < 4 || strcmp(e->d_name + len - 4, ".png")) continue;
        char pa[1024], pb[1024];
        snprintf(pa, sizeof pa, "%s/%s", a, e->d_name);
        snprintf(pb, sizeof pb, "%s/%s", b, e->d_name);
        mx_image ia = {0}, ib = {0};
        mx_status st;
        if (mx_io_read_image(pa, &ia, &st) || mx_io_read_image(pb, &ib, &st) || ia.w != ib.w || ia.h != ib.h ||
            ia.c != ib.c) {
            diff = -1;
        } else {
            for (size_t i = 0; i < (size_t)ia.w * ia.h; i++) {
                int differs = 0;
                for (int c = 0; c < ia.c; c++) differs |= fabsf(ia.data[i * ia.c + c] - ib.data[i * ib.c + c]) > 0.5f / 255;
                diff += differs;
            }
            *total += (int64_t)ia.w * ia.h;
        }
        mx_image_free(&ia);
        mx_image_free(&ib);
    }
    closedir(d);
    return diff;
}

/* The source's texture moved onto itself, rendered over the background (r, g, b), into out: as
 * `matex transfer SRC SRC --size 256 --image-size 128 --candidates 8 --views 4 --background r,g,b -o out`. */
static int transfer(const char *src_dir, float r, float g, float b, const char *out, mx_status *st) {
    char mesh[512];
    snprintf(mesh, sizeof mesh, "%s/mesh.obj", src_dir);
    mx_texture_opts o;
    mx_texture_opts_default(&o);
    o.pub.source_path = o.pub.mesh_path = mesh;
    o.pub.out_dir = out;
    o.pub.texture_size = o.pub.render_size = 256;
    o.pub.image_size = 128;
    o.pub.through_model_image = 1;
    o.pub.candidates = 8;
    o.pub.views = 4;
    o.pub.verbose = 0;
    o.pub.background[0] = r, o.pub.background[1] = g, o.pub.background[2] = b;
    return mx_texture_opts_check(&o, MX_VERB_TRANSFER, st) || mx_transfer_run(&o, NULL, st);
}

int main(void) {
    mx_log_set_level(MX_LOG_ERROR);
    snprintf(tmpdir, sizeof tmpdir, "/tmp/matex_bleed_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    for (size_t k = 0; k < MX_TEST_NASSETS; k++) {
        char src[512], a[512], b[512];
        snprintf(src, sizeof src, "%s/src%zu", tmpdir, k);
        snprintf(a, sizeof a, "%s/magenta%zu", tmpdir, k);
        snprintf(b, sizeof b, "%s/green%zu", tmpdir, k);
        char rel[256], path[2048];
        snprintf(rel, sizeof rel, "assets/%s", mx_test_assets[k]);
        if (!mx_test_need(path, sizeof path, "%s", rel)) continue;
        mx_status st;
        int ok = write_source(rel, src, &st) == 0;
        if (!ok) fprintf(stderr, "%s: %s\n", mx_test_assets[k], st.msg);
        CHECK(ok);
        if (!ok || transfer(src, 1, 0, 1, a, &st) || transfer(src, 0, 1, 0, b, &st)) {
            if (ok) fprintf(stderr, "%s: transfer: %s\n", mx_test_assets[k], st.msg);
            CHECK(0);
            continue;
        }
        int64_t total = 0, diff = differing_texels(a, b, &total);
        printf("%-48s %lld of %lld texels depend on the background\n", mx_test_assets[k], (long long)diff, (long long)total);
        CHECK(diff == 0 && total > 0);
    }
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd)) fprintf(stderr, "could not remove %s\n", tmpdir);
    return mx_test_finish("test_texture_bleed");
}
