/* The blocked GEMM engine (see gemm.h): packing, blocking and the threaded driver. The SIMD
 * files supply the micro-kernel and the weight widening. */
#include "gemm.h"

#include <string.h>

#include "wpack.h"

/* Rows of A per compute task (rounded down to whole MR panels). */
#define MC_ROWS 96
/* Compute tasks wanted, so that a few threads stay busy; the row blocks of a tall GEMM
 * (M = 4096: 43 blocks) are then enough on their own and N is not split. */
#define TASKS_WANTED 32
/* Tasks of the COLUMNS or ROWS split wanted at least (else TILES, which splits both ways). */
#define SPLIT_TASKS_MIN 8

static int min_int(int a, int b) { return a < b ? a : b; }
static int max_int(int a, int b) { return a > b ? a : b; }
static int ceil_div(int a, int b) { return (a + b - 1) / b; }


void mx_gemm_zero_panel_tail(const mx_gemm_kernel *g, void *dstv, int width, int valid, int kc) {
    int rows = g->to_pairs ? (kc + 1) / 2 : kc;
    uint32_t *dst = dstv;
    for (int k = 0; k < rows && valid < width; k++)
        memset(dst + (size_t)k * width + valid, 0, (size_t)(width - valid) * sizeof *dst);
    size_t words = mx_gemm_panel_words(g, kc);
    for (size_t k = (size_t)rows; k < words; k++) memset(dst + k * width, 0, (size_t)width * sizeof *dst);
}

/* Starts fetching rows first..first+n-1, columns k0..k0+kc-1, of a row-major matrix. The packers
 * read a weight matrix a few rows at a time, each row only a short run (kc elements: 1.25 KiB of
 * fp16 at kc = 640) that the hardware prefetcher barely ramps up on; without this, widening the
 * weights (straight from memory, far larger than the caches) stalled on every load. */
void mx_gemm_prefetch_rows(mx_wptr src, size_t ld, int first, int n, int k0, int kc) {
    size_t es = mx_dtype_size(src.dtype), bytes = (size_t)kc * es;
    for (int r = 0; r < n; r++) {
        const char *row = (const char *)src.data + ((size_t)(first + r) * ld + (size_t)k0) * es;
        for (size_t b = 0; b < bytes; b += 64) __builtin_prefetch(row + b, 0, 3);
    }
}

/* One row of src (element (r, k) at r*ld + k) as kc/2 words of pairs (16-bit weights widened),
 * of its low part with lo. */
static void row_to_pairs(const mx_gemm_kernel *g, uint32_t *dst, mx_wptr src, size_t ld, int r, int k0, int kc,
                         int lo) {
    float row[MX_GEMM_KC_MAX];
    size_t off = (size_t)r * ld + (size_t)k0;
    const float *f = (const float *)src.data + off;
    if (src.dtype != MX_F32) {
        g->widen(row, src, off, (size_t)kc);
        f = row;
    }
    (lo ? g->row_pairs_lo : g->row_pairs)(dst, f, kc);
}

/* bf16 pairs, row-major (a_rows): dst[r][words], each row's pairs then zeros. */
static void pack_rows_pairs_rowmajor(const mx_gemm_kernel *g, uint32_t *dst, mx_wptr src, size_t ld, int first,
                                     int valid, int width, int k0, int kc, int lo) {
    size_t words = mx_gemm_panel_words(g, kc), kp = (size_t)(kc + 1) / 2;
    for (int r = 0; r < width; r++) {
        uint32_t *d = dst + (size_t)r * words;
        size_t done = 0;
        if (r < valid) {
            row_to_pairs(g, d, src, ld, first + r, k0, kc, lo);
            done = kp;
        }
        memset(d + done, 0, (words - done) * sizeof *d);
    }
}

/* k per chunk of the k-major packers: a chunk of a panel (width rows × PACK_CHUNK k, 8 KiB of fp32
 * at NR = 32) is gathered in L1 and then written whole, one contiguous run of the panel. Packing
 * MX_GEMM_WIDEN_ROWS rows of the whole K block at a time instead wrote a quarter of each panel row
 * per pass (32-byte pieces of every 128-byte row), each pass reading back from memory the lines the
 * previous one had left half written. */
#define PACK_CHUNK 64

/* Rows first..first+valid-1 of src, columns k .. k+n (n <= PACK_CHUNK), as rows *ld apart from
 * the address returned: fp32 weights in place, 16-bit ones widened into tmp[r][PACK_CHUNK], or with
 * pairs (n+1)/2 words of bf16 pairs there (of the low parts with lo). */
static const float *gather_chunk(const mx_gemm_kernel *g, float *tmp, mx_wptr src, size_t ld, int first, int valid,
                                 int k, int n, int pairs, int lo, size_t *tmp_ld) {
    size_t base = (size_t)first * ld + (size_t)k;
    if (!pairs && src.dtype == MX_F32) {
        *tmp_ld = ld;
        return (const float *)src.data + base;
    }
    for (int r = 0; r < valid; r++) {
        float *t = tmp + (size_t)r * PACK_CHUNK;
        if (pairs)
            row_to_pairs(g, (uint32_t *)(void *)t, src, ld, first + r, k, n, lo);
        else
            g->widen(t, src, base + (size_t)r * ld, (size_t)n);
    }
    *tmp_ld = PACK_CHUNK;
    return tmp;
}

