/* The job queue of `matex serve`, held on disk under the jobs folder so that nothing acknowledged
 * is lost when the server dies:
 *   JOBS/.matex-serve        the marker: a folder without it (and not empty) is refused
 *   JOBS/.lock               flock'ed by the server for its lifetime: a second server is refused
 *   JOBS/.incoming/ID/       an upload being received (removed when it fails or the server starts)
 *   JOBS/ID/                 a job, put in place by one rename once complete (then it is
 *                            acknowledged): mesh.EXT, style_K.EXT, options.json (the request's
 *                            options), state (queued|running|done|failed|cancelled), attempts,
 *                            error (when failed), events.jsonl (the CLI's progress stream,
 *                            tools/matex/cli_progress.h), out/ (the output folder, written by the
 *                            library as `matex texture -o` writes it).
 * Ids are the submission time in milliseconds and a counter, in hexadecimal: their order is the
 * queue's. One worker runs the jobs one at a time, oldest first. A job found `running` when the
 * server starts was interrupted (kill -9, a crash): it runs again once, then is marked failed. */
#ifndef MX_SERVE_JOBS_H
#define MX_SERVE_JOBS_H

#include <pthread.h>
#include <signal.h>
#include <stdint.h>

#include "../../../include/matex.h"
#include "../../../runtime/buf.h"
#include "../../../runtime/status.h"
#include "serve_request.h"

#define MX_SERVE_MAX_ATTEMPTS 2 /* a job interrupted by the server's death runs again once */

typedef enum { MX_JOB_QUEUED, MX_JOB_RUNNING, MX_JOB_DONE, MX_JOB_FAILED, MX_JOB_CANCELLED, MX_JOB_NONE } mx_job_state;

typedef struct mx_serve_limits {
    int max_queued;      /* jobs waiting or running; a submission beyond it is a 429 */
    int keep_jobs;       /* finished jobs kept; the oldest beyond it are removed */
    uint64_t keep_bytes; /* the same by their total size on disk */
} mx_serve_limits;

typedef struct mx_serve_jobs {
    char dir[4096];
    int lock_fd;
    mx_serve_limits limits;
    pthread_mutex_t mu;          /* state changes and the fields below */
    pthread_cond_t wake;         /* a job was queued, or stop was set */
    unsigned counter;            /* of ids made in this millisecond */
    uint64_t last_ms;
    char running[MX_SERVE_ID_MAX + 1]; /* the job the worker runs ("" none) */
    volatile sig_atomic_t cancel;      /* the running job stops (matex_options.cancel) */
    int requeue;                 /* the running job was stopped by the shutdown: back to queued */
    int stop;                    /* the worker ends after its job */
} mx_serve_jobs;

/* Opens (creating and marking it when missing or empty) and locks the jobs folder, removes
 * unfinished uploads and recovers the jobs an earlier server left running. */
int mx_serve_jobs_open(mx_serve_jobs *q, const char *dir, const mx_serve_limits *limits, mx_status *st);
void mx_serve_jobs_close(mx_serve_jobs *q);

/* A submission: a fresh id and its upload folder (a 429 when the queue is full). */
int mx_serve_jobs_stage(mx_serve_jobs *q, char id[MX_SERVE_ID_MAX + 1], char stage[4200], mx_serve_error *e);
/* The upload is complete and checked: the job is queued, on disk, before this returns 0. */
int mx_serve_jobs_commit(mx_serve_jobs *q, const char *id, mx_serve_error *e);
/* Drops an upload folder. */
void mx_serve_jobs_unstage(mx_serve_jobs *q, const char *id);

/* A job as JSON: {"id", "state", "attempts", "progress": the latest progress line or null,
 * "error" (failed), "files": [...] (done)}; a 404 when there is no such job. */
int mx_serve_jobs_describe(mx_serve_jobs *q, const char *id, mx_buf *out, mx_serve_error *e);
/* {"jobs": [each as describe writes it], oldest first}. */
void mx_serve_jobs_list(mx_serve_jobs *q, mx_buf *out);
/* DELETE: a queued job is cancelled, a running one is asked to stop (202); a finished one is
 * removed with its files (200). *status gets the HTTP status; out the job's state. */
int mx_serve_jobs_delete(mx_serve_jobs *q, const char *id, int *status, mx_buf *out, mx_serve_error *e);
/* An output file of a done job, opened without following links: its descriptor and size. */
int mx_serve_jobs_open_file(mx_serve_jobs *q, const char *id, const char *name, int *fd, uint64_t *size,
                            mx_serve_error *e);
/* The state of a job (MX_JOB_NONE when there is none). */
mx_job_state mx_serve_jobs_state(mx_serve_jobs *q, const char *id);
/* JOBS/ID/NAME (id checked by the caller, name one of the server's own). */
void mx_serve_jobs_path(const mx_serve_jobs *q, const char *id, const char *name, char out[4200]);
const char *mx_serve_state_name(mx_job_state s);

/* The worker: runs queued jobs with the model set m until mx_serve_jobs_stop. */
void mx_serve_jobs_work(mx_serve_jobs *q, matex_models *m);
/* Ends the worker after its job; cancel_running: the running job stops now and is queued again. */
void mx_serve_jobs_stop(mx_serve_jobs *q, int cancel_running);

#endif
