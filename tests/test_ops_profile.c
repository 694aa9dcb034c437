/* The profile (ops/profile.h): a context with one counts each op's calls and time (CPU and wall,
 * in the op's own slot, none in the others'), and the GEMM engine's FLOPs and part times (linear
 * and conv2d told apart, K split into several blocks; the parts within the op's time); a second
 * run adds to the sums; the results are bit-identical with and without it; a context without one
 * records nothing; the op names are the list's; each call's cost (op_list.h: FLOPs, bytes) and
 * roofline floor. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/ops.h"
#include "util_test.h"

enum { M = 50, N = 70, K = 1500 }; /* K: more than one K block of the GEMM */
enum { CB = 2, CIN = 20, H = 9, W = 11, COUT = 13 };

typedef struct {
    float x[M * K], w[N * K], y[M * N];
    float img[CB * CIN * H * W], cw[COUT * CIN * 9], cy[CB * COUT * H * W];
} problem;

static void run_ops(const mx_ctx *c, problem *p) {
    mx_linear(c, p->y, p->x, mx_w_f32(p->w), mx_w_none(), M, N, K);
    mx_conv2d(c, p->cy, p->img, CB, CIN, H, W, mx_w_f32(p->cw), mx_w_none(), COUT, 3, 3, 1, 1);
    mx_silu(c, p->y, (size_t)M * N);
}

/* The GEMM engine's record of one user (linear or conv2d) whose op took op_secs of process CPU
 * time: on the SIMD levels every part took time, and the parts (thread CPU time inside the op)
 * add up to no more than the op's own; the scalar reference records nothing. */
static void check_gemm_user(const mx_profile *pr, int user, double flops, int engine, double op_secs) {
    double parts = 0;
    for (int q = 0; q < MX_GEMM_PARTS; q++) {
        if (engine) CHECK(pr->gemm_secs[user][q] > 0);
        parts += pr->gemm_secs[user][q];
    }
    if (engine) { /* the SIMD levels run the GEMM engine */
        CHECK(pr->gemm_flops[user] == flops);
        if (parts > op_secs) printf("FAIL: GEMM parts %.3e s > the op's %.3e s\n", parts, op_secs);
        CHECK(parts <= op_secs);
    } else { /* the scalar reference does not */
        CHECK(pr->gemm_flops[user] == 0 && parts == 0);
    }
}

/* The ops run_ops calls (linear, conv2d, silu once each) took time, CPU and wall, and every
 * other op's slots are untouched. */
static void check_op_slots(const mx_profile *pr, long calls) {
    for (int op = 0; op < MX_OP_COUNT; op++) {
        int called = op == MX_OP_ID_linear || op == MX_OP_ID_conv2d || op == MX_OP_ID_silu;
        if (called) {
            CHECK(pr->op_calls[op] == calls && pr->op_secs[op] > 0 && pr->op_wall[op] > 0);
        } else {
            if (pr->op_calls[op] || pr->op_secs[op] != 0 || pr->op_wall[op] != 0)
                printf("FAIL: op %s was not called but has a profile\n", mx_op_name(op));
            CHECK(pr->op_calls[op] == 0 && pr->op_secs[op] == 0 && pr->op_wall[op] == 0 && pr->op_flops[op] == 0);
        }
    }
}

/* A second run into the same profile adds to it: counts and FLOPs double, times grow. */
static void check_accumulates(const mx_ctx *c, problem *p, mx_profile *pr) {
    mx_profile first = *pr;
    run_ops(c, p);
    check_op_slots(pr, 2);
    for (int op = 0; op < MX_OP_COUNT; op++) {
        CHECK(pr->op_flops[op] == 2 * first.op_flops[op]);
        if (first.op_calls[op]) CHECK(pr->op_secs[op] > first.op_secs[op] && pr->op_wall[op] > first.op_wall[op]);
    }
    for (int user = 0; user < MX_GEMM_USERS; user++) {
        CHECK(pr->gemm_flops[user] == 2 * first.gemm_flops[user]);
        for (int q = 0; q < MX_GEMM_PARTS; q++)
            if (first.gemm_secs[user][q] > 0) CHECK(pr->gemm_secs[user][q] > first.gemm_secs[user][q]);
    }
}

static void test_level(mx_isa isa) {
    mx_status st = {0};
    mx_ctx c;
    if (mx_ctx_create(&c, 2, isa, (size_t)16 << 20, &st)) {
        printf("FAIL: context: %s\n", st.msg);
        CHECK(0);
        return;
    }
    problem *a = calloc(1, sizeof *a), *b = calloc(1, sizeof *b);
    CHECK(a && b);
    if (!a || !b) goto done;
    mx_fill_random(a->x, M * K, 1, -1, 1);
    mx_fill_random(a->w, N * K, 2, -1, 1);
    mx_fill_random(a->img, sizeof a->img / sizeof *a->img, 3, -1, 1);
    mx_fill_random(a->cw, sizeof a->cw / sizeof *a->cw, 4, -1, 1);
    memcpy(b, a, sizeof *a);
    mx_profile pr;
    memset(&pr, 0, sizeof pr);
    run_ops(&c, a); /* no profile: nothing to record into, nothing read */
    c.prof = &pr;
    run_ops(&c, b);
    CHECK(memcmp(a->y, b->y, sizeof a->y) == 0 && memcmp(a->cy, b->cy, sizeof a->cy) == 0);
    check_op_slots(&pr, 1);
    int engine = c.k->isa != MX_ISA_SCALAR;
    check_gemm_user(&pr, MX_GEMM_LINEAR, 2.0 * M * N * K, engine, pr.op_secs[MX_OP_ID_linear]);
    check_gemm_user(&pr, MX_GEMM_CONV, 2.0 * CB * COUT * H * W * CIN * 9, engine, pr.op_secs[MX_OP_ID_conv2d]);
    check_accumulates(&c, b, &pr);
    if (c.k->isa == MX_ISA_AMX) { /* its fp32 layers: three bf16 products in one pass, all counted */
        mx_profile p3;
        memset(&p3, 0, sizeof p3);
        mx_ctx f = mx_ctx_fp32(&c);
        f.prof = &p3;
        mx_linear(&f, b->y, b->x, mx_w_f32(b->w), mx_w_none(), M, N, K);
        CHECK(p3.gemm_flops[MX_GEMM_LINEAR] == 3 * 2.0 * M * N * K);
    }
    printf("profile %-10s linear %.2e FLOP, conv2d %.2e FLOP: ok\n", mx_isa_name(c.k->isa),
           pr.gemm_flops[MX_GEMM_LINEAR], pr.gemm_flops[MX_GEMM_CONV]);
done:
    free(a);
    free(b);
    mx_ctx_destroy(&c);
}

