#include "views.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "masks.h"
#include "raster.h"

void mx_view_cache_free(mx_view_cache *vc) {
    if (vc->texels)
        for (int c = 0; c < vc->ncand; c++) free(vc->texels[c]);
    free(vc->texels);
    free(vc->ntexels);
    free(vc->cams);
    memset(vc, 0, sizeof *vc);
}

/* Texel ids of the usable pixels of one rendered candidate. */
static int collect_texels(mx_view_cache *vc, int c, const mx_mesh *m, const mx_gbuffer *gb,
                          const uint8_t *usable, mx_status *st) {
    size_t n = (size_t)gb->w * gb->h, plane = (size_t)vc->tex_w * vc->tex_h;
    int64_t count = 0;
    for (size_t i = 0; i < n; i++) count += usable[i];
    vc->texels[c] = malloc(((size_t)count + 1) * sizeof **vc->texels);
    if (!vc->texels[c]) return mx_fail(st, MX_ENOMEM, "view selection: out of memory");
    int64_t k = 0;
    for (size_t i = 0; i < n; i++) {
        if (!usable[i]) continue;
        int layer = m->face_mat ? m->face_mat[gb->face[i]] : 0;
        if (layer < 0 || layer >= vc->nlayers) layer = 0;
        int64_t t = mx_uv_texel(gb->uv[2 * i], gb->uv[2 * i + 1], vc->tex_w, vc->tex_h);
        vc->texels[c][k++] = (int32_t)((size_t)layer * plane + (size_t)t);
    }
    vc->ntexels[c] = k;
    return 0;
}

static int erode_mask(const mx_gbuffer *gb, uint8_t *mask, uint8_t *tmp, int radius, mx_status *st);

/* usable = foreground, finite UV, not internal, frontal. */
static void usable_pixels(const mx_gbuffer *gb, int normal_source, float thr, uint8_t *usable, uint8_t *tmp) {
    size_t n = (size_t)gb->w * gb->h;
    mx_mask_frontal(gb, normal_source, thr, usable);
    mx_mask_internal(gb->depth, gb->depth_unculled, (int64_t)n, tmp);
    for (size_t i = 0; i < n; i++)
        usable[i] = usable[i] && !tmp[i] && isfinite(gb->uv[2 * i]) && isfinite(gb->uv[2 * i + 1]);
}

/* Candidates are rendered in parallel, one per task, each thread with its own buffers,
 * when the rasterizer scratch of all threads stays modest (about 150 bytes per face and
 * thread: faces x threads up to this budget); otherwise one at a time with the pool
 * inside the rasterizer. Either way each candidate's list depends only on its camera. */
#define CACHE_PARALLEL_FACE_BUDGET (1 << 20)

typedef struct cache_worker {
    mx_gbuffer gb;
    uint8_t *usable, *tmp;
} cache_worker;

typedef struct cache_job {
    mx_view_cache *vc;
    const mx_mesh *m;
    const float *pos;
    int normal_source;
    float frontal_threshold;
    int erode_radius;
    mx_pool *inner_pool; /* pool for the rasterizer: NULL when candidates run in parallel */
    cache_worker *workers;
    int *failed;         /* [ncand] */
    mx_status *status;   /* [ncand] */
} cache_job;

static void render_candidate_task(void *ctx, int c, int thread) {
    cache_job *j = ctx;
    cache_worker *w = &j->workers[thread];
    mx_view_cache *vc = j->vc;
    if (mx_rasterize(j->m, j->pos, &vc->cams[c], MX_VIEW_RASTER_FLAGS, j->inner_pool, &w->gb,
                     &j->status[c])) {
        j->failed[c] = 1;
        return;
    }
    usable_pixels(&w->gb, j->normal_source, j->frontal_threshold, w->usable, w->tmp);
    if (j->erode_radius > 0 && erode_mask(&w->gb, w->usable, w->tmp, j->erode_radius, &j->status[c])) {
        j->failed[c] = 1;
        return;
    }
    j->failed[c] = collect_texels(vc, c, j->m, &w->gb, w->usable, &j->status[c]) != 0;
}

