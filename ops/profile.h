/* Where a run's time goes: per op the CPU time of the process (all threads) while it ran and,
 * inside the GEMM engine (linear, conv2d), the CPU time of each part in each thread (packing A,
 * packing B = the tiled im2col for conv, the micro-kernel with the bias added to its tiles).
 * CPU time, not wall time: on a shared machine it counts only the work of this run (the pool's
 * idle workers sleep, so they add nothing). Filled only when a context carries one (mx_ctx.prof,
 * set by bench_nets); a NULL profile reads no clock. Plain sums, written by the calling thread
 * after each op (the GEMM's worker threads write their own slots first). */
#ifndef MX_OPS_PROFILE_H
#define MX_OPS_PROFILE_H

#include <time.h>

#include "op_list.h"

/* The op ids, in list order: MX_OP_ID_linear, ... (profile slots and names). */
#define MX_OP_ID_(name, guard, params, args, cost) MX_OP_ID_##name,
enum { MX_OPS(MX_OP_ID_) };
#undef MX_OP_ID_

typedef enum {
    MX_GEMM_PACK_A,   /* A panels: linear's activations, conv's weights (widened, to pairs) */
    MX_GEMM_PACK_B,   /* B panels: linear's weights; conv's input band (gemm_conv.c) and panels copied from it */
    MX_GEMM_MICRO,    /* the register-blocked micro-kernel, C loads and stores and the bias included */
    MX_GEMM_PARTS
} mx_gemm_part;

/* The GEMM users that are told apart (0: linear, 1: conv2d). */
enum { MX_GEMM_LINEAR, MX_GEMM_CONV, MX_GEMM_USERS };

/* What one op call costs at least (op_list.h's cost): its FLOPs and the bytes it moves. */
typedef struct {
    double flops, bytes;
} mx_op_cost;

typedef struct mx_profile {
    double op_secs[MX_OP_COUNT]; /* process CPU seconds inside each op */
    double op_wall[MX_OP_COUNT]; /* wall seconds inside each op (threads × wall − CPU: idle) */
    long op_calls[MX_OP_COUNT];
    /* The roofline: the machine's peak FLOP/s and memory bandwidth in bytes/s (set by the caller;
     * 0: no floors) and per op the sums of its calls' FLOPs, bytes and floors, a call's floor
     * being the longer of its FLOPs at the peak and its bytes at the bandwidth, in seconds. */
    double peak_flops, bandwidth;
    double op_flops[MX_OP_COUNT], op_bytes[MX_OP_COUNT], op_floor[MX_OP_COUNT];
    double gemm_secs[MX_GEMM_USERS][MX_GEMM_PARTS]; /* thread seconds, summed over threads */
    double gemm_flops[MX_GEMM_USERS];               /* 2·M·N·K·batch of the calls, three times that for
                                                     * a split product's (the fp32 layers on AMX) */
} mx_profile;

/* CPU seconds of the process (CLOCK_PROCESS_CPUTIME_ID) or the calling thread (…THREAD…). */
static inline double mx_profile_clock(clockid_t which) {
    struct timespec ts;
    clock_gettime(which, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* The name of op id `op` (its op_list.h name), or "?" out of range. */
const char *mx_op_name(int op);

#endif