/* k-major panels dst[words][width] of `valid` rows of src (of the `total` rows from `first` on),
 * chunk by chunk (PACK_CHUNK): fp32 values, or bf16 pairs (to_pairs kernels; of the low parts with
 * lo); the chunk's source lines of the next chunk (at the last one, the next panel's first) are
 * fetched meanwhile. */
static void pack_rows_kmajor(const mx_gemm_kernel *g, void *dstv, mx_wptr src, size_t ld, int first, int valid,
                             int total, int width, int k0, int kc, int lo) {
    float tmp[MX_GEMM_PANEL_MAX * PACK_CHUNK];
    int pairs = g->to_pairs != NULL, per_word = pairs ? 2 : 1;
    uint32_t *dst = dstv;
    for (int k = 0; k < kc; k += PACK_CHUNK) {
        int n = min_int(PACK_CHUNK, kc - k), next = min_int(PACK_CHUNK, kc - k - n);
        if (next > 0)
            mx_gemm_prefetch_rows(src, ld, first, valid, k0 + k + n, next);
        else
            mx_gemm_prefetch_rows(src, ld, first + valid, min_int(width, total - valid), k0, min_int(PACK_CHUNK, kc));
        size_t rows_ld;
        const float *rows = gather_chunk(g, tmp, src, ld, first, valid, k0 + k, n, pairs, lo, &rows_ld);
        /* a bit-exact copy: the transpose only shuffles 32-bit lanes */
        g->transpose((float *)(void *)(dst + (size_t)(k / per_word) * width), (size_t)width, rows, rows_ld, valid,
                     (n + per_word - 1) / per_word);
    }
    mx_gemm_zero_panel_tail(g, dst, width, valid, kc);
}

/* Transposes `valid` rows of src (element (r, k) at r*ld + k) into the k-major panel dst[k][width]
 * (pack_rows_kmajor; bf16 kernels: pairs), or for row_major the row-major pairs of
 * pack_rows_pairs_rowmajor (the A panels of a_rows kernels); of the rows' low parts with lo (bf16
 * kernels only). */
static void pack_rows(const mx_gemm_kernel *g, void *dstv, mx_wptr src, size_t ld, int first, int total,
                      int width, int k0, int kc, int row_major, int lo) {
    int valid = min_int(width, total);
    if (g->to_pairs && row_major)
        pack_rows_pairs_rowmajor(g, dstv, src, ld, first, valid, width, k0, kc, lo);
    else
        pack_rows_kmajor(g, dstv, src, ld, first, valid, total, width, k0, kc, lo);
}

void mx_gemm_pack_a_rows(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                         int k0, int kc) {
    pack_rows(g, dst, p->a_mat, p->a_ld, first, p->M - first, rows, k0, kc, g->a_rows, 0);
}

void mx_gemm_pack_b_rows(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                         int k0, int kc) {
    pack_rows(g, dst, p->b_mat, p->b_ld, first, p->N - first, rows, k0, kc, 0, 0);
}

/* Both parts of a split kernel's panel: the high part in split_of's format at dst, the low part
 * right after it. */
static void pack_split(const mx_gemm_problem *p, const mx_gemm_kernel *g, const mx_gemm_pack_fn part[2], void *dst,
                       int first, int width, int k0, int kc) {
    const mx_gemm_kernel *one = g->split_of;
    part[0](p, one, dst, first, width, k0, kc);
    part[1](p, one, (uint32_t *)dst + mx_gemm_panel_words(one, kc) * (size_t)width, first, width, k0, kc);
}

void mx_gemm_pack_a_split(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                          int k0, int kc) {
    pack_split(p, g, p->split_a, dst, first, rows, k0, kc);
}

void mx_gemm_pack_b_split(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int cols,
                          int k0, int kc) {
    pack_split(p, g, p->split_b, dst, first, cols, k0, kc);
}

void mx_gemm_pack_a_rows_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                            int k0, int kc) {
    pack_rows(g, dst, p->a_mat, p->a_ld, first, p->M - first, rows, k0, kc, g->a_rows, 1);
}

void mx_gemm_pack_b_rows_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                            int k0, int kc) {
    pack_rows(g, dst, p->b_mat, p->b_ld, first, p->N - first, rows, k0, kc, 0, 1);
}

/* Outer blocks of columns bound the shared B buffer (≤ OUTER_MAX columns per K block, ~5 MiB),
 * whatever the problem size, e.g. a VAE conv over 512×512 pixels. */
#define OUTER_MAX 4096

/* How a K block's work is split into tasks (chosen by problem size only; who computes a tile
 * never changes its sums):
 * - TILES: per batch item and outer block of columns, B packed by all threads, then MC×NC
 *   tiles; A per thread, or shared (small M);
 * - COLUMNS (column_task): A shared, B packed per call: each task packs a block of B panels
 *   and computes its whole column of C;
 * - ROWS (row_task): A shared, B packed per call but too few columns for COLUMNS (e.g. a conv
 *   of 1280 channels at 16×16): B of every batch item packed once by all threads, then each
 *   task computes a row block of C across all of them, so each A block (a weight read from
 *   memory) is read once per K block instead of once per batch item and column block. */