static int workers_init(cache_worker *w, int n, int size, mx_status *st) {
    for (int k = 0; k < n; k++) {
        w[k].usable = malloc((size_t)size * size);
        w[k].tmp = malloc((size_t)size * size);
        if (!w[k].usable || !w[k].tmp) return mx_fail(st, MX_ENOMEM, "view selection: out of memory");
        if (mx_gbuffer_init(&w[k].gb, size, size, st)) return -1;
    }
    return 0;
}

static void workers_free(cache_worker *w, int n) {
    for (int k = 0; w && k < n; k++) {
        mx_gbuffer_free(&w[k].gb);
        free(w[k].usable);
        free(w[k].tmp);
    }
    free(w);
}

int mx_view_cache_build(mx_view_cache *vc, const mx_mesh *m, const float *pos,
                        const mx_camera *cams, int ncand, int size, int tex_w, int tex_h,
                        int nlayers, int normal_source, float frontal_threshold, int erode_radius, mx_pool *pool,
                        mx_status *st) {
    memset(vc, 0, sizeof *vc);
    if (!m->face_uv) return mx_fail(st, MX_EINPUT, "%s: view selection needs UVs", m->source_path);
    if (ncand <= 0 || (size_t)tex_w * tex_h * nlayers > INT32_MAX)
        return mx_fail(st, MX_EINPUT, "view selection: bad candidate count or texture size");
    if (size <= 0 || size > 16384) return mx_fail(st, MX_EINPUT, "view selection: bad render size %d", size);
    vc->ncand = ncand;
    vc->size = size;
    vc->tex_w = tex_w;
    vc->tex_h = tex_h;
    vc->nlayers = nlayers;
    int parallel = mx_pool_threads(pool) > 1 &&
                   (int64_t)m->nfaces * mx_pool_threads(pool) <= CACHE_PARALLEL_FACE_BUDGET;
    int nworkers = parallel ? mx_pool_threads(pool) : 1;
    cache_job j = {vc, m, pos, normal_source, frontal_threshold, erode_radius, parallel ? NULL : pool, NULL, NULL, NULL};
    vc->cams = malloc((size_t)ncand * sizeof *vc->cams);
    vc->texels = calloc((size_t)ncand, sizeof *vc->texels);
    vc->ntexels = calloc((size_t)ncand, sizeof *vc->ntexels);
    j.workers = calloc((size_t)nworkers, sizeof *j.workers);
    j.failed = calloc((size_t)ncand, sizeof *j.failed);
    j.status = calloc((size_t)ncand, sizeof *j.status);
    int ok = vc->cams && vc->texels && vc->ntexels && j.workers && j.failed && j.status;
    if (!ok) mx_fail(st, MX_ENOMEM, "view selection: out of memory");
    ok = ok && !workers_init(j.workers, nworkers, size, st);
    if (ok) {
        memcpy(vc->cams, cams, (size_t)ncand * sizeof *cams);
        if (parallel)
            mx_pool_for(pool, ncand, render_candidate_task, &j);
        else
            for (int c = 0; c < ncand; c++) render_candidate_task(&j, c, 0);
        for (int c = 0; ok && c < ncand; c++) /* the first failure, whatever the thread count */
            if (j.failed[c]) {
                *st = j.status[c];
                ok = 0;
            }
    }
    workers_free(j.workers, nworkers);
    free(j.failed);
    free(j.status);
    if (!ok) {
        mx_view_cache_free(vc);
        return -1;
    }
    return 0;
}

int64_t mx_view_untextured(const mx_view_cache *vc, int c, const uint8_t *known) {
    int64_t n = 0;
    for (int64_t k = 0; k < vc->ntexels[c]; k++) n += !known[vc->texels[c][k]];
    return n;
}

void mx_view_cache_visible(const mx_view_cache *vc, uint8_t *visible) {
    memset(visible, 0, (size_t)vc->tex_w * vc->tex_h * vc->nlayers);
    for (int c = 0; c < vc->ncand; c++)
        for (int64_t k = 0; k < vc->ntexels[c]; k++) visible[vc->texels[c][k]] = 1;
}

