/* Every op that takes a weight has a strict wrapper: on cpu-strict, an op whose parameters in
 * ops/op_list.h include an mx_wptr must check that each weight is device memory before the
 * kernel runs (ops/backend.c, strict_table), or a host weight would pass unseen. The set of ops
 * with a weight is read from the op list itself, so a new weighted op without a wrapper fails
 * here by name. Checked on the table of each level this CPU runs and on its fp32 table. */
#include <stdio.h>
#include <string.h>

#include "../ops/ops.h"
#include "util_test.h"

/* 1 when an op's parameter list (op_list.h's params, as text) has a weight. */
static int takes_weight(const char *params) { return strstr(params, "mx_wptr") != NULL; }

/* Each weighted op's entry of the strict table `strict` is a wrapper, not the CPU kernel of
 * `inner` that it wraps; returns the number of weighted ops. */
static int check_wrapped(const mx_kernels *strict, const mx_kernels *inner, const char *table) {
    int weighted = 0;
#define CHECK_WRAPPED_(name, guard, params, args, cost)                                                      \
    if (takes_weight(#params)) {                                                                             \
        weighted++;                                                                                          \
        if (strict->name == inner->name || !strict->name)                                                    \
            printf("FAIL: cpu-strict table %s: op %s takes a weight but has no strict wrapper\n", table, #name); \
        CHECK(strict->name && strict->name != inner->name);                                                  \
    }
    MX_OPS(CHECK_WRAPPED_)
#undef CHECK_WRAPPED_
    return weighted;
}

static void check_level(mx_isa isa) {
    mx_ctx c;
    mx_status st = {0};
    if (mx_ctx_create_on(&c, MX_BACKEND_CPU_STRICT, 1, isa, 1 << 16, &st)) {
        printf("FAIL: cpu-strict context at %s: %s\n", mx_isa_name(isa), st.msg);
        CHECK(0);
        return;
    }
    const mx_kernels *inner = mx_kernels_for(isa);
    int weighted = check_wrapped(c.k, inner, mx_isa_name(isa));
    mx_ctx f = mx_ctx_fp32(&c);
    char name[64];
    snprintf(name, sizeof name, "%s (fp32 layers)", mx_isa_name(isa));
    CHECK(check_wrapped(f.k, mx_kernels_fp32_of(inner), name) == weighted);
    CHECK(weighted > 0); /* the list has weighted ops (linear, conv2d, ...): the test reads it */
    printf("cpu-strict %-10s: %d ops with a weight checked\n", mx_isa_name(isa), weighted);
    mx_ctx_destroy(&c);
}

int main(void) {
    /* every level this CPU runs, each once (mx_kernels_for lowers the ones it lacks) */
    for (mx_isa isa = MX_ISA_SCALAR; isa < MX_ISA_COUNT; isa++)
        if (mx_kernels_compiled(isa) && mx_kernels_for(isa)->isa == isa) check_level(isa);
    return mx_test_finish("test_ops_strict_wrappers");
}
