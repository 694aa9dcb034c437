/* Weights packed once (ops/cpu/wpack.h, mx_ctx_pack_weights): at every CPU level this machine
 * has, linear and conv2d on a context that keeps packed weights give bit for bit what the same
 * level gives packing per call, on the call that packs and on the calls that reuse; a weight
 * used by two levels (a bf16 context and its mx_ctx_fp32 view share one cache) gets one entry
 * per level; the cache grows past its first table; panels that would take more than their
 * weight beyond the budget are not kept (packed per call, the same results), panels of the
 * weight's own size are (conv2d_up2x's phase kernels, larger than their weight, only with room); packing split over several threads gives the panels one thread gives, byte
 * for byte; a linear weight's panels hold the layout of gemm.h, value by value; a weight mapped from
 * a file is dropped from the process once packed but stays in the page cache. */
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "../ops/cpu/gemm.h"
#include "../ops/cpu/wpack.h"
#include "../ops/ops.h"
#include "util_test.h"

typedef struct {
    int M, N, K; /* linear */
    int B, Cin, H, W, Cout, k, stride, pad; /* conv */
} shapes;

/* Awkward sizes: odd everything, several K blocks (K > 640), a conv with three K blocks. */
static const shapes cases[] = {
    {.M = 37, .N = 70, .K = 1300, .B = 2, .Cin = 5, .H = 9, .W = 11, .Cout = 19, .k = 3, .stride = 1, .pad = 1},
    {.M = 3, .N = 33, .K = 17, .B = 1, .Cin = 150, .H = 7, .W = 6, .Cout = 13, .k = 3, .stride = 2, .pad = 1},
    {.M = 130, .N = 9, .K = 641, .B = 2, .Cin = 4, .H = 5, .W = 40, .Cout = 35, .k = 1, .stride = 1, .pad = 0},
};

/* fp16 copies of x (the dtype the model files store). */
static uint16_t *to_f16(const float *x, size_t n) {
    uint16_t *h = malloc(n * sizeof *h);
    for (size_t i = 0; i < n && h; i++) h[i] = mx_float_to_half(x[i]);
    return h;
}

static int conv_out(int n, const shapes *s) { return (n + 2 * s->pad - s->k) / s->stride + 1; }

/* linear then conv2d of case s on c into y (linear's M·N, then conv's outputs). */
static void run_case(const mx_ctx *c, const shapes *s, float *y, const float *x, mx_wptr lw, mx_wptr lb, mx_wptr cw,
                     mx_wptr cb) {
    mx_linear(c, y, x, lw, lb, s->M, s->N, s->K);
    mx_conv2d(c, y + (size_t)s->M * s->N, x, s->B, s->Cin, s->H, s->W, cw, cb, s->Cout, s->k, s->k, s->stride, s->pad);
}

static size_t case_outputs(const shapes *s) {
    return (size_t)s->M * s->N + (size_t)s->B * s->Cout * conv_out(s->H, s) * conv_out(s->W, s);
}

static int same_bits(const float *a, const float *b, size_t n) { return memcmp(a, b, n * sizeof *a) == 0; }

/* Case s at level k: per-call packing vs a caching context (first and second call), fp16 and
 * fp32 weights. */
