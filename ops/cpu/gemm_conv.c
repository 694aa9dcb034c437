/* conv2d as an implicit GEMM on the engine of gemm.c: C[Cout, pixels] = W[Cout, K] · B[K, pixels]
 * with K in the order (ky, kx, ci). The output is computed in blocks of whole output rows; for
 * each block all threads first prepare a band of the input rows it reads, zero-padded on every
 * side and, on the bf16 levels, already converted to channel pairs (one 32-bit word = bf16 of
 * channels 2cp and 2cp+1 at one pixel, an odd last channel paired with zero). A word row of a B
 * panel, one (tap, channel or channel pair) over up to NR consecutive output pixels, is then a
 * straight copy from the band (a strided one for stride > 1): no index arithmetic per element,
 * no edge tests, each input converted to bf16 once instead of once per tap. The weights' A
 * panels gather the same K order: k = (ky·kw + kx)·Cin' + ci, Cin' = Cin rounded up to even on
 * the bf16 levels (the pair of a padding channel is zero in both A and B). */
#include "gemm.h"

#include <stdint.h>
#include <string.h>

/* Output columns per block: within gemm.c's outer block of columns (4096), so one block is one
 * pass of the engine over its B panels. */
#define CONV_COLS_MAX 4096
/* Bound of the band (all batch items): at least one output row's input rows are prepared, so
 * a block is smaller only for images of more than BAND_BYTES_MAX / (kh · channels · 4) columns. */
#define BAND_BYTES_MAX ((size_t)8 << 20)
/* Band channels (all their rows) per task of the band's preparation. */
#define BAND_TASK_CHANS 16

static int min_int(int a, int b) { return a < b ? a : b; }
static int max_int(int a, int b) { return a > b ? a : b; }

/* 32-bit words per band pixel: channels (fp32) or channel pairs (bf16 levels). */
static int band_chans(const mx_gemm_kernel *g, int Cin) { return g->to_pairs ? (Cin + 1) / 2 : Cin; }
static int k_per_word(const mx_gemm_kernel *g) { return g->to_pairs ? 2 : 1; }

/* Where word row q of B (k = q·k_per_word) is: channel group, tap, word in the group. The K
 * order is (group, ky, kx, ci in the group) on pair levels (a pair is two channels at one tap),
 * (group, ci, ky, kx) on fp32 ones (problem.taps_inner: the weights' own order, so packing A
 * needs no transpose of the taps): a K block of the engine is one whole group, so the weights
 * it needs, channels of the group × all taps, are one contiguous run of each weight row. */
typedef struct {
    int group, tap, word, group_words; /* group_words: words per pixel in this group */
} k_pos;

static k_pos k_pos_of(const mx_gemm_problem *p, int q) {
    int gw = p->group_words, taps = p->kh * p->kw, grp = q / (gw * taps), first = grp * gw;
    /* at least 1: the position past the last row, which k_pos_next may reach, is never read */
    int words = max_int(1, min_int(gw, p->chans - first)), r = q - first * taps;
    if (p->taps_inner) return (k_pos){.group = grp, .tap = r % taps, .word = r / taps, .group_words = words};
    return (k_pos){.group = grp, .tap = r / words, .word = r % words, .group_words = words};
}

/* The next word row. */
static void k_pos_next(const mx_gemm_problem *p, k_pos *at) {
    int taps = p->kh * p->kw;
    if (p->taps_inner) {
        if (++at->tap < taps) return;
        at->tap = 0;
        if (++at->word < at->group_words) return;
    } else {
        if (++at->word < at->group_words) return;
        at->word = 0;
        if (++at->tap < taps) return;
    }
    *at = k_pos_of(p, (at->group + 1) * p->group_words * taps);
}

/* ---- A: the weights [Cout][Cin][kh][kw] in the K order of k_pos ---- */

/* The 2×2 kernels of phase (a, b) = (phase >> 1, phase & 1) of conv2d_up2x, folded from 3×3 ones:
 * output pixel (2i+a, 2j+b) of the 3×3 conv on the upsampled image reads upsampled rows 2i+a-1 ..
 * 2i+a+1, i.e. input rows i-1+a (tap ty 0: ky 0 .. a) and i+a (ty 1: ky a+1 .. 2), which the 2×2
 * conv with padding 1 reads at its output row i+a (columns alike). out[ci·cs + (ty·2 + tx)·ts]
 * from w[ci·9 + ky·3 + kx] for ci < real, written out per phase (this runs per call where fp32
 * panels are not kept: a loop over the tap ranges took ~4 % of an fp32 UNet call), each sum ky-major. */