int mx_view_pick(const mx_view_cache *vc, const uint8_t *known, const uint8_t *used,
                 int64_t min_pixels) {
    int best = -1;
    int64_t best_n = min_pixels - 1;
    for (int c = 0; c < vc->ncand; c++) {
        if (used && used[c]) continue;
        int64_t n = mx_view_untextured(vc, c, known);
        if (n > best_n) { /* ties: the lower index wins */
            best_n = n;
            best = c;
        }
    }
    return best;
}

void mx_view_plan_free(mx_view_plan *plan) {
    free(plan->cand);
    free(plan->group);
    memset(plan, 0, sizeof *plan);
}

static double simulated_coverage(const uint8_t *sim, const uint8_t *visible, size_t n) {
    size_t vis = 0, got = 0;
    for (size_t t = 0; t < n; t++) {
        vis += visible[t];
        got += visible[t] && sim[t];
    }
    return vis ? (double)got / (double)vis : 1.0;
}

/* mx_view_plan_make, with the candidates in `chosen` (may be NULL) excluded. */
static int plan_views(const mx_view_cache *vc, const uint8_t *known, const uint8_t *chosen, int budget,
                      double coverage_stop, int64_t min_pixels, mx_view_plan *plan, mx_status *st) {
    memset(plan, 0, sizeof *plan);
    size_t n = (size_t)vc->tex_w * vc->tex_h * vc->nlayers;
    int cap = budget > 0 ? budget : 1;
    plan->cand = malloc((size_t)cap * sizeof *plan->cand);
    plan->group = malloc((size_t)cap * sizeof *plan->group);
    uint8_t *sim = malloc(n), *visible = malloc(n), *claimed = calloc(n, 1);
    uint8_t *used = calloc((size_t)vc->ncand, 1), *group_known = malloc(n);
    if (!plan->cand || !plan->group || !sim || !visible || !claimed || !used || !group_known) {
        free(sim), free(visible), free(claimed), free(used), free(group_known);
        mx_view_plan_free(plan);
        return mx_fail(st, MX_ENOMEM, "view selection: out of memory");
    }
    memcpy(sim, known, n);
    memcpy(group_known, known, n);
    if (chosen) memcpy(used, chosen, (size_t)vc->ncand);
    mx_view_cache_visible(vc, visible);
    int group = 0;
    plan->coverage = simulated_coverage(sim, visible, n);
    while (plan->n < budget && plan->coverage < coverage_stop) {
        int c = mx_view_pick(vc, sim, used, min_pixels);
        if (c < 0) break;
        /* overlap with what the current group already claims (untextured at group start); a
         * sliver of shared texels along silhouettes (MX_VIEW_GROUP_OVERLAP of the view's own
         * untextured texels) still counts as non-overlapping: the first view of the batch wins there */
        int64_t overlap = 0, fresh = 0;
        for (int64_t k = 0; k < vc->ntexels[c]; k++) {
            int32_t t = vc->texels[c][k];
            fresh += !group_known[t];
            overlap += !group_known[t] && claimed[t];
        }
        if ((double)overlap > MX_VIEW_GROUP_OVERLAP * (double)fresh && plan->n > 0) {
            group++;
            memcpy(group_known, sim, n);
            memset(claimed, 0, n);
        }
        for (int64_t k = 0; k < vc->ntexels[c]; k++) {
            int32_t t = vc->texels[c][k];
            if (!sim[t]) claimed[t] = 1;
            sim[t] = 1;
        }
        used[c] = 1;
        plan->cand[plan->n] = c;
        plan->group[plan->n] = group;
        plan->n++;
        plan->coverage = simulated_coverage(sim, visible, n);
    }
    free(sim), free(visible), free(claimed), free(used), free(group_known);
    return 0;
}

int mx_view_plan_make(const mx_view_cache *vc, const uint8_t *known, int budget,
                      double coverage_stop, int64_t min_pixels, mx_view_plan *plan, mx_status *st) {
    return plan_views(vc, known, NULL, budget, coverage_stop, min_pixels, plan, st);
}

int mx_view_schedule_init(mx_view_schedule *s, const mx_view_cache *vc, const mx_view_schedule_params *p,
                          mx_status *st) {
    *s = (mx_view_schedule){.vc = vc, .p = *p};
    if (s->p.max_batch < 1) s->p.max_batch = 1;
    s->used = calloc((size_t)vc->ncand, 1);
    if (!s->used) return mx_fail(st, MX_ENOMEM, "view selection: out of memory");
    return 0;
}

