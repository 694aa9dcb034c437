/* Geometry benchmark: on the largest shared mesh (koala, 100k faces; UVs from the atlas),
 * the time of one 1024^2 view (rasterize culled with the unculled depth, masks, backproject), and of the
 * view-selection loop: 40 candidates (cached at 256^2), front + back + 4 picked views, each
 * baked at 1024^2. Every number is the median over repeats (the machine is shared: medians
 * are steadier than means). Usage: bench_geom [MESH] [THREADS] [REPS]; the mesh defaults to
 * $MATEX_TESTDATA/assets/koala/koala.obj (../shared without the variable), 2 threads, 15 repeats. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../pipeline/geom/backproject.h"
#include "../../pipeline/geom/masks.h"
#include "../../pipeline/geom/mesh.h"
#include "../../pipeline/geom/uvatlas.h"
#include "../../pipeline/geom/views.h"
#include "../../pipeline/io/mesh_load.h"
#include "../../runtime/log.h"

#define SIZE 1024
#define TEX 1024
#define NCAND 40
#define CACHE_SIZE 256
#define MAX_REPS 100

typedef struct bench_env {
    mx_mesh m;
    float *pos;
    mx_pool *pool;
    mx_view_buffers vb;
    mx_bake bake;
    mx_image img;
    mx_camera cands[2 + NCAND];
} bench_env;

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double median(double *v, int n) {
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

static double cpu_seconds(void) {
    return (double)clock() / CLOCKS_PER_SEC;
}

static int bake_view(bench_env *e, const mx_camera *cam, mx_status *st) {
    return mx_view_prepare(&e->vb, &e->m, e->pos, cam, MX_NORMAL_GEOMETRIC, 0.1f, e->pool, st) ||
           mx_backproject(&e->bake, &e->vb.gb, &e->m, &e->img, e->vb.mask, 0, e->pool, st);
}

/* One view, repeated over the candidate cameras: each stage timed separately. */
typedef struct view_times {
    double raster[MAX_REPS], masks[MAX_REPS], bp[MAX_REPS], total[MAX_REPS], cpu[MAX_REPS];
} view_times;

static int time_one_view(bench_env *e, int reps, view_times *t, mx_status *st) {
    for (int r = 0; r < reps; r++) {
        const mx_camera *cam = &e->cands[2 + r % NCAND];
        mx_bake_reset(&e->bake);
        double c0 = cpu_seconds(), t0 = mx_now();
        if (mx_rasterize(&e->m, e->pos, cam, MX_VIEW_RASTER_FLAGS, e->pool, &e->vb.gb, st)) return -1;
        double t1 = mx_now();
        mx_view_masks(&e->vb, MX_NORMAL_GEOMETRIC, 0.1f, e->pool);
        double t2 = mx_now();
        if (mx_backproject(&e->bake, &e->vb.gb, &e->m, &e->img, e->vb.mask, 0, e->pool, st)) return -1;
        double t3 = mx_now();
        t->raster[r] = 1e3 * (t1 - t0);
        t->masks[r] = 1e3 * (t2 - t1);
        t->bp[r] = 1e3 * (t3 - t2);
        t->total[r] = 1e3 * (t3 - t0);
        t->cpu[r] = 1e3 * (cpu_seconds() - c0);
    }
    return 0;
}

/* The view-selection loop: candidate cache, front + back, then 4 picked views. */
static int time_loop(bench_env *e, double *cache_ms, double *loop_ms, double *cpu_ms, int64_t *known,
                     mx_status *st) {
    mx_bake_reset(&e->bake);
    double c0 = cpu_seconds(), t0 = mx_now();
    mx_view_cache vc;
    if (mx_view_cache_build(&vc, &e->m, e->pos, e->cands, 2 + NCAND, CACHE_SIZE, TEX, TEX, 1, MX_NORMAL_GEOMETRIC, 0.1f, 0,
                            e->pool, st))
        return -1;
    *cache_ms = 1e3 * (mx_now() - t0);
    uint8_t used[2 + NCAND] = {1, 1};
    int rc = bake_view(e, &e->cands[0], st) || bake_view(e, &e->cands[1], st);
    for (int v = 2; !rc && v < 6; v++) {
        int c = mx_view_pick(&vc, e->bake.known, used, 1);
        if (c < 0) break;
        used[c] = 1;
        rc = bake_view(e, &e->cands[c], st);
    }
    *loop_ms = 1e3 * (mx_now() - t0);
    *cpu_ms = 1e3 * (cpu_seconds() - c0);
    *known = mx_bake_known_count(&e->bake);
    mx_view_cache_free(&vc);
    return rc ? -1 : 0;
}

