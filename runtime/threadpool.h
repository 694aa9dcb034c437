/* A pthread pool with one primitive: run fn(ctx, task, thread) for task in [0, ntasks).
 * Determinism rule: callers split work into tasks by problem size only (never by the
 * number of threads), and each task writes its own outputs with a fixed order of
 * arithmetic; so results are bit-identical for 1, 2 or 16 threads.
 * `thread` (0..nthreads-1) only selects per-thread scratch space. */
#ifndef MX_THREADPOOL_H
#define MX_THREADPOOL_H

#include "status.h"

typedef struct mx_pool mx_pool;
typedef void (*mx_task_fn)(void *ctx, int task, int thread);

/* nthreads <= 0 means the number of online CPUs. The caller's thread works too,
 * so nthreads - 1 workers are started. */
mx_pool *mx_pool_create(int nthreads, mx_status *st);
void mx_pool_destroy(mx_pool *pool);
/* 1 for a NULL pool (serial execution). */
int mx_pool_threads(const mx_pool *pool);
/* Runs all tasks and returns when they are done. pool may be NULL (runs inline).
 * Not reentrant: a task must not call mx_pool_for on the same pool. */
void mx_pool_for(mx_pool *pool, int ntasks, mx_task_fn fn, void *ctx);

#endif