void mx_view_schedule_free(mx_view_schedule *s) {
    free(s->used);
    memset(s, 0, sizeof *s);
}

/* The plan of the next max_batch views is the greedy sequence from T^B; its first group (views
 * whose untextured texels do not overlap) is the step. */
int mx_view_schedule_next(mx_view_schedule *s, const uint8_t *known, int *cand, int *n, mx_status *st) {
    *n = 0;
    int left = s->p.budget - s->done, budget = left < s->p.max_batch ? left : s->p.max_batch;
    if (budget <= 0) return 0;
    mx_view_plan plan;
    if (plan_views(s->vc, known, s->used, budget, s->p.coverage_stop, s->p.min_gain, &plan, st)) return -1;
    for (int i = 0; i < plan.n && plan.group[i] == plan.group[0]; i++) {
        cand[(*n)++] = plan.cand[i];
        s->used[plan.cand[i]] = 1;
    }
    s->done += *n;
    mx_view_plan_free(&plan);
    return 0;
}

int mx_view_buffers_init(mx_view_buffers *vb, int size, mx_status *st) {
    memset(vb, 0, sizeof *vb);
    vb->mask = malloc((size_t)size * size);
    vb->tmp = malloc((size_t)size * size);
    if (!vb->mask || !vb->tmp) {
        mx_view_buffers_free(vb);
        return mx_fail(st, MX_ENOMEM, "view buffers: out of memory");
    }
    if (mx_gbuffer_init(&vb->gb, size, size, st)) {
        mx_view_buffers_free(vb);
        return -1;
    }
    return 0;
}

void mx_view_buffers_free(mx_view_buffers *vb) {
    mx_gbuffer_free(&vb->gb);
    free(vb->mask);
    free(vb->tmp);
    memset(vb, 0, sizeof *vb);
}

#define MASK_ROWS 16

typedef struct mask_job {
    mx_view_buffers *vb;
    int normal_source;
    float threshold;
} mask_job;

/* The common case (orthographic camera, geometric normals) in one pass over the pixels:
 * the same tests as mx_mask_frontal_rows, mx_mask_internal and mx_mask_and_not. */
static void ortho_geometric_masks(mx_view_buffers *vb, float threshold, size_t i0, size_t i1) {
    const mx_gbuffer *gb = &vb->gb;
    const float *fn = mx_gbuffer_face_normals(gb);
    float v[3] = {-gb->cam.forward[0], -gb->cam.forward[1], -gb->cam.forward[2]};
    for (size_t i = i0; i < i1; i++) {
        float a = gb->depth[i], b = gb->depth_unculled[i];
        uint8_t internal = !isinf(b) && (isinf(a) || a - b > 1e-4f * fabsf(a));
        uint8_t frontal = 0;
        int f = gb->face[i];
        if (f >= 0) {
            const float *n = fn + 3 * (size_t)f;
            frontal = fabsf(n[0] * v[0] + n[1] * v[1] + n[2] * v[2]) >= threshold;
        }
        vb->tmp[i] = internal;
        vb->mask[i] = frontal && !internal;
    }
}

static void view_mask_task(void *ctx, int task, int thread) {
    (void)thread;
    mask_job *j = ctx;
    mx_view_buffers *vb = j->vb;
    int y0 = task * MASK_ROWS, y1 = y0 + MASK_ROWS < vb->gb.h ? y0 + MASK_ROWS : vb->gb.h;
    size_t o = (size_t)y0 * vb->gb.w;
    int64_t n = (int64_t)(y1 - y0) * vb->gb.w;
    if (vb->gb.cam.ortho && j->normal_source != MX_NORMAL_FROM_DEPTH) {
        ortho_geometric_masks(vb, j->threshold, o, o + (size_t)n);
        return;
    }
    mx_mask_frontal_rows(&vb->gb, j->normal_source, j->threshold, y0, y1, vb->mask);
    mx_mask_internal(vb->gb.depth + o, vb->gb.depth_unculled + o, n, vb->tmp + o);
    mx_mask_and_not(vb->mask + o, vb->tmp + o, vb->mask + o, n);
}