static void check_case(const mx_kernels *k, mx_pool *pool, mx_arena *scratch, const shapes *s, uint64_t seed) {
    size_t nx = (size_t)s->M * s->K, ncx = (size_t)s->B * s->Cin * s->H * s->W;
    if (ncx > nx) nx = ncx;
    size_t nlw = (size_t)s->N * s->K, ncw = (size_t)s->Cout * s->Cin * s->k * s->k, ny = case_outputs(s);
    float *x = malloc(nx * sizeof *x), *lw = malloc(nlw * sizeof *lw), *cw = malloc(ncw * sizeof *cw);
    float *lb = malloc((size_t)s->N * sizeof *lb), *cb = malloc((size_t)s->Cout * sizeof *cb);
    float *want = malloc(ny * sizeof *want), *got = malloc(ny * sizeof *got);
    CHECK(x && lw && cw && lb && cb && want && got);
    mx_fill_random(x, nx, seed, -1, 1);
    mx_fill_random(lw, nlw, seed + 1, -0.5f, 0.5f);
    mx_fill_random(cw, ncw, seed + 2, -0.5f, 0.5f);
    mx_fill_random(lb, (size_t)s->N, seed + 3, -1, 1);
    mx_fill_random(cb, (size_t)s->Cout, seed + 4, -1, 1);
    uint16_t *lw16 = to_f16(lw, nlw), *cw16 = to_f16(cw, ncw);
    CHECK(lw16 && cw16);
    mx_wptr wl[2] = {mx_w_f32(lw), {lw16, MX_F16}}, wc[2] = {mx_w_f32(cw), {cw16, MX_F16}};
    for (int d = 0; d < 2; d++) {
        mx_status st;
        mx_ctx plain = {.pool = pool, .k = k, .scratch = scratch}, cached = plain;
        CHECK(mx_ctx_pack_weights(&cached, (size_t)1 << 30, 0, &st) == 0);
        run_case(&plain, s, want, x, wl[d], mx_w_f32(lb), wc[d], mx_w_f32(cb));
        for (int call = 0; call < 2; call++) {
            memset(got, 0xff, ny * sizeof *got);
            run_case(&cached, s, got, x, wl[d], mx_w_f32(lb), wc[d], mx_w_f32(cb));
            if (!same_bits(got, want, ny)) {
                fprintf(stderr, "%s M=%d N=%d K=%d Cin=%d %s weights, call %d: packed-once result differs\n",
                        mx_isa_name(k->isa), s->M, s->N, s->K, s->Cin, d ? "fp16" : "fp32", call + 1);
                mx_test_failures++;
            }
        }
        /* both weights are kept on the levels with the GEMM engine */
        if (k->isa != MX_ISA_SCALAR) CHECK(mx_wpack_bytes(cached.wpack) > 0);
        mx_wpack_destroy(cached.wpack);
    }
    free(lw16), free(cw16);
    free(x), free(lw), free(cw), free(lb), free(cb), free(want), free(got);
}

/* n rows padded to whole panels of the kernel of w's entries (NR: 32 on AVX-512, 12 on NEON); 0
 * when w holds none. */
static size_t padded_rows(const mx_wpack *w, int n) {
    for (size_t i = 0; i < mx_wpack_slots(w); i++) {
        mx_wpack_key key;
        size_t bytes;
        if (!mx_wpack_slot(w, i, &key, &bytes)) continue;
        int nr = ((const mx_gemm_kernel *)key.kernel)->nr;
        return (size_t)(n + nr - 1) / (size_t)nr * (size_t)nr;
    }
    return 0;
}

/* Many weights in one cache (its table grows), each reused on a second pass with the bytes held
 * unchanged; then a budget too small for any: nothing kept, same results. */
