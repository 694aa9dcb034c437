/* UV atlas benchmark: builds the atlas for each mesh given (default: the shared assets that
 * have no UVs) and prints faces, charts, utilisation, area stretch and the best of N runs.
 * usage: bench_atlas [--runs N] [MESH...] */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../pipeline/geom/uvatlas.h"
#include "../../pipeline/io/mesh_load.h"

/* Loads path, builds the atlas `runs` times (UVs dropped between runs) and prints one line. */
static int bench_mesh(const char *path, int runs) {
    mx_mesh m = {0};
    mx_status st = {0};
    if (mx_mesh_load(path, &m, &st)) {
        fprintf(stderr, "bench_atlas: %s\n", st.msg);
        return 1;
    }
    free(m.uv), free(m.face_uv); /* meshes with UVs are laid out anew */
    m.uv = NULL, m.face_uv = NULL, m.nuv = 0;
    mx_uvatlas_report r = {0}, best = {0};
    for (int i = 0; i < runs; i++) {
        if (mx_uvatlas_build(&m, NULL, &r, &st)) {
            fprintf(stderr, "bench_atlas: %s: %s\n", path, st.msg);
            mx_mesh_free(&m);
            return 1;
        }
        if (i == 0 || r.seconds < best.seconds) best = r;
        free(m.uv), free(m.face_uv);
        m.uv = NULL, m.face_uv = NULL, m.nuv = 0;
    }
    const char *name = strrchr(path, '/') ? strrchr(path, '/') + 1 : path;
    printf("%-20s %7d faces %5d charts  utilisation %.3f  stretch mean %.3f max %.2f  %.3f s\n", name, m.nfaces,
           best.charts, best.utilisation, best.stretch_mean, best.stretch_max, best.seconds);
    mx_mesh_free(&m);
    return 0;
}

int main(int argc, char **argv) {
    int runs = 3, first = 1;
    if (argc > 2 && strcmp(argv[1], "--runs") == 0) {
        runs = atoi(argv[2]);
        first = 3;
        if (runs < 1) runs = 1;
    }
    static const char *const assets[] = {"spot_ply/spot.ply", "boot/boot.obj", "koala/koala.obj",
                                         "mountain/mountain.obj", "hammer/hammer.obj"};
    int rc = 0;
    if (first < argc) {
        for (int i = first; i < argc; i++) rc |= bench_mesh(argv[i], runs);
        return rc;
    }
    /* the larger test meshes live outside the repository (tests/data/README.md) */
    const char *shared = getenv("MATEX_TESTDATA") ? getenv("MATEX_TESTDATA") : "../shared";
    for (size_t i = 0; i < sizeof assets / sizeof *assets; i++) {
        char path[2048];
        snprintf(path, sizeof path, "%s/assets/%s", shared, assets[i]);
        rc |= bench_mesh(path, runs);
    }
    return rc;
}