typedef enum { GEMM_TILES, GEMM_COLUMNS, GEMM_ROWS } gemm_split;

typedef struct {
    const mx_gemm_kernel *g;
    const mx_gemm_problem *p;
    /* the B panels of the outer block: bpack (packed by all threads), or the weight's cached ones */
    float *bpack;
    const float *b;
    /* per-thread A blocks (MC rows × kc, packed by the thread that computes with them, so they
     * stay in its L2) and the row block each one holds (-1: none yet in this K block); or, with
     * shared_a, all of A's panels of the K block at a: packed once by all threads into ablock,
     * or the weight's cached ones */
    float *ablock;
    const float *a;
    size_t ablock_stride;
    int *ablock_mb;
    int shared_a;
    /* a weight's panels of every K block from the context's cache (pack_weight_once), or NULL */
    const float *a_cached, *b_cached;
    int kc_max;
    const float *bias; /* widened, or NULL */
    const float *bias_rows; /* a row bias for micro_bias (MX_GEMM_BIAS_ROW copies of each), or NULL */
    int n_off, n_end; /* the outer block of columns */
    int k0, kc, first_block, last_block;
    int mpanels, npanels, mc_panels, nc_panels, nmb, nnb;
    gemm_split split;
    /* column tasks: thread t's B panels at bpack + t·bpack_stride */
    size_t bpack_stride;
    /* with a profile (c->prof): thread t's seconds of each part at part_secs[t·MX_GEMM_PARTS + part] */
    double *part_secs;
    /* column tasks whose B panels are read in place (problem.rows_in_place) at these offsets,
     * not packed */
    int rows_in_place;
    int32_t offs[MX_GEMM_KC_MAX + MX_GEMM_ROWS_AHEAD];
} gemm_job;

/* The clock of the profiled parts, the thread's CPU time: 0 (never read) without a profile. */
static double part_clock(const gemm_job *j) { return j->part_secs ? mx_profile_clock(CLOCK_THREAD_CPUTIME_ID) : 0; }

static void add_part(const gemm_job *j, int thread, mx_gemm_part part, double t0, double t1) {
    if (j->part_secs) j->part_secs[(size_t)thread * MX_GEMM_PARTS + part] += t1 - t0;
}

#define PACK_PANELS_PER_TASK 4


static void pack_b_task(void *arg, int task, int thread) {
    const gemm_job *j = arg;
    int nr = j->g->nr;
    double t0 = part_clock(j);
    for (int np = task * PACK_PANELS_PER_TASK; np < min_int(j->npanels, (task + 1) * PACK_PANELS_PER_TASK); np++)
        j->p->pack_b(j->p, j->g, j->bpack + (size_t)np * mx_gemm_panel_words(j->g, j->kc) * nr, j->n_off + np * nr, nr, j->k0,
                     j->kc);
    add_part(j, thread, MX_GEMM_PACK_B, t0, part_clock(j));
}

/* A panels of the K block packed once for all tasks (shared_a). */
static void pack_a_task(void *arg, int task, int thread) {
    const gemm_job *j = arg;
    int mr = j->g->mr;
    size_t panel = mx_gemm_panel_words(j->g, j->kc) * mr;
    double t0 = part_clock(j);
    for (int mp = task * PACK_PANELS_PER_TASK; mp < min_int(j->mpanels, (task + 1) * PACK_PANELS_PER_TASK); mp++)
        j->p->pack_a(j->p, j->g, j->ablock + (size_t)mp * panel, mp * mr, mr, j->k0, j->kc);
    add_part(j, thread, MX_GEMM_PACK_A, t0, part_clock(j));
}

/* The packed A panels of row block mb: in the shared buffer (shared_a), else in this thread's
 * buffer, packed only when the thread's previous task used another block (tasks of one row block
 * are claimed one after the other). Packing copies values exactly, so who packs never changes a
 * result. */
static const float *thread_a_block(const gemm_job *j, int mb, int thread) {
    if (j->shared_a) return j->a + (size_t)mb * j->mc_panels * mx_gemm_panel_words(j->g, j->kc) * j->g->mr;
    float *buf = j->ablock + (size_t)thread * j->ablock_stride;
    if (j->ablock_mb[thread] != mb) {
        int mr = j->g->mr, mp0 = mb * j->mc_panels, mp1 = min_int(j->mpanels, mp0 + j->mc_panels);
        for (int mp = mp0; mp < mp1; mp++)
            j->p->pack_a(j->p, j->g, buf + (size_t)(mp - mp0) * mx_gemm_panel_words(j->g, j->kc) * mr, mp * mr, mr, j->k0,
                         j->kc);
        j->ablock_mb[thread] = mb;
    }
    return buf;
}

/* The problem of batch item b: its own C and image. */
static mx_gemm_problem batch_item(const mx_gemm_problem *p, int b) {
    mx_gemm_problem q = *p;
    q.C += (size_t)b * p->c_batch_stride;
    if (q.image) q.image += (size_t)b * p->image_batch_stride;
    if (q.image_lo) q.image_lo += (size_t)b * p->image_batch_stride;
    return q;
}