static void check_many_and_budget(const mx_kernels *k, mx_pool *pool, mx_arena *scratch) {
    enum { NW = 100, M = 5, N = 24, K = 40 };
    float *x = malloc(M * K * sizeof *x), *w = malloc((size_t)NW * N * K * sizeof *w);
    float *want = malloc((size_t)NW * M * N * sizeof *want), *got = malloc((size_t)NW * M * N * sizeof *got);
    CHECK(x && w && want && got);
    mx_fill_random(x, M * K, 7, -1, 1);
    mx_fill_random(w, (size_t)NW * N * K, 8, -1, 1);
    mx_status st;
    mx_ctx plain = {.pool = pool, .k = k, .scratch = scratch}, cached = plain, tiny = plain;
    CHECK(mx_ctx_pack_weights(&cached, (size_t)1 << 30, 0, &st) == 0);
    CHECK(mx_ctx_pack_weights(&tiny, 0, 0, &st) == 0);
    for (int i = 0; i < NW; i++)
        mx_linear(&plain, want + (size_t)i * M * N, x, mx_w_f32(w + (size_t)i * N * K), mx_w_none(), M, N, K);
    size_t held = 0;
    for (int pass = 0; pass < 2; pass++) {
        for (int i = 0; i < NW; i++)
            mx_linear(&cached, got + (size_t)i * M * N, x, mx_w_f32(w + (size_t)i * N * K), mx_w_none(), M, N, K);
        CHECK(same_bits(got, want, (size_t)NW * M * N));
        if (pass == 0) held = mx_wpack_bytes(cached.wpack);
    }
    CHECK(mx_wpack_bytes(cached.wpack) == held);
    if (k->isa != MX_ISA_SCALAR) CHECK(held >= (size_t)NW * N * K * 2); /* the scalar level packs nothing */
    /* no room beyond the weights: fp16 weights widened to fp32 panels stay unpacked, as bf16
     * pairs (the same bytes, edge padding aside) they are kept */
    uint16_t *w16 = to_f16(w, (size_t)NW * N * K);
    CHECK(w16 != NULL);
    for (int i = 0; i < NW; i++)
        mx_linear(&plain, want + (size_t)i * M * N, x, (mx_wptr){w16 + (size_t)i * N * K, MX_F16}, mx_w_none(), M, N, K);
    memset(got, 0, (size_t)NW * M * N * sizeof *got);
    for (int i = 0; i < NW; i++)
        mx_linear(&tiny, got + (size_t)i * M * N, x, (mx_wptr){w16 + (size_t)i * N * K, MX_F16}, mx_w_none(), M, N, K);
    CHECK(same_bits(got, want, (size_t)NW * M * N));
    /* bf16 panels: K/2 words of pairs per row, on amx rounded up to whole tiles of 16 */
    size_t words = k->isa == MX_ISA_AMX ? (K / 2 + 15) / 16 * 16 : K / 2;
    if (mx_isa_precision(k->isa) != MX_PREC_BF16) CHECK(mx_wpack_bytes(tiny.wpack) == 0);
    else CHECK(mx_wpack_bytes(tiny.wpack) == (size_t)NW * padded_rows(tiny.wpack, N) * words * 4);
    mx_wpack_destroy(tiny.wpack);
    tiny.wpack = NULL;
    CHECK(mx_ctx_pack_weights(&tiny, 0, 0, &st) == 0);
    float *y32 = malloc(M * 32 * sizeof *y32), *want32 = malloc(M * 32 * sizeof *want32);
    CHECK(y32 && want32);
    mx_linear(&plain, want32, x, (mx_wptr){w16, MX_F16}, mx_w_none(), M, 32, K);
    mx_linear(&tiny, y32, x, (mx_wptr){w16, MX_F16}, mx_w_none(), M, 32, K);
    CHECK(same_bits(y32, want32, M * 32));
    if (mx_isa_precision(k->isa) == MX_PREC_BF16)
        CHECK(mx_wpack_bytes(tiny.wpack) == padded_rows(tiny.wpack, 32) * words * 4);
    else
        CHECK(mx_wpack_bytes(tiny.wpack) == 0);
    CHECK(mx_wpack_extra_bytes(tiny.wpack) == 0);
    free(w16), free(y32), free(want32);
    mx_wpack_destroy(cached.wpack);
    mx_wpack_destroy(tiny.wpack);
    free(x), free(w), free(want), free(got);
}

/* conv2d_up2x: its phase kernels (16 values for every 9 weights) kept by a cache with room, the
 * per-call results on both calls; with no room beyond the weights they are not kept, at any level
 * (not even as bf16 pairs of fp16 weights: the growth counts), the same results. */
