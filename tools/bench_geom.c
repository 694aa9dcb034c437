/* Geometry benchmark: on the largest shared mesh (koala, 100k faces; UVs from the atlas),
 * the time of one 1024^2 view (rasterize culled with the unculled depth, masks, backproject), and of the
 * view-selection loop: 40 candidates (cached at 256^2), front + back + 4 picked views, each
 * baked at 1024^2. 2 threads. Usage: bench_geom [MESH] [THREADS]; the mesh defaults to
 * $MATEX_SHARED/assets/koala/koala.obj (../shared without the variable). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../pipeline/geom/backproject.h"
#include "../pipeline/geom/masks.h"
#include "../pipeline/geom/mesh.h"
#include "../pipeline/geom/uvatlas.h"
#include "../pipeline/geom/views.h"
#include "../runtime/log.h"

#define SIZE 1024
#define TEX 1024
#define NCAND 40
#define REPS 10

static int bake_view(mx_bake *bake, mx_view_buffers *vb, const mx_mesh *m, const float *pos,
                     const mx_camera *cam, const mx_image *img, mx_pool *pool, mx_status *st) {
    return mx_view_prepare(vb, m, pos, cam, MX_NORMAL_GEOMETRIC, 0.1f, pool, st) ||
           mx_backproject(bake, &vb->gb, m, img, vb->mask, 0, pool, st);
}

int main(int argc, char **argv) {
    char koala[2048];
    const char *shared = getenv("MATEX_SHARED");
    snprintf(koala, sizeof koala, "%s/assets/koala/koala.obj", shared ? shared : "../shared");
    const char *path = argc > 1 ? argv[1] : koala;
    int threads = argc > 2 ? atoi(argv[2]) : 2;
    mx_status st;
    mx_mesh m = {0};
    float *pos = NULL;
    if (mx_mesh_load(path, &m, &st) || (!m.face_uv && mx_uvatlas_build(&m, NULL, NULL, &st)) ||
        mx_mesh_normalized(&m, MX_UP_Y, &pos, NULL, NULL, &st)) {
        fprintf(stderr, "bench_geom: %s\n", st.msg);
        return 1;
    }
    mx_pool *pool = mx_pool_create(threads, &st);
    mx_view_buffers vb;
    mx_bake bake;
    mx_image img;
    if (mx_view_buffers_init(&vb, SIZE, &st) || mx_bake_init(&bake, TEX, TEX, 1, &st) ||
        mx_image_alloc(&img, SIZE, SIZE, 3, &st)) {
        fprintf(stderr, "bench_geom: %s\n", st.msg);
        return 1;
    }
    for (size_t i = 0; i < (size_t)SIZE * SIZE * 3; i++) img.data[i] = (float)(i % 7) / 7.0f;
    mx_camera cands[2 + NCAND];
    mx_camera_ortho(&cands[0], 0, 0, 3, 1.05f);
    mx_camera_ortho(&cands[1], 180, 0, 3, 1.05f);
    mx_camera_fibonacci(cands + 2, NCAND, &cands[0]);

    /* one view, repeated: the stages separately, then together */
    double t_raster = 0, t_masks = 0, t_bp = 0;
    clock_t cpu0 = clock();
    for (int r = 0; r < REPS; r++) {
        const mx_camera *cam = &cands[2 + r % NCAND];
        mx_bake_reset(&bake);
        double t0 = mx_now();
        mx_rasterize(&m, pos, cam, MX_VIEW_RASTER_FLAGS, pool, &vb.gb, &st);
        double t1 = mx_now();
        mx_view_masks(&vb, MX_NORMAL_GEOMETRIC, 0.1f, pool);
        double t2 = mx_now();
        mx_backproject(&bake, &vb.gb, &m, &img, vb.mask, 0, pool, &st);
        double t3 = mx_now();
        t_raster += t1 - t0;
        t_masks += t2 - t1;
        t_bp += t3 - t2;
    }
    double cpu_view = (double)(clock() - cpu0) / CLOCKS_PER_SEC / REPS;
    printf("mesh %s: %d faces, %d threads\n", path, m.nfaces, threads);
    printf("one %dx%d view: rasterize %.2f ms, masks %.2f ms, backproject %.2f ms, total %.2f ms\n",
           SIZE, SIZE, 1e3 * t_raster / REPS, 1e3 * t_masks / REPS, 1e3 * t_bp / REPS,
           1e3 * (t_raster + t_masks + t_bp) / REPS);
    /* CPU time over all threads: on a busy machine a steadier number than the wall clock */
    printf("one view: %.2f ms CPU time (all threads)\n", 1e3 * cpu_view);

    /* the view-selection loop */
    mx_bake_reset(&bake);
    double t0 = mx_now();
    cpu0 = clock();
    mx_view_cache vc;
    if (mx_view_cache_build(&vc, &m, pos, cands, 2 + NCAND, 256, TEX, TEX, 1, 0.1f, pool, &st)) {
        fprintf(stderr, "bench_geom: %s\n", st.msg);
        return 1;
    }
    double t_cache = mx_now() - t0;
    uint8_t used[2 + NCAND] = {1, 1};
    int rc = bake_view(&bake, &vb, &m, pos, &cands[0], &img, pool, &st) ||
             bake_view(&bake, &vb, &m, pos, &cands[1], &img, pool, &st);
    for (int v = 2; !rc && v < 6; v++) {
        int c = mx_view_pick(&vc, bake.known, used, 1);
        if (c < 0) break;
        used[c] = 1;
        rc = bake_view(&bake, &vb, &m, pos, &cands[c], &img, pool, &st);
    }
    double t_loop = mx_now() - t0, cpu_loop = (double)(clock() - cpu0) / CLOCKS_PER_SEC;
    printf("view selection, 6 views / %d candidates: %.1f ms (candidate cache %.1f ms), %.1f ms CPU time, "
           "T^B texels %lld\n",
           NCAND, 1e3 * t_loop, 1e3 * t_cache, 1e3 * cpu_loop, (long long)mx_bake_known_count(&bake));
    mx_view_cache_free(&vc);
    mx_image_free(&img);
    mx_bake_free(&bake);
    mx_view_buffers_free(&vb);
    mx_pool_destroy(pool);
    free(pos);
    mx_mesh_free(&m);
    return rc ? 1 : 0;
}
