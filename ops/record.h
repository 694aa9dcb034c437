/* A recorded region: work that a caller queues the same way call after call (the networks' part of
 * a denoising step, pipeline/nn/sd_pipeline.c), which a backend may capture once and replay
 * instead of queueing it op by op (CUDA graphs under MATEX_CUDA_GRAPH=1, docs/cuda-notes.md §11).
 *
 * The region is a function fn(user) that queues ops. Its contract, from its second call on:
 * - it queues the same ops with the same arguments (pointers, sizes, host scalars) at every call;
 *   what changes between calls lives in device memory written by work queued outside the region
 *   (e.g. the timestep buffer, filled before it);
 * - it allocates and frees no backend memory, copies nothing to or from the host and waits for
 *   nothing (a replay runs none of fn's host code: only the work it queued);
 * - host state it changes (step-cache cursors, arena marks) ends each call as it began.
 * The first call always runs fn directly: it may build what later calls reuse (the step caches,
 * GEMM and cuDNN plans, grown buffers). cpu-strict checks the second rule at every later call, so
 * the CPU tests catch a region that a GPU could not capture. */
#ifndef MX_RECORD_H
#define MX_RECORD_H

#include "ops.h"

typedef struct mx_record {
    int calls;   /* calls made so far */
    int direct;  /* 1: the backend could not capture it; fn runs directly from now on */
    void *graph; /* the backend's captured form (CUDA: a cudaGraphExec_t), or NULL */
} mx_record;

/* Runs (or replays) the region fn(user) on c as the next call of rec (zeroed before the first).
 * 0, or -1 with st from fn or the backend. */
int mx_ctx_recorded(const mx_ctx *c, mx_record *rec, int (*fn)(void *user, mx_status *st), void *user,
                    mx_status *st);
/* Frees what the backend kept for rec (after the last call, before the memory fn used is freed)
 * and zeroes it. */
void mx_record_free(const mx_ctx *c, mx_record *rec);

#endif