void mx_view_masks(mx_view_buffers *vb, int normal_source, float frontal_threshold, mx_pool *pool) {
    mask_job j = {vb, normal_source, frontal_threshold};
    mx_pool_for(pool, (vb->gb.h + MASK_ROWS - 1) / MASK_ROWS, view_mask_task, &j);
}

int mx_view_prepare(mx_view_buffers *vb, const mx_mesh *m, const float *pos, const mx_camera *cam,
                    int normal_source, float frontal_threshold, mx_pool *pool, mx_status *st) {
    if (mx_rasterize(m, pos, cam, MX_VIEW_RASTER_FLAGS, pool, &vb->gb, st)) return -1;
    mx_view_masks(vb, normal_source, frontal_threshold, pool);
    return 0;
}

int mx_view_erode_radius(int render_size, int image_size) {
    float ratio = image_size > 0 ? (float)render_size / (float)image_size : 1.0f;
    int r = (int)ceilf(MX_VIEW_ERODE_MODEL_PX * ratio - 1e-4f);
    return r < 1 ? 1 : r;
}

/* World size of one pixel at depth d (orthographic: the same everywhere). */
static float pixel_footprint(const mx_camera *cam, int h, float d) {
    if (cam->ortho) return 2.0f * cam->half_extent / (float)h;
    return d * 2.0f * tanf(cam->fov_y * 0.5f * 3.14159265f / 180.0f) / (float)h;
}

static void mark_edges(const mx_gbuffer *gb, uint8_t *edge) {
    int w = gb->w, h = gb->h;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            edge[i] = 0;
            if (gb->face[i] < 0) continue;
            float d = gb->depth[i], jump = MX_VIEW_DEPTH_JUMP * pixel_footprint(&gb->cam, h, d);
            int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
            for (int k = 0; k < 4 && !edge[i]; k++) {
                if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
                size_t o = (size_t)ny[k] * w + nx[k];
                edge[i] = gb->face[o] < 0 || fabsf(gb->depth[o] - d) > jump;
            }
        }
}

/* out[i] = 1 when some in[j] is set with |j - i| <= r along rows (stride 1, n per line,
 * `lines` lines of `line_stride`) or columns: one pass of a separable square dilation. */
static void dilate_lines(const uint8_t *in, uint8_t *out, int n, int lines, size_t step, size_t line_stride, int r) {
    for (int l = 0; l < lines; l++) {
        const uint8_t *a = in + (size_t)l * line_stride;
        uint8_t *b = out + (size_t)l * line_stride;
        int last = -1 - r; /* position of the latest set pixel seen, looking ahead r */
        for (int i = 0; i < n + r; i++) {
            if (i < n && a[(size_t)i * step]) last = i;
            int o = i - r;
            if (o >= 0) b[(size_t)o * step] = 0;
            if (o >= 0 && last >= o - r) b[(size_t)o * step] = 1;
        }
    }
}

/* mask &= not within radius of an edge pixel of gb; tmp: scratch of the image size. */
static int erode_mask(const mx_gbuffer *gb, uint8_t *mask, uint8_t *tmp, int radius, mx_status *st) {
    int w = gb->w, h = gb->h;
    size_t n = (size_t)w * h;
    uint8_t *edge = malloc(n);
    if (!edge) return mx_fail(st, MX_ENOMEM, "edge erosion: out of memory");
    mark_edges(gb, edge);
    dilate_lines(edge, tmp, w, h, 1, (size_t)w, radius);
    dilate_lines(tmp, edge, h, w, (size_t)w, 1, radius);
    for (size_t i = 0; i < n; i++) mask[i] = mask[i] && !edge[i];
    free(edge);
    return 0;
}

int mx_view_erode_edges(mx_view_buffers *vb, int radius, mx_status *st) {
    return erode_mask(&vb->gb, vb->mask, vb->tmp, radius, st);
}

int mx_view_scale_radius(int radius, int from, int to) {
    if (radius <= 0 || from <= 0) return 0;
    int r = (int)lroundf((float)radius * (float)to / (float)from);
    return r < 1 ? 1 : r;
}