/* C's tile of A panels mp0..mp1 (at a) × B panels np0..np1 (at b) of problem p: B panels outside,
 * A panels (in L2) inside. */
static void compute_tile(const gemm_job *j, const mx_gemm_problem *p, const float *a, int mp0, int mp1,
                         const float *b, int np0, int np1) {
    int mr = j->g->mr, nr = j->g->nr;
    size_t words = mx_gemm_panel_words(j->g, j->kc);
    /* the kernel starts the sums at the bias in the first K block */
    int folded = j->g->micro_bias != NULL;
    if (j->g->begin) j->g->begin();
    for (int np = np0; np < np1; np++, b += words * nr) {
        int n0 = j->n_off + np * nr, n = min_int(nr, j->n_end - n0);
        const uint32_t *half[2];
        int in_place = j->rows_in_place && p->panel_in_place(p, j->g, n0, half);
        for (int mp = mp0; mp < mp1; mp++) {
            int m0 = mp * mr, m = min_int(mr, p->M - m0);
            const float *ap = a + (size_t)(mp - mp0) * words * mr;
            float *cp = p->C + (size_t)m0 * p->ldc + n0;
            int accumulate = !j->first_block;
            const float *bias = j->bias ? (p->bias_per_row ? j->bias + m0 : j->bias + n0) : NULL;
            const float *start = bias && folded && !accumulate
                                     ? (p->bias_per_row ? j->bias_rows + (size_t)m0 * MX_GEMM_BIAS_ROW : bias)
                                     : NULL;
            if (in_place)
                j->g->micro_rows(j->kc, ap, half, j->offs, cp, p->ldc, m, accumulate, start, p->bias_per_row);
            else if (start)
                j->g->micro_bias(j->kc, ap, b, cp, p->ldc, m, n, start, p->bias_per_row);
            else
                j->g->micro(j->kc, ap, b, cp, p->ldc, m, n, accumulate);
            /* else the bias while the tile is still in L1 (a pass over C afterwards read it back
             * from memory: 2-3 % of a VAE decode) */
            if (j->last_block && bias && !folded) j->g->add_bias(cp, p->ldc, m, n, bias, p->bias_per_row);
        }
    }
    if (j->g->end) j->g->end();
}

/* One MC×NC tile of C with the shared B panels of the outer block and the A panels of the
 * thread's row block. */
static void compute_task(void *arg, int task, int thread) {
    const gemm_job *j = arg;
    int mb = task / j->nnb, nb = task % j->nnb;
    int mp0 = mb * j->mc_panels, mp1 = min_int(j->mpanels, mp0 + j->mc_panels);
    int np0 = nb * j->nc_panels, np1 = min_int(j->npanels, np0 + j->nc_panels);
    double t0 = part_clock(j);
    const float *a = thread_a_block(j, mb, thread);
    double t1 = part_clock(j);
    add_part(j, thread, MX_GEMM_PACK_A, t0, t1);
    compute_tile(j, j->p, a, mp0, mp1, j->b + (size_t)np0 * mx_gemm_panel_words(j->g, j->kc) * j->g->nr, np0, np1);
    add_part(j, thread, MX_GEMM_MICRO, t1, part_clock(j));
}

/* Column tasks, for A shared (all its panels packed for the K block) and B packed per call:
 * task = (batch item, block of nc_panels B panels); the thread packs that block's B panels
 * into its own buffer and computes the whole column of C with them, row block by row block.
 * The B panels are then written and read by one core and stay in its L2, where with shared B
 * panels packed by all threads and tiles claimed row block first every task read a block of
 * panels (up to 640 KiB) that the other core had written: a 3×3 conv of 320 channels at 64×64
 * ran at 86 % of the peak on one thread and 63 % on two. One join per block instead of two. */
static void column_task(void *arg, int task, int thread) {
    const gemm_job *j = arg;
    int ncb = ceil_div(j->npanels, j->nc_panels), b = task / ncb, cb = task % ncb, nr = j->g->nr;
    int np0 = cb * j->nc_panels, np1 = min_int(j->npanels, np0 + j->nc_panels);
    mx_gemm_problem item = batch_item(j->p, b);
    size_t words = mx_gemm_panel_words(j->g, j->kc);
    float *bbuf = j->bpack + (size_t)thread * j->bpack_stride;
    double t0 = part_clock(j);
    const uint32_t *half[2];
    for (int np = np0; np < np1; np++)
        if (!j->rows_in_place || !item.panel_in_place(&item, j->g, j->n_off + np * nr, half))
            item.pack_b(&item, j->g, bbuf + (size_t)(np - np0) * words * nr, j->n_off + np * nr, nr, j->k0, j->kc);
    double t1 = part_clock(j);
    add_part(j, thread, MX_GEMM_PACK_B, t0, t1);
    for (int mp0 = 0; mp0 < j->mpanels; mp0 += j->mc_panels)
        compute_tile(j, &item, j->a + (size_t)mp0 * words * j->g->mr, mp0, min_int(j->mpanels, mp0 + j->mc_panels), bbuf,
                     np0, np1);
    add_part(j, thread, MX_GEMM_MICRO, t1, part_clock(j));
}