static void fold_phase(float *out, size_t cs, size_t ts, const float *w, int real, int phase) {
    for (int ci = 0; ci < real; ci++, w += 9, out += cs) {
        float *o0 = out, *o1 = out + ts, *o2 = out + 2 * ts, *o3 = out + 3 * ts;
        switch (phase) {
        case 0: /* ky {0}, {1,2}; kx {0}, {1,2} */
            *o0 = w[0], *o1 = w[1] + w[2], *o2 = w[3] + w[6], *o3 = w[4] + w[5] + w[7] + w[8];
            break;
        case 1: /* ky {0}, {1,2}; kx {0,1}, {2} */
            *o0 = w[0] + w[1], *o1 = w[2], *o2 = w[3] + w[4] + w[6] + w[7], *o3 = w[5] + w[8];
            break;
        case 2: /* ky {0,1}, {2}; kx {0}, {1,2} */
            *o0 = w[0] + w[3], *o1 = w[1] + w[2] + w[4] + w[5], *o2 = w[6], *o3 = w[7] + w[8];
            break;
        default: /* ky {0,1}, {2}; kx {0,1}, {2} */
            *o0 = w[0] + w[1] + w[3] + w[4], *o1 = w[2] + w[5], *o2 = w[6] + w[7], *o3 = w[8];
        }
    }
}

/* Row m's 3×3 weights of input channels c0 .. c0+real (a_phases): in place (fp32) or widened into buf9. */
static const float *weights_3x3(const mx_gemm_problem *p, const mx_gemm_kernel *g, float *buf9, int m, int c0,
                                int real) {
    size_t at = ((size_t)(m % (p->M / p->a_phases)) * p->Cin + (size_t)c0) * 9;
    if (p->a_mat.dtype == MX_F32) return (const float *)p->a_mat.data + at;
    g->widen(buf9, p->a_mat, at, (size_t)real * 9);
    return buf9;
}

/* Row m's weights of input channels c0 .. c0+real, [real][taps] in fp32: in place (fp32 weights) or
 * widened into buf; NULL where they do not fit buf (read per element then). */
static const float *weight_run(const mx_gemm_problem *p, const mx_gemm_kernel *g, float *buf, int m, int c0,
                               int real) {
    int taps = p->kh * p->kw;
    size_t at = ((size_t)m * p->Cin + (size_t)c0) * taps;
    if (p->a_mat.dtype == MX_F32) return (const float *)p->a_mat.data + at;
    if ((size_t)real * taps > MX_GEMM_KC_MAX) return NULL; /* a group of one word longer than buf (kernels > 17×17) */
    g->widen(buf, p->a_mat, at, (size_t)real * taps);
    return buf;
}

/* A group's weights in the K order, o = [size][taps] (taps_inner) or [taps][size]: the channels
 * real .. size (past Cin) zero. */
static void zero_group_tail(const mx_gemm_problem *p, float *o, int taps, int real, int size) {
    if (real >= size) return;
    if (p->taps_inner) {
        memset(o + (size_t)real * taps, 0, (size_t)(size - real) * taps * sizeof *o);
        return;
    }
    for (int t = 0; t < taps; t++) memset(o + (size_t)t * size + real, 0, (size_t)(size - real) * sizeof *o);
}