static int env_init(bench_env *e, const char *path, int threads, mx_status *st) {
    memset(e, 0, sizeof *e);
    if (mx_mesh_load(path, &e->m, st) || (!e->m.face_uv && mx_uvatlas_build(&e->m, NULL, NULL, st)) ||
        mx_mesh_normalized(&e->m, MX_UP_Y, &e->pos, NULL, NULL, st))
        return -1;
    e->pool = mx_pool_create(threads, st);
    if (!e->pool || mx_view_buffers_init(&e->vb, SIZE, st) || mx_bake_init(&e->bake, TEX, TEX, 1, st) ||
        mx_image_alloc(&e->img, SIZE, SIZE, 3, st))
        return -1;
    for (size_t i = 0; i < (size_t)SIZE * SIZE * 3; i++) e->img.data[i] = (float)(i % 7) / 7.0f;
    mx_camera_ortho(&e->cands[0], 0, 0, 3, 1.05f);
    mx_camera_ortho(&e->cands[1], 180, 0, 3, 1.05f);
    mx_camera_fibonacci(e->cands + 2, NCAND, &e->cands[0]);
    return 0;
}

static void env_free(bench_env *e) {
    mx_image_free(&e->img);
    mx_bake_free(&e->bake);
    mx_view_buffers_free(&e->vb);
    mx_pool_destroy(e->pool);
    free(e->pos);
    mx_mesh_free(&e->m);
}

int main(int argc, char **argv) {
    char koala[2048];
    const char *shared = getenv("MATEX_TESTDATA");
    snprintf(koala, sizeof koala, "%s/assets/koala/koala.obj", shared ? shared : "../shared");
    const char *path = argc > 1 ? argv[1] : koala;
    int threads = argc > 2 ? atoi(argv[2]) : 2;
    int reps = argc > 3 ? atoi(argv[3]) : 15;
    if (threads <= 0 || reps <= 0 || reps > MAX_REPS) {
        fprintf(stderr, "usage: bench_geom [MESH] [THREADS>0] [REPS 1..%d]\n", MAX_REPS);
        return 2;
    }
    mx_status st;
    static bench_env e;
    static view_times vt;
    if (env_init(&e, path, threads, &st) || time_one_view(&e, reps, &vt, &st)) {
        fprintf(stderr, "bench_geom: %s\n", st.msg);
        return 1;
    }
    int loop_reps = reps < 5 ? reps : 5;
    double cache[MAX_REPS], loop[MAX_REPS], loop_cpu[MAX_REPS];
    int64_t known = 0;
    for (int r = 0; r < loop_reps; r++)
        if (time_loop(&e, &cache[r], &loop[r], &loop_cpu[r], &known, &st)) {
            fprintf(stderr, "bench_geom: %s\n", st.msg);
            return 1;
        }
    printf("bench-geom: %s, %d faces, %d threads, medians of %d repeats (loop: %d)\n", path, e.m.nfaces,
           threads, reps, loop_reps);
    printf("  %-44s %10s\n", "stage", "ms");
    printf("  %-44s %10.2f\n", "rasterize 1024^2 (culled + unculled depth, UV)", median(vt.raster, reps));
    printf("  %-44s %10.2f\n", "masks (frontal, internal)", median(vt.masks, reps));
    printf("  %-44s %10.2f\n", "backproject into 1024^2", median(vt.bp, reps));
    printf("  %-44s %10.2f\n", "per view (wall)", median(vt.total, reps));
    printf("  %-44s %10.2f\n", "per view (CPU time, all threads)", median(vt.cpu, reps));
    printf("  %-44s %10.2f\n", "candidate cache, 42 views at 256^2", median(cache, loop_reps));
    printf("  %-44s %10.2f\n", "6-view loop incl. cache (wall)", median(loop, loop_reps));
    printf("  %-44s %10.2f\n", "6-view loop (CPU time, all threads)", median(loop_cpu, loop_reps));
    printf("  T^B texels after the loop: %lld\n", (long long)known);
    printf("bench-geom-summary: view_ms=%.2f loop6_ms=%.2f\n", median(vt.total, reps), median(loop, loop_reps));
    env_free(&e);
    return 0;
}