/* Row block mb of C over every batch item, with B packed for all of them (ROWS). */
static void row_task(void *arg, int mb, int thread) {
    const gemm_job *j = arg;
    int mp0 = mb * j->mc_panels, mp1 = min_int(j->mpanels, mp0 + j->mc_panels);
    size_t words = mx_gemm_panel_words(j->g, j->kc), item_floats = (size_t)j->npanels * words * j->g->nr;
    double t0 = part_clock(j);
    for (int b = 0; b < j->p->batch; b++) {
        mx_gemm_problem item = batch_item(j->p, b);
        compute_tile(j, &item, j->a + (size_t)mp0 * words * j->g->mr, mp0, mp1, j->bpack + (size_t)b * item_floats, 0,
                     j->npanels);
    }
    add_part(j, thread, MX_GEMM_MICRO, t0, part_clock(j));
}

/* B panels task·PACK_PANELS_PER_TASK... of every batch item in a row (ROWS). */
static void pack_b_items_task(void *arg, int task, int thread) {
    const gemm_job *j = arg;
    int nr = j->g->nr, per_item = ceil_div(j->npanels, PACK_PANELS_PER_TASK), b = task / per_item;
    int np0 = task % per_item * PACK_PANELS_PER_TASK;
    size_t words = mx_gemm_panel_words(j->g, j->kc);
    mx_gemm_problem item = batch_item(j->p, b);
    float *dst = j->bpack + (size_t)b * j->npanels * words * nr;
    double t0 = part_clock(j);
    for (int np = np0; np < min_int(j->npanels, np0 + PACK_PANELS_PER_TASK); np++)
        item.pack_b(&item, j->g, dst + (size_t)np * words * nr, np * nr, nr, j->k0, j->kc);
    add_part(j, thread, MX_GEMM_PACK_B, t0, part_clock(j));
}

/* Convs read their B panels in place (micro_rows) only up to this many A panels (Cout 264 on
 * 12-row panels): a packed panel is copied once and then read by every A panel's micro call,
 * one read in place costs a little in each of them (its rows lie scattered over the band, no
 * stream prefetch). Zen 5, 2 threads, 3×3 convs: Cout 128 at 256² and 512², +8-13 % (fp32 and
 * bf16); 256, +3-8 %; 320-1280 (the UNet's), no gain within the noise. */
#define ROWS_IN_PLACE_PANELS_MAX 22

/* B panels per column task: a block that stays in L2 beside an MC-row block of A. */
#define COLUMN_BLOCK_BYTES (384 << 10)

static int column_panels(const mx_gemm_kernel *g, int kc) {
    return max_int(1, (int)(COLUMN_BLOCK_BYTES / (mx_gemm_panel_words(g, kc) * g->nr * sizeof(float))));
}

/* The split of gemm_split's comment: COLUMNS or ROWS where A is shared, B is packed per call and
 * there are enough of those tasks to keep a few threads busy (ROWS also only where B of all
 * batch items fits one outer block), else TILES. */
static gemm_split choose_split(const mx_gemm_kernel *g, const mx_gemm_problem *p, int shared_a, int b_cached,
                               int kc_max) {
    if (!shared_a || b_cached) return GEMM_TILES;
    int npanels = ceil_div(p->N, g->nr), row_blocks = ceil_div(ceil_div(p->M, g->mr), max_int(1, MC_ROWS / g->mr));
    if (p->batch * ceil_div(npanels, column_panels(g, kc_max)) >= SPLIT_TASKS_MIN) return GEMM_COLUMNS;
    if (row_blocks >= SPLIT_TASKS_MIN && (size_t)p->batch * npanels * g->nr <= OUTER_MAX) return GEMM_ROWS;
    return GEMM_TILES;
}

/* Task grid of the current outer block: MC-row blocks × NC-column blocks. */
static void plan_tiles(gemm_job *j) {
    const mx_gemm_kernel *g = j->g;
    j->mpanels = ceil_div(j->p->M, g->mr);
    j->npanels = ceil_div(j->n_end - j->n_off, g->nr);
    j->mc_panels = max_int(1, MC_ROWS / g->mr);
    j->nmb = ceil_div(j->mpanels, j->mc_panels);
    /* split N into equal blocks only as far as needed for enough tasks: a thread repacks its
     * A block whenever it moves to another row block */
    int nnb = min_int(j->npanels, ceil_div(TASKS_WANTED, j->nmb));
    j->nc_panels = ceil_div(j->npanels, nnb);
    j->nnb = ceil_div(j->npanels, j->nc_panels);
}

/* The length of the K blocks (the last one may be shorter): the problem's own, or blocks as
 * equal as can be of at most the kernel's. */
static int k_block_length(const mx_gemm_kernel *g, const mx_gemm_problem *p) {
    int most = mx_gemm_kc(g);
    if (p->kc_block > 0) return min_int(p->kc_block, most);
    return max_int(1, ceil_div(p->K, max_int(1, ceil_div(p->K, most))));
}

/* ---- a weight's panels packed once (wpack.h) ----
 * Layout: the panels of K block kb, as one call packs them (panel i at i · words(kc) · width),
 * start at kb · panels · words(kc_max) · width floats. */