/* out[0 .. kc) = row m of A for k0 .. k0+kc (a channel past Cin, the pair of an odd Cin: 0). */
static void weight_row(const mx_gemm_problem *p, const mx_gemm_kernel *g, float *out, int m, int k0, int kc) {
    /* buf9: the 3×3 weights of a phase-folded group (≤ MX_GEMM_KC_MAX / 4 channels of 2×2 taps) */
    float buf[MX_GEMM_KC_MAX], buf9[MX_GEMM_KC_MAX / 4 * 9];
    int taps = p->kh * p->kw, k = k0, group = p->group_words * k_per_word(g), span = group * taps;
    while (k < k0 + kc) {
        int grp = k / span, c0 = grp * group, size = min_int(group, p->chans * k_per_word(g) - c0);
        int real = max_int(0, min_int(size, p->Cin - c0)), r = k - grp * span, r1 = min_int(size * taps, r + k0 + kc - k);
        /* the group's channels × taps: one run of the weight row, widened once */
        size_t at = ((size_t)m * p->Cin + (size_t)c0) * taps;
        float *o = out + (k - k0);
        /* phase kernels: a K block is always one whole group (conv2d sets kc_block to a group's
         * span, which fits a block for 2×2 taps), folded straight into the K order */
        if (p->a_phases) {
            size_t cs = p->taps_inner ? (size_t)taps : 1, ts = p->taps_inner ? 1 : (size_t)size;
            fold_phase(o, cs, ts, weights_3x3(p, g, buf9, m, c0, real), real, m / (p->M / p->a_phases));
            zero_group_tail(p, o, taps, real, size);
            k += r1;
            continue;
        }
        int whole = r == 0 && r1 == size * taps;
        if (whole && p->taps_inner) { /* the run is the K order already */
            if (p->a_mat.dtype == MX_F32)
                memcpy(o, (const float *)p->a_mat.data + at, (size_t)real * taps * sizeof *o);
            else
                g->widen(o, p->a_mat, at, (size_t)real * taps);
            zero_group_tail(p, o, taps, real, size);
            k += r1;
            continue;
        }
        const float *w = weight_run(p, g, buf, m, c0, real);
        if (w && whole) { /* [real][taps] to [taps][size] */
            if (taps == 1) /* 1×1: the run is the row already */
                memcpy(o, w, (size_t)real * sizeof *o);
            else
                g->transpose(o, (size_t)size, w, (size_t)taps, real, taps);
            zero_group_tail(p, o, taps, real, size);
            k += r1;
            continue;
        }
        for (; r < r1; r++, k++) {
            int ci = p->taps_inner ? r / taps : r % size, t = p->taps_inner ? r % taps : r / size;
            size_t i = (size_t)ci * taps + (size_t)t;
            out[k - k0] = ci >= real ? 0.0f : w ? w[i] : mx_w_get(p->a_mat, at + i);
        }
    }
}

/* The A packer of conv, of the weights' low parts with lo (bf16 kernels). */
static void pack_a_conv(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dstv, int first, int rows, int k0,
                        int kc, int lo) {
    enum { KC = MX_GEMM_KC_MAX };
    float tmp[MX_GEMM_WIDEN_ROWS * KC];
    uint32_t words_tmp[MX_GEMM_WIDEN_ROWS * KC / 2];
    int valid = min_int(rows, p->M - first), kp = (kc + 1) / 2;
    size_t words = mx_gemm_panel_words(g, kc);
    uint32_t *dst = dstv;
    /* the weights of the K block's first group: one run of each row, fetched a row group ahead
     * (into the next panel's rows at the end) */
    int taps = p->kh * p->kw, group = p->group_words * k_per_word(g), c0 = k0 / (group * taps) * group;
    int run = max_int(0, min_int(group, p->Cin - c0)) * taps;
    for (int r0 = 0; r0 < valid; r0 += MX_GEMM_WIDEN_ROWS) {
        int n = min_int(MX_GEMM_WIDEN_ROWS, valid - r0);
        if (!p->a_phases) /* phase rows read the weight rows of their own 3×3 layout */
            mx_gemm_prefetch_rows(p->a_mat, (size_t)p->Cin * taps, first + r0 + n,
                                  min_int(MX_GEMM_WIDEN_ROWS, p->M - first - r0 - n), c0 * taps, run);
        for (int i = 0; i < n; i++) weight_row(p, g, tmp + (size_t)i * KC, first + r0 + i, k0, kc);
        if (!g->to_pairs) {
            g->transpose((float *)dstv + r0, (size_t)rows, tmp, KC, n, kc);
            continue;
        }
        for (int i = 0; i < n; i++) {
            uint32_t *d = g->a_rows ? dst + (size_t)(r0 + i) * words : words_tmp + (size_t)i * (KC / 2);
            (lo ? g->row_pairs_lo : g->row_pairs)(d, tmp + (size_t)i * KC, kc);
            if (g->a_rows) memset(d + kp, 0, (words - (size_t)kp) * sizeof *d);
        }
        /* a bit-exact copy: the transpose only shuffles 32-bit lanes */
        if (!g->a_rows)
            g->transpose((float *)dstv + r0, (size_t)rows, (const float *)(const void *)words_tmp, KC / 2, n, kp);
    }
    if (g->a_rows) {
        memset(dst + (size_t)valid * words, 0, (size_t)(rows - valid) * words * sizeof *dst);
        return;
    }
    mx_gemm_zero_panel_tail(g, dst, rows, valid, kc);
}