static void check_up2x(const mx_kernels *k, mx_pool *pool, mx_arena *scratch) {
    enum { B = 2, CI = 37, H = 7, W = 9, CO = 21 };
    size_t nx = (size_t)B * CI * H * W, nw = (size_t)CO * CI * 9, ny = (size_t)B * CO * 4 * H * W;
    float *x = malloc(nx * sizeof *x), *w = malloc(nw * sizeof *w), *want = malloc(ny * sizeof *want);
    float *got = malloc(ny * sizeof *got), bias[CO];
    CHECK(x && w && want && got);
    mx_fill_random(x, nx, 61, -1, 1);
    mx_fill_random(w, nw, 62, -0.5f, 0.5f);
    mx_fill_random(bias, CO, 63, -1, 1);
    uint16_t *w16 = to_f16(w, nw);
    CHECK(w16 != NULL);
    mx_wptr wf = {w16, MX_F16};
    mx_status st;
    mx_ctx plain = {.pool = pool, .k = k, .scratch = scratch}, cached = plain, tiny = plain;
    CHECK(mx_ctx_pack_weights(&cached, (size_t)1 << 30, 0, &st) == 0);
    CHECK(mx_ctx_pack_weights(&tiny, 0, 0, &st) == 0);
    mx_conv2d_up2x(&plain, want, x, B, CI, H, W, wf, mx_w_f32(bias), CO);
    for (int call = 0; call < 2; call++) {
        memset(got, 0xff, ny * sizeof *got);
        mx_conv2d_up2x(&cached, got, x, B, CI, H, W, wf, mx_w_f32(bias), CO);
        CHECK(same_bits(got, want, ny));
        memset(got, 0xff, ny * sizeof *got);
        mx_conv2d_up2x(&tiny, got, x, B, CI, H, W, wf, mx_w_f32(bias), CO);
        CHECK(same_bits(got, want, ny));
    }
    if (k->isa != MX_ISA_SCALAR) CHECK(mx_wpack_bytes(cached.wpack) > 0);
    CHECK(mx_wpack_bytes(tiny.wpack) == 0);
    mx_wpack_destroy(cached.wpack);
    mx_wpack_destroy(tiny.wpack);
    free(x), free(w), free(w16), free(want), free(got);
}

/* A bf16 context and its fp32 view share the cache: one entry per level, each level's own result. */
static void check_two_levels(const mx_kernels *bf16, mx_pool *pool, mx_arena *scratch) {
    enum { M = 9, N = 50, K = 70 };
    float x[M * K], w[N * K], want[2][M * N], got[M * N];
    mx_fill_random(x, M * K, 11, -1, 1);
    mx_fill_random(w, N * K, 12, -1, 1);
    mx_status st;
    mx_ctx plain = {.pool = pool, .k = bf16, .scratch = scratch}, cached = plain;
    CHECK(mx_ctx_pack_weights(&cached, (size_t)1 << 30, 0, &st) == 0);
    mx_ctx plain32 = mx_ctx_fp32(&plain), cached32 = mx_ctx_fp32(&cached);
    mx_linear(&plain, want[0], x, mx_w_f32(w), mx_w_none(), M, N, K);
    mx_linear(&plain32, want[1], x, mx_w_f32(w), mx_w_none(), M, N, K);
    CHECK(!same_bits(want[0], want[1], M * N)); /* else this test could not tell the levels apart */
    for (int round = 0; round < 2; round++) {
        mx_linear(&cached, got, x, mx_w_f32(w), mx_w_none(), M, N, K);
        CHECK(same_bits(got, want[0], M * N));
        mx_linear(&cached32, got, x, mx_w_f32(w), mx_w_none(), M, N, K);
        CHECK(same_bits(got, want[1], M * N));
    }
    mx_wpack_destroy(cached.wpack);
}

/* Entries of cache a that cache b holds too, byte for byte; -1 when one is missing or differs. */
static int same_entries(const mx_wpack *a, const mx_wpack *b) {
    int n = 0;
    for (size_t i = 0; i < mx_wpack_slots(a); i++) {
        mx_wpack_key key;
        size_t bytes, other;
        const float *p = mx_wpack_slot(a, i, &key, &bytes), *q = p ? mx_wpack_find_sized(b, &key, &other) : NULL;
        if (!p) continue;
        if (!q || other != bytes || memcmp(p, q, bytes) != 0) return -1;
        n++;
    }
    return n;
}

/* Weights of many panels, so that every thread of a pool packs some (a few tasks are all done by
 * the calling thread before the others wake). */