static size_t cached_block_offset(const mx_gemm_kernel *g, int width, int rows, int kc_max, int kb) {
    return (size_t)kb * (size_t)ceil_div(rows, width) * mx_gemm_panel_words(g, kc_max) * (size_t)width;
}

typedef struct {
    const mx_gemm_kernel *g;
    const mx_gemm_problem *p;
    mx_gemm_pack_fn pack;
    float *dst;
    int width, rows, kc_max, tasks_per_block;
} weight_fill;

static void fill_task(void *arg, int task, int thread) {
    (void)thread;
    const weight_fill *f = arg;
    int kb = task / f->tasks_per_block, first = task % f->tasks_per_block * PACK_PANELS_PER_TASK;
    int k0 = kb * f->kc_max, kc = min_int(f->kc_max, f->p->K - k0), panels = ceil_div(f->rows, f->width);
    size_t words = mx_gemm_panel_words(f->g, kc);
    float *block = f->dst + cached_block_offset(f->g, f->width, f->rows, f->kc_max, kb);
    for (int i = first; i < min_int(panels, first + PACK_PANELS_PER_TASK); i++)
        f->pack(f->p, f->g, block + (size_t)i * words * f->width, i * f->width, f->width, k0, kc);
}

/* Packs f's panels of every K block by all threads; the CPU time (all threads: nothing else
 * runs in the process meanwhile) goes to the profile's part of that operand. */
static void fill_blocks(const mx_ctx *c, weight_fill *f, int operand_b) {
    double t0 = c && c->prof ? mx_profile_clock(CLOCK_PROCESS_CPUTIME_ID) : 0;
    f->tasks_per_block = ceil_div(ceil_div(f->rows, f->width), PACK_PANELS_PER_TASK);
    mx_par_for(c, ceil_div(f->p->K, f->kc_max) * f->tasks_per_block, fill_task, f);
    if (c && c->prof)
        c->prof->gemm_secs[f->p->image ? MX_GEMM_CONV : MX_GEMM_LINEAR][operand_b ? MX_GEMM_PACK_B : MX_GEMM_PACK_A] +=
            mx_profile_clock(CLOCK_PROCESS_CPUTIME_ID) - t0;
}

/* The panels of the weight operand (B with operand_b, else A) for every K block: from the
 * context's cache, packed into it by all threads on first use. NULL without a cache or room in
 * it (the caller packs per call). */
static const float *pack_weight_once(const mx_ctx *c, const mx_gemm_kernel *g, const mx_gemm_problem *p,
                                     int operand_b, int kc_max) {
    if (!c || !c->wpack || !(operand_b ? p->b_weight : p->a_weight)) return NULL;
    mx_wptr w = operand_b ? p->b_mat : p->a_mat;
    weight_fill f = {.g = g, .p = p, .pack = operand_b ? p->pack_b : p->pack_a, .width = operand_b ? g->nr : g->mr,
                     .rows = operand_b ? p->N : p->M, .kc_max = kc_max};
    mx_wpack_key key = {.data = w.data, .dtype = w.dtype, .packer = (const void *)(uintptr_t)f.pack, .kernel = g,
                        .rows = f.rows, .K = p->K, .ld = operand_b ? p->b_ld : p->a_ld};
    const float *have = mx_wpack_find(c->wpack, &key);
    if (have) return have;
    int nkb = ceil_div(p->K, kc_max);
    /* the weight's own rows: a phase-folded A (a_phases) has a_phases rows per weight row */
    int source_rows = operand_b || !p->a_phases ? f.rows : f.rows / p->a_phases;
    size_t source_bytes = (size_t)source_rows * key.ld * mx_dtype_size(w.dtype);
    /* a 32-bit panel word holds one fp32 value or a pair of bf16 ones; phase kernels hold 16 values
     * for every 9 of their weight */
    size_t own = (size_t)source_rows * key.ld, panel_values = (size_t)f.rows * (size_t)p->K;
    f.dst = mx_wpack_add(c->wpack, &key, cached_block_offset(g, f.width, f.rows, kc_max, nkb) * sizeof(float),
                         g->to_pairs ? 2 : 4, mx_dtype_size(w.dtype),
                         p->a_phases && !operand_b && panel_values > own ? panel_values - own : 0);
    if (!f.dst) return NULL;
    mx_wpack_fetch_source(c->wpack, w.data, source_bytes);
    fill_blocks(c, &f, operand_b);
    mx_wpack_release_source(c->wpack, w.data, source_bytes);
    return f.dst;
}

size_t mx_gemm_a_panels_floats(const mx_gemm_kernel *g, const mx_gemm_problem *p) {
    int kc_max = k_block_length(g, p);
    return cached_block_offset(g, g->mr, p->M, kc_max, ceil_div(p->K, kc_max));
}

const float *mx_gemm_cached_a_panels(const mx_ctx *c, const mx_gemm_kernel *g, const mx_gemm_problem *p) {
    return p->M > 0 && p->K > 0 ? pack_weight_once(c, g, p, 0, k_block_length(g, p)) : NULL;
}