void mx_gemm_pack_a_conv(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows, int k0,
                         int kc) {
    pack_a_conv(p, g, dst, first, rows, k0, kc, 0);
}

void mx_gemm_pack_a_conv_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                            int k0, int kc) {
    pack_a_conv(p, g, dst, first, rows, k0, kc, 1);
}

/* dst[c] = the pair (even[c], odd[c]) for c < n (odd NULL: zeros), of their low parts with lo. */
static void to_pairs_part(const mx_gemm_kernel *g, uint32_t *dst, const float *even, const float *odd, int n, int lo) {
    (lo ? g->to_pairs_lo : g->to_pairs)(dst, even, odd, n);
}

/* ---- B: panels copied from the band ---- */

/* Panel columns j .. j+len, consecutive output pixels of one output row, whose inputs for the
 * tap (0, 0) start at word `off` of a band plane (the other taps: off + ky·width + kx). */
typedef struct {
    int j, len;
    size_t off;
} pixel_run;

/* The runs of panel columns first .. first+cols that are pixels (< N); *valid: their count. */
static int panel_runs(const mx_gemm_problem *p, pixel_run *runs, int first, int cols, int *valid) {
    int n = 0, j = 0, end = max_int(0, min_int(cols, p->N - first));
    while (j < end) {
        int pix = first + j, oy = pix / p->Wo, ox = pix % p->Wo, len = min_int(end - j, p->Wo - ox);
        runs[n++] = (pixel_run){.j = j, .len = len,
                                .off = ((size_t)oy * p->band_width + (size_t)ox) * (size_t)p->stride};
        j += len;
    }
    *valid = end;
    return n;
}

/* d[i] = s[i · stride] for i < len, as 32-bit words (fp32 or pairs: copied, never converted). */
static void copy_run(uint32_t *d, const uint32_t *s, int len, int stride) {
    if (stride != 1)
        for (int i = 0; i < len; i++) memcpy(d + i, s + (size_t)i * stride, sizeof *d);
    else if (len == MX_GEMM_PANEL_MAX) /* the whole AVX-512 panel: a fixed-size copy, inlined */
        memcpy(d, s, MX_GEMM_PANEL_MAX * sizeof *d);
    else
        memcpy(d, s, (size_t)len * sizeof *d);
}

/* Word row of channel pair cp, straight from the fp32 input (band_fp32): each value of a 1×1
 * conv is converted once either way, so a band of pairs would only add a copy. */
static void pair_row_from_input(const mx_gemm_problem *p, const mx_gemm_kernel *g, uint32_t *d, int cp,
                                const pixel_run *runs, int nruns, int lo) {
    const float *even = p->image + (size_t)2 * cp * p->band_plane;
    const float *odd = 2 * cp + 1 < p->Cin ? even + p->band_plane : NULL;
    for (int r = 0; r < nruns; r++)
        to_pairs_part(g, d + runs[r].j, even + runs[r].off, odd ? odd + runs[r].off : NULL, runs[r].len, lo);
}

/* The B packer of conv; lo: the inputs' low parts, converted here (band_fp32) or copied from
 * the band of them (problem.image_lo). */
static void pack_b_conv(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dstv, int first, int cols, int k0,
                        int kc, int lo) {
    pixel_run runs[MX_GEMM_PANEL_MAX]; /* cols <= the kernel's NR */
    int valid, nruns = panel_runs(p, runs, first, cols, &valid);
    int nq = (kc + k_per_word(g) - 1) / k_per_word(g);
    k_pos at = k_pos_of(p, k0 / k_per_word(g));
    const uint32_t *band = (const uint32_t *)(const void *)(lo && p->image_lo ? p->image_lo : p->image);
    size_t plane = p->band_plane;
    uint32_t *dst = dstv;
    for (int q = 0; q < nq; q++, k_pos_next(p, &at)) {
        int cp = at.group * p->group_words + at.word, ky = at.tap / p->kw, kx = at.tap % p->kw;
        const uint32_t *src = band + (size_t)cp * plane + (size_t)ky * p->band_width + (size_t)kx;
        uint32_t *d = dst + (size_t)q * cols;
        if (p->band_fp32) {
            pair_row_from_input(p, g, d, cp, runs, nruns, lo);
            continue;
        }
        for (int r = 0; r < nruns; r++) copy_run(d + runs[r].j, src + runs[r].off, runs[r].len, p->stride);
    }
    mx_gemm_zero_panel_tail(g, dst, cols, valid, kc);
}