static const shapes large[] = {
    {.M = 4, .N = 1500, .K = 1300, .B = 1, .Cin = 256, .H = 6, .W = 6, .Cout = 300, .k = 3, .stride = 1, .pad = 1},
    {.M = 2, .N = 2049, .K = 321, .B = 1, .Cin = 640, .H = 4, .W = 4, .Cout = 1281, .k = 1, .stride = 1, .pad = 0},
};

/* The weights of these shapes packed by one thread and by a pool of three (fill_blocks splits a
 * weight's panels over the threads): the same entries, byte for byte. */
static void check_threads_same_panels(const mx_kernels *k, mx_arena *scratch) {
    mx_status st;
    mx_pool *three = mx_pool_create(3, &st);
    CHECK(three != NULL);
    for (size_t c = 0; c < sizeof large / sizeof large[0]; c++) {
        const shapes *s = &large[c];
        size_t nx = (size_t)s->M * s->K, ncx = (size_t)s->B * s->Cin * s->H * s->W;
        nx = ncx > nx ? ncx : nx;
        size_t nlw = (size_t)s->N * s->K, ncw = (size_t)s->Cout * s->Cin * s->k * s->k;
        float *x = malloc(nx * sizeof *x), *y = malloc(case_outputs(s) * sizeof *y);
        float *lw = malloc(nlw * sizeof *lw), *cw = malloc(ncw * sizeof *cw);
        CHECK(x && y && lw && cw);
        mx_fill_random(x, nx, 30 + c, -1, 1);
        mx_fill_random(lw, nlw, 40 + c, -0.5f, 0.5f);
        mx_fill_random(cw, ncw, 50 + c, -0.5f, 0.5f);
        uint16_t *lw16 = to_f16(lw, nlw), *cw16 = to_f16(cw, ncw);
        CHECK(lw16 && cw16);
        mx_ctx one = {.pool = NULL, .k = k, .scratch = scratch}, many = {.pool = three, .k = k, .scratch = scratch};
        CHECK(mx_ctx_pack_weights(&one, (size_t)1 << 30, 0, &st) == 0);
        CHECK(mx_ctx_pack_weights(&many, (size_t)1 << 30, 0, &st) == 0);
        mx_wptr wl[2] = {mx_w_f32(lw), {lw16, MX_F16}}, wc[2] = {mx_w_f32(cw), {cw16, MX_F16}};
        for (int d = 0; d < 2; d++) {
            run_case(&one, s, y, x, wl[d], mx_w_none(), wc[d], mx_w_none());
            run_case(&many, s, y, x, wl[d], mx_w_none(), wc[d], mx_w_none());
        }
        int n = same_entries(one.wpack, many.wpack);
        if (n < 0 || n != same_entries(many.wpack, one.wpack) || (k->isa != MX_ISA_SCALAR && n < 4)) {
            fprintf(stderr, "%s case %zu: panels packed by 3 threads differ from 1 thread's (%d entries)\n",
                    mx_isa_name(k->isa), c, n);
            mx_test_failures++;
        }
        mx_wpack_destroy(one.wpack);
        mx_wpack_destroy(many.wpack);
        free(lw16), free(cw16), free(x), free(y), free(lw), free(cw);
    }
    mx_pool_destroy(three);
}

/* Word q of row r of a B panel of weight w (row-major [N][K], fp16) for the K block k0..k0+kc, as
 * gemm.h lays it out: the value (fp32 panels) or the bf16 pair of k0+2q and k0+2q+1 (rounded to
 * nearest even; an odd last k paired with zero); zero past the rows and the K block. */
static uint32_t panel_word(const mx_gemm_kernel *g, const uint16_t *w, int N, int K, int n, int k0, int kc, int q) {
    if (n >= N) return 0;
    const uint16_t *row = w + (size_t)n * K + k0;
    if (!g->to_pairs) return q < kc ? mx_f32_bits(mx_half_to_float(row[q])) : 0;
    if (2 * q >= kc) return 0;
    uint32_t lo = mx_float_to_bf16(mx_half_to_float(row[2 * q]));
    return 2 * q + 1 < kc ? lo | (uint32_t)mx_float_to_bf16(mx_half_to_float(row[2 * q + 1])) << 16 : lo;
}