const float *mx_gemm_pack_a_panels(const mx_ctx *c, const mx_gemm_kernel *g, const mx_gemm_problem *p, float *dst) {
    if (p->M <= 0 || p->K <= 0) return NULL;
    weight_fill f = {.g = g, .p = p, .pack = p->pack_a, .dst = dst, .width = g->mr, .rows = p->M,
                     .kc_max = k_block_length(g, p)};
    fill_blocks(c, &f, 0);
    return dst;
}

/* One K block: for every batch item and outer block of columns, B is packed by all threads,
 * then the tiles are computed (each thread packing the A blocks it needs; A is the same for
 * every batch item, so a thread's A block stays valid across items). */
static void run_k_block(const mx_ctx *c, gemm_job *j, const mx_gemm_problem *p, int nb_max, int nthreads) {
    const mx_gemm_kernel *g = j->g;
    int kb = j->k0 / j->kc_max;
    size_t words = mx_gemm_panel_words(g, j->kc);
    for (int t = 0; t < nthreads; t++) j->ablock_mb[t] = -1;
    if (j->a_cached)
        j->a = j->a_cached + cached_block_offset(g, g->mr, p->M, j->kc_max, kb);
    else if (j->shared_a)
        mx_par_for(c, ceil_div(ceil_div(p->M, g->mr), PACK_PANELS_PER_TASK), pack_a_task, j);
    if (j->split != GEMM_TILES) { /* one outer block, all batch items in one loop */
        j->n_off = 0;
        j->n_end = p->N;
        plan_tiles(j);
        if (j->split == GEMM_COLUMNS) {
            j->nc_panels = column_panels(g, j->kc_max);
            j->rows_in_place = p->rows_in_place && j->mpanels <= ROWS_IN_PLACE_PANELS_MAX &&
                               p->rows_in_place(p, g, j->k0, j->kc, j->offs);
            mx_par_for(c, p->batch * ceil_div(j->npanels, j->nc_panels), column_task, j);
        } else {
            mx_par_for(c, p->batch * ceil_div(j->npanels, PACK_PANELS_PER_TASK), pack_b_items_task, j);
            mx_par_for(c, j->nmb, row_task, j);
        }
        return;
    }
    for (int b = 0; b < p->batch; b++) {
        mx_gemm_problem item = batch_item(p, b);
        j->p = &item;
        for (j->n_off = 0; j->n_off < p->N; j->n_off += nb_max) {
            j->n_end = min_int(p->N, j->n_off + nb_max);
            plan_tiles(j);
            if (j->b_cached)
                j->b = j->b_cached + cached_block_offset(g, g->nr, p->N, j->kc_max, kb) +
                       (size_t)(j->n_off / g->nr) * words * g->nr;
            else
                mx_par_for(c, ceil_div(j->npanels, PACK_PANELS_PER_TASK), pack_b_task, j);
            mx_par_for(c, j->nmb * j->nnb, compute_task, j);
        }
    }
    j->p = p;
}

/* Adds the threads' part times and the FLOPs of p to the profile (conv: the problems with an image);
 * a split kernel's (split_of) as the three products it computes. */
static void profile_gemm(mx_profile *prof, const mx_gemm_kernel *g, const mx_gemm_problem *p, const double *part_secs,
                         int nthreads) {
    int user = p->image ? MX_GEMM_CONV : MX_GEMM_LINEAR;
    for (int t = 0; t < nthreads; t++)
        for (int part = 0; part < MX_GEMM_PARTS; part++)
            prof->gemm_secs[user][part] += part_secs[(size_t)t * MX_GEMM_PARTS + part];
    prof->gemm_flops[user] += (g->split_of ? 3 : 1) * 2.0 * p->M * p->N * (double)p->K * p->batch;
}