void mx_gemm_pack_b_conv(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int cols, int k0,
                         int kc) {
    pack_b_conv(p, g, dst, first, cols, k0, kc, 0);
}

void mx_gemm_pack_b_conv_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int cols,
                            int k0, int kc) {
    pack_b_conv(p, g, dst, first, cols, k0, kc, 1);
}

/* ---- B read in place (the kernel's micro_rows): a panel of one output row needs no copy ---- */

/* problem.rows_in_place (gemm.h): stride 1, not on a band of fp32 inputs paired per panel. */
static int band_rows_in_place(const mx_gemm_problem *p, const mx_gemm_kernel *g, int k0, int kc, int32_t *offs) {
    if (!g->micro_rows || p->stride != 1 || p->band_fp32 || p->band_plane * (size_t)p->chans > INT32_MAX) return 0;
    int nq = (kc + k_per_word(g) - 1) / k_per_word(g);
    k_pos at = k_pos_of(p, k0 / k_per_word(g));
    for (int q = 0; q < nq; q++, k_pos_next(p, &at)) {
        int cp = at.group * p->group_words + at.word, ky = at.tap / p->kw, kx = at.tap % p->kw;
        offs[q] = (int32_t)((size_t)cp * p->band_plane + (size_t)ky * p->band_width + (size_t)kx);
    }
    for (int q = nq; q < nq + MX_GEMM_ROWS_AHEAD; q++) offs[q] = offs[nq - 1];
    return 1;
}

/* problem.panel_in_place (gemm.h): each half of the panel within one output row. */
static int band_panel_in_place(const mx_gemm_problem *p, const mx_gemm_kernel *g, int first, const uint32_t *half[2]) {
    int w = g->nr / 2;
    if (first + g->nr > p->N) return 0;
    for (int h = 0; h < 2; h++) { /* e.g. a 16-wide image: a panel is two rows */
        int pix = first + h * w, ox = pix % p->Wo;
        if (ox + w > p->Wo) return 0;
        half[h] = (const uint32_t *)(const void *)p->image + (size_t)(pix / p->Wo) * p->band_width + (size_t)ox;
    }
    return 1;
}

/* ---- the band: input rows of a block of output rows, padded, in the kernel's words ---- */

typedef struct {
    const mx_gemm_kernel *g;
    const float *x; /* the input [B][Cin][H][W] */
    uint32_t *band; /* [B][chans][rows][width]; NULL: the input is the band (problem.band_fp32 on pairs) */
    int B, Cin, H, W, pad, chans, rows, width;
    int iy0;      /* input row of band row 0 (negative in the top padding) */
    int lo;       /* bf16 levels: the band of the inputs' low parts (a split kernel's) */
    double *secs; /* with a profile: each thread's CPU seconds */
} band_job;

/* The rows of band channel cp of batch item b. */
static void prepare_band_channel(const band_job *j, int b, int cp) {
    int pairs = j->g->to_pairs != NULL, ci = pairs ? 2 * cp : cp;
    size_t plane = (size_t)j->H * j->W;
    const float *chan = j->x + ((size_t)b * j->Cin + (size_t)ci) * plane;
    uint32_t *d = j->band + ((size_t)b * j->chans + (size_t)cp) * j->rows * j->width;
    for (int r = 0; r < j->rows; r++, d += j->width) {
        int iy = j->iy0 + r;
        if (iy < 0 || iy >= j->H) {
            memset(d, 0, (size_t)j->width * sizeof *d);
            continue;
        }
        const float *row = chan + (size_t)iy * j->W;
        memset(d, 0, (size_t)j->pad * sizeof *d);
        if (pairs)
            to_pairs_part(j->g, d + j->pad, row, ci + 1 < j->Cin ? row + plane : NULL, j->W, j->lo);
        else
            memcpy(d + j->pad, row, (size_t)j->W * sizeof *d);
        memset(d + j->pad + j->W, 0, (size_t)(j->width - j->pad - j->W) * sizeof *d);
    }
}

/* Task t: band channels t·BAND_TASK_CHANS... of all batch items in a row (few tasks: a profile
 * reads the thread clock per task, a system call on some VMs). */