/* A linear's fp16 weight [N][K] (three K blocks, N not a multiple of any NR) as the cache keeps it:
 * K blocks as equal as can be of at most the kernel's, each ceil(N/NR) k-major panels
 * [words][NR], word by word. */
static void check_panel_layout(const mx_kernels *k, mx_pool *pool, mx_arena *scratch) {
    enum { M = 3, N = 70, K = 1301 };
    float *x = malloc(M * K * sizeof *x), *w = malloc(N * K * sizeof *w), y[M * N];
    CHECK(x && w);
    mx_fill_random(x, M * K, 60, -1, 1);
    mx_fill_random(w, N * K, 61, -2, 2);
    uint16_t *w16 = to_f16(w, N * K);
    CHECK(w16 != NULL);
    mx_status st;
    mx_ctx c = {.pool = pool, .k = k, .scratch = scratch};
    CHECK(mx_ctx_pack_weights(&c, (size_t)1 << 30, 0, &st) == 0);
    mx_linear(&c, y, x, (mx_wptr){w16, MX_F16}, mx_w_none(), M, N, K);
    int found = 0, wrong = 0;
    for (size_t i = 0; i < mx_wpack_slots(c.wpack); i++) {
        mx_wpack_key key;
        size_t bytes;
        const uint32_t *p = (const uint32_t *)(const void *)mx_wpack_slot(c.wpack, i, &key, &bytes);
        if (!p || key.data != w16) continue;
        found++;
        const mx_gemm_kernel *g = key.kernel;
        int most = mx_gemm_kc(g), kc_max = (K + (K + most - 1) / most - 1) / ((K + most - 1) / most);
        int nr = g->nr, panels = (N + nr - 1) / nr;
        size_t at = 0;
        for (int k0 = 0; k0 < K; k0 += kc_max) {
            int kc = K - k0 < kc_max ? K - k0 : kc_max;
            size_t words = mx_gemm_panel_words(g, kc);
            for (int pn = 0; pn < panels; pn++)
                for (size_t q = 0; q < words; q++)
                    for (int r = 0; r < nr; r++)
                        wrong += p[at + ((size_t)pn * words + q) * nr + r] !=
                                 panel_word(g, w16, N, K, pn * nr + r, k0, kc, (int)q);
            at += (size_t)panels * mx_gemm_panel_words(g, kc_max) * nr;
        }
        CHECK(bytes == at * sizeof *p); /* every K block takes the room of a whole one */
    }
    if (found != (k->isa != MX_ISA_SCALAR) || wrong) {
        fprintf(stderr, "%s: linear weight panels: %d entries, %d words off the layout\n", mx_isa_name(k->isa), found,
                wrong);
        mx_test_failures++;
    }
    mx_wpack_destroy(c.wpack);
    free(x), free(w), free(w16);
}

/* Whether page i of p..p+pages·page is mapped in this process (/proc/self/pagemap: bit 63, present). */
static int page_mapped(const char *p, size_t page) {
    int fd = open("/proc/self/pagemap", O_RDONLY);
    uint64_t e = 0;
    off_t at = (off_t)((uintptr_t)p / page * sizeof e);
    int ok = fd >= 0 && pread(fd, &e, sizeof e, at) == (ssize_t)sizeof e;
    if (fd >= 0) close(fd);
    return ok && (e >> 63) & 1;
}

/* fp16 weights mapped from a file (sources_mapped): once a linear has packed them, their pages are
 * no longer mapped in the process (its RSS) but still in the page cache (mincore), for the next job;
 * the results are the per-call ones. */