/* The costs of op_list.h on calls whose FLOPs and bytes are counted here by hand: a linear with
 * fp16 weights (2 bytes each), a strided conv, a broadcast add, attention; and each call's floor
 * is the longer of its FLOPs at the peak and its bytes at the bandwidth. */
static void test_costs(void) {
    enum { LM = 3, LN = 5, LK = 7, CI = 2, CO = 3, CH = 9, CW = 6, BA = 2, HD = 2, TQ = 5, TK = 4, D = 3 };
    static float x[LM * LK], y[LM * LN], img[CI * CH * CW], cw[CO * CI * 9], cy[CO * 5 * 3], a[4 * 6], b[6], ay[4 * 6];
    static float q[BA * TQ * HD * D], k[BA * TK * HD * D], v[BA * TK * HD * D], o[BA * TQ * HD * D];
    static uint16_t w16[LN * LK];
    mx_ctx c;
    mx_status st = {0};
    if (mx_ctx_create(&c, 1, MX_ISA_SCALAR, (size_t)1 << 20, &st)) {
        printf("FAIL: context: %s\n", st.msg);
        CHECK(0);
        return;
    }
    mx_profile pr;
    memset(&pr, 0, sizeof pr);
    pr.peak_flops = 1e3;
    pr.bandwidth = 1e3; /* 1 FLOP per byte: a call's floor is max(FLOPs, bytes) ms */
    c.prof = &pr;
    mx_wptr wh = {w16, MX_F16};
    mx_linear(&c, y, x, wh, mx_w_none(), LM, LN, LK);
    CHECK(pr.op_flops[MX_OP_ID_linear] == 2.0 * LM * LN * LK);
    CHECK(pr.op_bytes[MX_OP_ID_linear] == 4.0 * (LM * LK + LM * LN) + 2.0 * LN * LK);
    mx_conv2d(&c, cy, img, 1, CI, CH, CW, mx_w_f32(cw), mx_w_none(), CO, 3, 3, 2, 1); /* 5×3 outputs */
    CHECK(pr.op_flops[MX_OP_ID_conv2d] == 2.0 * CO * 5 * 3 * CI * 9);
    CHECK(pr.op_bytes[MX_OP_ID_conv2d] == 4.0 * (CI * CH * CW + CO * 5 * 3) + 4.0 * CO * CI * 9);
    int64_t as[2] = {4, 6}, bs[2] = {1, 6};
    mx_binary(&c, MX_BIN_ADD, ay, a, as, b, bs, 2);
    CHECK(pr.op_flops[MX_OP_ID_binary] == 24 && pr.op_bytes[MX_OP_ID_binary] == 4.0 * (24 + 6 + 24));
    mx_attention(&c, o, q, k, v, BA, HD, TQ, TK, D, HD * D, HD * D, HD * D, 0, 1.0f);
    CHECK(pr.op_flops[MX_OP_ID_attention] == 4.0 * BA * HD * TQ * TK * D);
    CHECK(pr.op_bytes[MX_OP_ID_attention] == 4.0 * BA * HD * D * (2 * TQ + 2 * TK));
    for (int op = 0; op < MX_OP_COUNT; op++) {
        double most = pr.op_flops[op] > pr.op_bytes[op] ? pr.op_flops[op] : pr.op_bytes[op];
        CHECK(fabs(pr.op_floor[op] - most / 1e3) <= 1e-12 * most);
    }
    printf("costs: linear %.0f FLOP %.0f B, conv2d %.0f FLOP %.0f B, floors: ok\n", pr.op_flops[MX_OP_ID_linear],
           pr.op_bytes[MX_OP_ID_linear], pr.op_flops[MX_OP_ID_conv2d], pr.op_bytes[MX_OP_ID_conv2d]);
    mx_ctx_destroy(&c);
}

int main(void) {
    test_costs();
    CHECK(strcmp(mx_op_name(MX_OP_ID_linear), "linear") == 0);
    CHECK(strcmp(mx_op_name(MX_OP_ID_embed_tokens), "embed_tokens") == 0);
    CHECK(strcmp(mx_op_name(MX_OP_COUNT), "?") == 0 && strcmp(mx_op_name(-1), "?") == 0);
    test_level(MX_ISA_SCALAR);
    test_level(mx_cpu_isa_for(MX_PREC_FP32));
    mx_isa bf16 = mx_cpu_isa_for(MX_PREC_BF16);
    if (mx_isa_precision(bf16) == MX_PREC_BF16) test_level(bf16);
    return mx_test_finish("test_ops_profile");
}