static void prepare_band_task(void *arg, int task, int thread) {
    const band_job *j = arg;
    double t0 = j->secs ? mx_profile_clock(CLOCK_THREAD_CPUTIME_ID) : 0;
    int n = j->B * j->chans;
    for (int i = task * BAND_TASK_CHANS; i < n && i < (task + 1) * BAND_TASK_CHANS; i++)
        prepare_band_channel(j, i / j->chans, i % j->chans);
    if (j->secs) j->secs[thread] += mx_profile_clock(CLOCK_THREAD_CPUTIME_ID) - t0;
}

/* Channel words per K group: all of them when K fits one K block of the kernel (kc), else groups
 * as equal as can be of at most kc k values (e.g. 3×3, Cin 320, bf16: 5 groups of 32
 * pairs, K blocks of 576); groups of one word where even that is longer (then split over K
 * blocks). Groups of half that (B panels of 160 words, 20 KiB, that stay in L1 beside A) were
 * measured no faster on Zen 5. */
static int channel_group_words(int chans, int k_word, int taps, int kc) {
    int most = kc / (taps * k_word);
    if (most < 1 || chans < 1) return 1;
    int groups = (chans + most - 1) / most;
    return (chans + groups - 1) / groups;
}

/* Output rows per block: whole rows up to CONV_COLS_MAX columns, fewer where the band (all batch
 * items) would pass BAND_BYTES_MAX; at least one. */
static int rows_per_block(int B, int chans, int width, int kh, int stride, int Ho, int Wo) {
    int rows = min_int(Ho, max_int(1, CONV_COLS_MAX / Wo));
    size_t row_bytes = (size_t)B * chans * width * sizeof(uint32_t);
    size_t in_rows = row_bytes ? BAND_BYTES_MAX / row_bytes : (size_t)kh + (size_t)rows * stride;
    if ((size_t)(rows - 1) * stride + kh > in_rows) rows = in_rows < (size_t)kh ? 1 : (int)((in_rows - kh) / stride) + 1;
    return max_int(1, rows);
}

/* Prepares the band of output rows oy0 .. oy0+rows and points p at it. */
static void prepare_band(const mx_ctx *c, band_job *j, mx_gemm_problem *p, int oy0, int rows, int B) {
    int nthreads = mx_par_threads(c);
    p->N = rows * p->Wo;
    j->iy0 = oy0 * p->stride - j->pad;
    if (!j->band) {
        p->image = j->x + (size_t)j->iy0 * j->W;
        p->image_batch_stride = (size_t)j->Cin * j->H * j->W;
        p->band_plane = (size_t)j->H * j->W;
        return;
    }
    j->rows = (rows - 1) * p->stride + p->kh;
    for (int t = 0; t < nthreads && j->secs; t++) j->secs[t] = 0;
    mx_par_for(c, (B * j->chans + BAND_TASK_CHANS - 1) / BAND_TASK_CHANS, prepare_band_task, j);
    for (int t = 0; t < nthreads && j->secs; t++) c->prof->gemm_secs[MX_GEMM_CONV][MX_GEMM_PACK_B] += j->secs[t];
    p->image = (const float *)(const void *)j->band;
    p->image_batch_stride = (size_t)j->chans * j->rows * j->width;
    p->band_plane = (size_t)j->rows * j->width;
}

/* A split product (x3) in one pass of the split kernel: both parts of each operand packed into
 * its panels (the inputs' low parts from problem.image_lo where the input is a band). */
static void use_split_kernel(mx_gemm_problem *p) {
    p->split_a[0] = mx_gemm_pack_a_conv, p->split_a[1] = mx_gemm_pack_a_conv_lo;
    p->split_b[0] = mx_gemm_pack_b_conv, p->split_b[1] = mx_gemm_pack_b_conv_lo;
    p->pack_a = mx_gemm_pack_a_split;
    p->pack_b = mx_gemm_pack_b_split;
}

/* The band of the inputs' low parts beside p's (a split kernel's), at lo_band. */
static void prepare_lo_band(const mx_ctx *c, const band_job *j, uint32_t *lo_band, mx_gemm_problem *p, int oy0,
                            int rows, int B) {
    band_job jl = *j;
    jl.band = lo_band;
    jl.lo = 1;
    mx_gemm_problem t = *p;
    prepare_band(c, &jl, &t, oy0, rows, B);
    p->image_lo = t.image;
}

