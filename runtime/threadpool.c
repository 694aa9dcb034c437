#include "threadpool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

/* How long a worker waits for the next job, and the caller for the workers to finish, by
 * polling before it sleeps on a condition variable. A GEMM issues a job per K block and
 * outer block (thousands per UNet call, each a few hundred µs); waking a sleeping thread
 * takes tens of µs on a VM (an IPI to a halted vCPU), so without polling the threads sat
 * idle for ~6 % of a UNet call. Polling is bounded, so an idle pool still sleeps. */
#define POLL_NS 200000

struct mx_pool {
    int nthreads;
    pthread_t *workers;
    pthread_mutex_t mu;
    pthread_cond_t work_cv, done_cv;
    /* the job being run; generation changes each time a new job is published */
    mx_task_fn fn;
    void *ctx;
    int ntasks;
    /* (generation << 32) | next task: a worker still holding an older job can never claim
     * a task of the current one (it would run it with the old job's fn and ctx) */
    atomic_ullong next_task;
    /* changed under mu; atomic so that the polling loops can read them without it */
    atomic_int active_workers;
    atomic_ulong generation;
    int quit;
};

typedef struct {
    mx_pool *pool;
    int index;
} worker_arg;

static void run_tasks(mx_pool *p, mx_task_fn fn, void *ctx, int ntasks, unsigned long gen, int thread) {
    unsigned long long v = atomic_load(&p->next_task);
    for (;;) {
        if ((v >> 32) != (gen & 0xffffffffu) || (int)(v & 0xffffffffu) >= ntasks) break;
        if (atomic_compare_exchange_weak(&p->next_task, &v, v + 1)) {
            fn(ctx, (int)(v & 0xffffffffu), thread);
            v = atomic_load(&p->next_task);
        }
    }
}

static long long now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static inline void cpu_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

/* Polls until *v differs from old, for at most POLL_NS; the caller then checks again under
 * the mutex. */
static void poll_until_changed(atomic_ulong *v, unsigned long old) {
    long long end = now_ns() + POLL_NS;
    for (int i = 0; atomic_load_explicit(v, memory_order_relaxed) == old; i++) {
        cpu_relax();
        if ((i & 255) == 255 && now_ns() > end) return;
    }
}

/* Polls until *v is 0, for at most POLL_NS. */
static void poll_until_zero(atomic_int *v) {
    long long end = now_ns() + POLL_NS;
    for (int i = 0; atomic_load_explicit(v, memory_order_relaxed) != 0; i++) {
        cpu_relax();
        if ((i & 255) == 255 && now_ns() > end) return;
    }
}

static void *worker_main(void *arg) {
    worker_arg *wa = arg;
    mx_pool *p = wa->pool;
    int index = wa->index;
    free(wa);
    unsigned long seen = 0;
    pthread_mutex_lock(&p->mu);
    for (;;) {
        if (!p->quit && p->generation == seen) {
            pthread_mutex_unlock(&p->mu);
            poll_until_changed(&p->generation, seen);
            pthread_mutex_lock(&p->mu);
        }
        while (!p->quit && p->generation == seen) pthread_cond_wait(&p->work_cv, &p->mu);
        if (p->quit) break;
        seen = p->generation;
        mx_task_fn fn = p->fn;
        void *ctx = p->ctx;
        int ntasks = p->ntasks;
        p->active_workers++;
        pthread_mutex_unlock(&p->mu);
        run_tasks(p, fn, ctx, ntasks, seen, index);
        pthread_mutex_lock(&p->mu);
        if (--p->active_workers == 0) pthread_cond_signal(&p->done_cv);
    }
    pthread_mutex_unlock(&p->mu);
    return NULL;
}

mx_pool *mx_pool_create(int nthreads, mx_status *st) {
    if (nthreads <= 0) {
        long n = sysconf(_SC_NPROCESSORS_ONLN);
        nthreads = n > 0 ? (int)n : 1;
    }
    if (nthreads > 256) nthreads = 256;
    mx_pool *p = calloc(1, sizeof *p);
    if (!p) {
        mx_fail(st, MX_ENOMEM, "thread pool: out of memory");
        return NULL;
    }
    p->nthreads = nthreads;
    pthread_mutex_init(&p->mu, NULL);
    pthread_cond_init(&p->work_cv, NULL);
    pthread_cond_init(&p->done_cv, NULL);
    atomic_init(&p->next_task, 0);
    if (nthreads > 1) {
        p->workers = calloc((size_t)nthreads - 1, sizeof *p->workers);
        if (!p->workers) {
            mx_pool_destroy(p);
            mx_fail(st, MX_ENOMEM, "thread pool: out of memory");
            return NULL;
        }
    }
    for (int i = 1; i < nthreads; i++) {
        worker_arg *wa = malloc(sizeof *wa);
        if (wa) *wa = (worker_arg){p, i}; /* filled before the thread can read it */
        if (!wa || pthread_create(&p->workers[i - 1], NULL, worker_main, wa) != 0) {
            free(wa);
            p->nthreads = i; /* only i-1 workers exist */
            mx_pool_destroy(p);
            mx_fail(st, MX_EINTERNAL, "thread pool: cannot start thread %d", i);
            return NULL;
        }
    }
    return p;
}

void mx_pool_destroy(mx_pool *p) {
    if (!p) return;
    pthread_mutex_lock(&p->mu);
    p->quit = 1;
    pthread_cond_broadcast(&p->work_cv);
    pthread_mutex_unlock(&p->mu);
    for (int i = 1; i < p->nthreads; i++) pthread_join(p->workers[i - 1], NULL);
    pthread_mutex_destroy(&p->mu);
    pthread_cond_destroy(&p->work_cv);
    pthread_cond_destroy(&p->done_cv);
    free(p->workers);
    free(p);
}

int mx_pool_threads(const mx_pool *p) { return p ? p->nthreads : 1; }

void mx_pool_for(mx_pool *p, int ntasks, mx_task_fn fn, void *ctx) {
    if (ntasks <= 0) return;
    if (!p || p->nthreads == 1 || ntasks == 1) {
        for (int t = 0; t < ntasks; t++) fn(ctx, t, 0);
        return;
    }
    pthread_mutex_lock(&p->mu);
    p->fn = fn;
    p->ctx = ctx;
    p->ntasks = ntasks;
    unsigned long gen = ++p->generation;
    atomic_store(&p->next_task, (unsigned long long)(gen & 0xffffffffu) << 32);
    pthread_cond_broadcast(&p->work_cv);
    pthread_mutex_unlock(&p->mu);
    run_tasks(p, fn, ctx, ntasks, gen, 0);
    /* wait until every worker that picked up this generation has finished */
    poll_until_zero(&p->active_workers);
    pthread_mutex_lock(&p->mu);
    while (p->active_workers > 0) pthread_cond_wait(&p->done_cv, &p->mu);
    pthread_mutex_unlock(&p->mu);
}