int mx_gemm_run(const mx_ctx *c, const mx_gemm_kernel *g, const mx_gemm_problem *p) {
    if (p->M <= 0 || p->N <= 0 || p->batch <= 0) return 0;
    /* outer blocks end on whole panels */
    int nb_max = OUTER_MAX / g->nr * g->nr, nb = min_int(p->N, nb_max);
    int kc_max = k_block_length(g, p), nkb = ceil_div(p->K, kc_max);
    int nthreads = mx_par_threads(c);
    size_t bias_n = p->bias.data ? (size_t)(p->bias_per_row ? p->M : p->N) : 0;
    /* a row bias as micro_bias reads it: each value MX_GEMM_BIAS_ROW times, after the bias */
    size_t bias_rows_n = bias_n && p->bias_per_row && g->micro_bias ? bias_n * MX_GEMM_BIAS_ROW : 0;
    size_t words = mx_gemm_panel_words(g, kc_max);
    size_t ablock_n = (size_t)max_int(1, MC_ROWS / g->mr) * g->mr * words;
    /* Fewer row blocks than tasks wanted: each row block is split over column blocks (and batch
     * items) that different threads compute, and per-thread A blocks would be packed once per
     * thread (per batch item) instead of once: pack all of A's K block up front then (M < 3072
     * rows here, so ≤ 7.5 MiB at kc = 640; e.g. every conv, M = Cout). */
    int mpanels = ceil_div(p->M, g->mr), shared_a = ceil_div(mpanels, max_int(1, MC_ROWS / g->mr)) < TASKS_WANTED;
    const float *a_cached = p->a_panels ? p->a_panels : pack_weight_once(c, g, p, 0, kc_max);
    const float *b_cached = pack_weight_once(c, g, p, 1, kc_max);
    if (a_cached) shared_a = 1;
    if (shared_a) ablock_n = a_cached ? 0 : (size_t)mpanels * g->mr * words;
    gemm_split split = choose_split(g, p, shared_a, b_cached != NULL, kc_max);
    size_t bpack_n = b_cached ? 0 : (size_t)ceil_div(nb, g->nr) * g->nr * words;
    if (split == GEMM_COLUMNS) bpack_n = (size_t)nthreads * column_panels(g, kc_max) * g->nr * words;
    if (split == GEMM_ROWS) bpack_n = (size_t)p->batch * ceil_div(p->N, g->nr) * g->nr * words;
    size_t ablocks = shared_a ? 1 : (size_t)nthreads;
    size_t floats = ablocks * ablock_n + bpack_n + bias_n + bias_rows_n;
    size_t nparts = c && c->prof ? (size_t)nthreads * MX_GEMM_PARTS : 0;
    mx_scratch s;
    /* floats, then the profile's doubles (8-byte aligned: floats is rounded up to even), then ints */
    floats += floats & 1;
    float *mem = mx_scratch_take(c, floats * sizeof(float) + nparts * sizeof(double) + (size_t)nthreads * sizeof(int), &s);
    if (!mem) return -1;
    double *part_secs = nparts ? (double *)(void *)(mem + floats) : NULL;
    gemm_job j = {.g = g, .p = p, .ablock = mem, .a = mem, .ablock_stride = ablock_n, .shared_a = shared_a,
                  .mpanels = mpanels, .a_cached = a_cached, .b_cached = b_cached, .kc_max = kc_max,
                  .part_secs = part_secs,
                  .ablock_mb = (int *)(void *)((char *)(mem + floats) + nparts * sizeof(double))};
    for (size_t i = 0; i < nparts; i++) part_secs[i] = 0;
    j.bpack = mem + ablocks * ablock_n;
    j.split = split;
    j.bpack_stride = split == GEMM_COLUMNS ? bpack_n / (size_t)nthreads : 0;
    j.b = j.bpack;
    if (bias_n) {
        float *bias = j.bpack + bpack_n;
        for (size_t i = 0; i < bias_n; i++) bias[i] = mx_w_get(p->bias, i);
        j.bias = bias;
        if (bias_rows_n) {
            float *rows = bias + bias_n;
            for (size_t i = 0; i < bias_rows_n; i++) rows[i] = bias[i / MX_GEMM_BIAS_ROW];
            j.bias_rows = rows;
        }
    }
    for (int b = 0; b < p->batch && p->K <= 0; b++) { /* empty sum: C = bias or 0 */
        mx_gemm_problem item = batch_item(p, b);
        for (int m = 0; m < p->M; m++) memset(item.C + (size_t)m * p->ldc, 0, (size_t)p->N * sizeof(float));
        if (j.bias) j.g->add_bias(item.C, p->ldc, p->M, p->N, j.bias, p->bias_per_row);
    }
    for (int kb = 0; kb < nkb && p->K > 0; kb++) {
        j.k0 = kb * kc_max;
        j.kc = min_int(kc_max, p->K - j.k0);
        j.first_block = kb == 0;
        j.last_block = kb == nkb - 1;
        run_k_block(c, &j, p, nb_max, nthreads);
    }
    if (part_secs) profile_gemm(c->prof, g, p, part_secs, nthreads);
    mx_scratch_release(c, &s);
    return 0;
}

static mx_gemm_problem linear_problem(float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    mx_gemm_problem p = {.M = M, .N = N, .K = K, .batch = 1, .C = y, .ldc = (size_t)N};
    p.pack_a = mx_gemm_pack_a_rows;
    p.pack_b = mx_gemm_pack_b_rows;
    p.a_mat = mx_w_f32(x);
    p.a_ld = (size_t)K;
    p.b_mat = w;
    p.b_ld = (size_t)K;
    p.b_weight = 1;
    p.bias = bias;
    return p;
}

void mx_gemm_linear(const mx_ctx *c, const mx_gemm_kernel *g, float *y, const float *x, mx_wptr w, mx_wptr bias,
                    int M, int N, int K) {
    mx_gemm_problem p = linear_problem(y, x, w, bias, M, N, K);
    if (g->split_of) { /* the split product: both parts of each operand in its panels */
        p.b_weight = 0; /* packed per call, as for conv2d (gemm_conv.c) */
        p.pack_a = mx_gemm_pack_a_split;
        p.pack_b = mx_gemm_pack_b_split;
        p.split_a[0] = mx_gemm_pack_a_rows, p.split_a[1] = mx_gemm_pack_a_rows_lo;
        p.split_b[0] = mx_gemm_pack_b_rows, p.split_b[1] = mx_gemm_pack_b_rows_lo;
    }
    if (mx_gemm_run(c, g, &p) != 0) mx_linear_ref(c, y, x, w, bias, M, N, K);
}