/* conv2d_up2x's output of a block of rows of the phase conv: its phase planes z ([B][4·Cout][rows][W+1],
 * the block's C) interleaved into y ([B][Cout][2H][2W]) with the bias. Row r of the phase conv holds
 * output row 2r of phases (0, b) and row 2r-1 of phases (1, b); column s holds output column 2s of
 * phases (a, 0) and 2s-1 of phases (a, 1). */
typedef struct {
    float *y;
    const float *z, *bias; /* bias: Cout widened values, or NULL */
    int Cout, H, W, oy0, rows;
} phase_block;

static void interleave_plane(void *arg, int task, int thread) {
    (void)thread;
    const phase_block *q = arg;
    int b = task / q->Cout, co = task % q->Cout, Wo = q->W + 1;
    float bias = q->bias ? q->bias[co] : 0.0f;
    size_t plane = (size_t)q->rows * Wo;
    const float *z = q->z + (size_t)b * 4 * q->Cout * plane;
    float *y = q->y + ((size_t)b * q->Cout + co) * 4 * q->H * q->W;
    for (int r = q->oy0; r < q->oy0 + q->rows; r++)
        for (int a = 0; a < 2; a++) {
            int i = r - a; /* output row 2i + a */
            if (i < 0 || i >= q->H) continue;
            const float *z0 = z + ((size_t)(2 * a) * q->Cout + co) * plane + (size_t)(r - q->oy0) * Wo;
            const float *z1 = z0 + (size_t)q->Cout * plane + 1; /* phase (a, 1), from column 1 */
            float *yr = y + (size_t)(2 * i + a) * 2 * q->W;
            for (int j = 0; j < q->W; j++) {
                yr[2 * j] = z0[j] + bias;
                yr[2 * j + 1] = z1[j] + bias;
            }
        }
}

/* Bound of conv2d_up2x's phase planes of a block (all batch items), in scratch. */
#define PHASE_BYTES_MAX ((size_t)16 << 20)

/* conv2d as one product of g; with a split kernel (g->split_of), the split product (gemm.h). With
 * up (conv2d_up2x: kh = kw = 2, pad 1, Cout = 4 × y's channels) each block of output rows is
 * computed into scratch and interleaved into y by interleave_plane. */