static void check_source_release(const mx_kernels *k, mx_pool *pool, mx_arena *scratch) {
    enum { M = 3, N = 256, K = 512 };
    size_t page = (size_t)sysconf(_SC_PAGESIZE), bytes = (size_t)N * K * sizeof(uint16_t), pages = bytes / page;
    char path[64];
    snprintf(path, sizeof path, "/tmp/matex_test_wpack_%d.bin", (int)getpid());
    float *w = malloc(N * K * sizeof *w), x[M * K], want[M * N], got[M * N];
    CHECK(w != NULL);
    mx_fill_random(w, N * K, 70, -1, 1);
    mx_fill_random(x, M * K, 71, -1, 1);
    uint16_t *w16 = to_f16(w, N * K);
    FILE *f = fopen(path, "wb");
    /* written back (fsync): clean pages, as a weight file's are, which the kernel could evict */
    CHECK(w16 && f && fwrite(w16, 1, bytes, f) == bytes && fflush(f) == 0 && fsync(fileno(f)) == 0);
    CHECK(fclose(f) == 0);
    int fd = open(path, O_RDONLY);
    const char *map = fd >= 0 ? mmap(NULL, bytes, PROT_READ, MAP_PRIVATE, fd, 0) : MAP_FAILED;
    CHECK(map != MAP_FAILED);
    mx_status st;
    mx_ctx plain = {.pool = pool, .k = k, .scratch = scratch}, cached = plain;
    CHECK(mx_ctx_pack_weights(&cached, (size_t)1 << 30, 1, &st) == 0);
    mx_wptr wm = {map, MX_F16};
    mx_linear(&plain, want, x, wm, mx_w_none(), M, N, K);
    mx_linear(&cached, got, x, wm, mx_w_none(), M, N, K);
    CHECK(same_bits(got, want, M * N));
    unsigned char *in_cache = malloc(pages);
    CHECK(in_cache && mincore((void *)map, bytes, in_cache) == 0);
    size_t mapped = 0, cached_pages = 0;
    for (size_t i = 0; i < pages; i++) {
        mapped += page_mapped(map + i * page, page);
        cached_pages += in_cache[i] & 1;
    }
    if (mapped != 0 || cached_pages != pages) {
        fprintf(stderr, "%s: a packed weight's %zu pages: %zu still mapped, %zu in the page cache\n",
                mx_isa_name(k->isa), pages, mapped, cached_pages);
        mx_test_failures++;
    }
    mx_linear(&cached, got, x, wm, mx_w_none(), M, N, K); /* from the panels: the weight is not read */
    CHECK(same_bits(got, want, M * N));
    mx_wpack_destroy(cached.wpack);
    munmap((void *)map, bytes);
    close(fd);
    unlink(path);
    free(in_cache), free(w16), free(w);
}

int main(void) {
    mx_status st;
    mx_pool *pool = mx_pool_create(2, &st);
    mx_arena scratch;
    CHECK(pool != NULL);
    CHECK(mx_arena_create(&scratch, (size_t)16 << 20, &st) == 0);
    int tested = 0;
    for (mx_isa isa = MX_ISA_SCALAR; isa < MX_ISA_COUNT; isa++) {
        const mx_kernels *k = mx_kernels_for(isa);
        if (!mx_kernels_compiled(isa)) continue; /* another architecture's level */
        if (k->isa != isa) {
            printf("%s: NOT TESTED (not a level of this CPU, or lowered by MATEX_ISA)\n", mx_isa_name(isa));
            continue;
        }
        for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) check_case(k, pool, &scratch, &cases[i], 100 + i);
        check_many_and_budget(k, pool, &scratch);
        check_up2x(k, pool, &scratch);
        if (mx_isa_precision(isa) == MX_PREC_BF16) check_two_levels(k, pool, &scratch);
        check_threads_same_panels(k, &scratch);
        check_panel_layout(k, pool, &scratch);
        if (isa != MX_ISA_SCALAR) check_source_release(k, pool, &scratch); /* the scalar level packs nothing */
        printf("%s: packed-once weights give the per-call results\n", mx_isa_name(isa));
        tested++;
    }
    CHECK(tested >= 1);
    mx_arena_destroy(&scratch);
    mx_pool_destroy(pool);
    if (mx_test_failures) fprintf(stderr, "test_ops_wpack: %d failures\n", mx_test_failures);
    return mx_test_failures ? 1 : 0;
}