static void conv2d(const mx_ctx *c, const mx_gemm_kernel *g, float *y, const float *x, int B, int Cin, int H, int W,
                   mx_wptr w, mx_wptr bias, int Cout, int kh, int kw, int stride, int pad, int up) {
    int Ho = (H + 2 * pad - kh) / stride + 1, Wo = (W + 2 * pad - kw) / stride + 1;
    if (B <= 0 || Cout <= 0 || Ho <= 0 || Wo <= 0 || H + 2 * pad < kh || W + 2 * pad < kw) return;
    int chans = band_chans(g, Cin), width = W + 2 * pad, taps = kh * kw, group = channel_group_words(chans, k_per_word(g), taps, mx_gemm_kc(g));
    int span = group * k_per_word(g) * taps; /* K blocks of whole groups, where a group fits one */
    /* no padding: the input rows are already a band (fp32; on pairs a 1×1 stride-1 conv) */
    int direct = pad == 0 && (!g->to_pairs || (taps == 1 && stride == 1)), split = g->split_of != NULL;
    /* image: prepare_band points it at each band; set before for the profile's conv parts */
    mx_gemm_problem p = {.M = Cout, .K = taps * chans * k_per_word(g), .batch = B, .ldc = (size_t)Ho * Wo, .image = x,
                         .c_batch_stride = (size_t)Cout * Ho * Wo, .pack_a = mx_gemm_pack_a_conv,
                         .pack_b = mx_gemm_pack_b_conv, .a_mat = w, .a_ld = (size_t)Cin * (up ? 9 : taps), .a_weight = 1,
                         .bias = up ? mx_w_none() : bias, .bias_per_row = 1, .Cin = Cin,
                         .chans = chans, .group_words = group, .kh = kh, .kw = kw, .stride = stride, .Wo = Wo,
                         .band_width = width, .band_fp32 = direct && g->to_pairs, .a_phases = up ? 4 : 0,
                         .taps_inner = !g->to_pairs,
                         .rows_in_place = band_rows_in_place, .panel_in_place = band_panel_in_place,
                         .kc_block = span <= mx_gemm_kc(g) ? span : mx_gemm_kc(g)};
    if (split) {
        use_split_kernel(&p);
        /* the weights are packed per call, as the fp32 ones were: panels of both parts would add
         * the weight's size again to the cache */
        p.a_weight = 0;
    }
    int rows = rows_per_block(B, chans, width, kh, stride, Ho, Wo), nthreads = mx_par_threads(c);
    if (up) rows = min_int(rows, max_int(1, (int)(PHASE_BYTES_MAX / ((size_t)B * Cout * Wo * sizeof(float)))));
    size_t band_words = direct ? 0 : (size_t)B * chans * ((size_t)(rows - 1) * stride + kh) * width;
    /* up: the phase planes of a block, then the widened bias */
    size_t phase_floats = up ? (size_t)B * Cout * rows * Wo + (size_t)Cout / 4 : 0;
    size_t nsecs = c && c->prof ? (size_t)nthreads : 0, a_floats = 0;
    /* several blocks of output rows run one problem each: A (the weights) packed once for all
     * of them, unless the context's cache holds it (else every block repacked it: 64 times
     * for a 512×512 VAE conv) */
    size_t per_a = rows < Ho ? mx_gemm_a_panels_floats(g, &p) : 0;
    const float *cached_a = per_a ? mx_gemm_cached_a_panels(c, g, &p) : NULL; /* NULL when split */
    a_floats = cached_a ? 0 : per_a;
    a_floats += (a_floats + phase_floats) & 1; /* the doubles after them stay 8-byte aligned */
    mx_scratch s;
    size_t bands = split ? 2 : 1; /* a split kernel's: the high and the low parts' */
    float *mem = mx_scratch_take(c,
                                 (a_floats + phase_floats) * sizeof(float) + nsecs * sizeof(double) +
                                     bands * band_words * sizeof(uint32_t) + 1,
                                 &s);
    int failed = !mem;
    double *secs = mem ? (double *)(void *)(mem + a_floats + phase_floats) : NULL;
    band_job j = {.g = g, .x = x, .B = B, .band = direct || !mem ? NULL : (uint32_t *)(void *)(secs + nsecs), .Cin = Cin,
                  .H = H, .W = W, .pad = pad, .chans = chans, .width = width, .secs = nsecs ? secs : NULL};
    p.a_panels = per_a && !cached_a && mem ? mx_gemm_pack_a_panels(c, g, &p, mem) : cached_a;
    phase_block q = {.y = y, .z = mem ? mem + a_floats : NULL, .Cout = Cout / 4, .H = H, .W = W};
    if (up && mem && bias.data) {
        float *b = mem + a_floats + phase_floats - Cout / 4;
        for (int i = 0; i < Cout / 4; i++) b[i] = mx_w_get(bias, (size_t)i);
        q.bias = b;
    }
    for (int oy0 = 0; oy0 < Ho && !failed; oy0 += rows) {
        int n = min_int(rows, Ho - oy0);
        prepare_band(c, &j, &p, oy0, n, B);
        if (split && j.band) prepare_lo_band(c, &j, j.band + band_words, &p, oy0, n, B);
        p.C = up ? mem + a_floats : y + (size_t)oy0 * Wo;
        if (up) p.ldc = (size_t)n * Wo, p.c_batch_stride = (size_t)Cout * n * Wo;
        failed = mx_gemm_run(c, g, &p) != 0;
        if (up && !failed) {
            q.oy0 = oy0, q.rows = n;
            mx_par_for(c, B * q.Cout, interleave_plane, &q);
        }
    }
    if (mem) mx_scratch_release(c, &s);
    if (failed && up)
        mx_conv2d_up2x_ref(c, y, x, B, Cin, H, W, w, bias, Cout / 4);
    else if (failed)
        mx_conv2d_ref(c, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad);
}

void mx_gemm_conv2d(const mx_ctx *c, const mx_gemm_kernel *g, float *y, const float *x, int B, int Cin, int H,
                    int W, mx_wptr w, mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    conv2d(c, g, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad, 0);
}

void mx_gemm_conv2d_up2x(const mx_ctx *c, const mx_gemm_kernel *g, float *y, const float *x, int B, int Cin, int H,
                         int W, mx_wptr w, mx_wptr bias, int Cout) {
    conv2d(c, g, y, x, B, Cin, H, W, w, bias, 4 * Cout, 2, 2, 1, 1, 1);
}
