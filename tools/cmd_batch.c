/* matex batch MANIFEST.jsonl --weights W -o OUTROOT [--shard I/N]: a catalogue, one model set
 * loaded once, the jobs of one shard in order, resumable (tools/cli_batch_manifest.h). */
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../pipeline/texture/api_opts.h"
#include "../runtime/buf.h"
#include "../runtime/log.h"
#include "cli.h"
#include "cli_batch_manifest.h"
#include "cli_signals.h"

typedef struct batch_args {
    const char *manifest, *weights, *outroot, *device;
    int shard, nshards, threads, precision, json, quiet, verbose;
} batch_args;

enum { JOB_DONE, JOB_SKIPPED, JOB_FAILED, JOB_INTERRUPTED };
static const char *const STATUS_NAME[] = {"done", "skipped", "failed", "interrupted"};

typedef struct batch_run {
    const batch_args *a;
    matex_models *models; /* opened at the first job that runs */
    int fatal;            /* the model set could not be opened: the batch stops */
    int count[4];
    double job_seconds; /* of the jobs done */
    mx_buf results;     /* JSON array members */
    volatile sig_atomic_t *stop; /* set by SIGINT/SIGTERM (scancel): the running job stops, leaves
                                    nothing, and the batch ends */
} batch_run;


static void batch_usage(FILE *f) {
    fprintf(f,
            "usage: matex batch MANIFEST.jsonl --weights W.mxw -o OUTROOT [--shard I/N] [options]\n\n"
            "Textures a catalogue: one JSON object per line, {\"mesh\": ..., \"prompt\": ...} and optionally\n"
            "\"name\" (output folder, default the mesh's file name), \"seed\", \"negative\" and any texture option\n"
            "(\"steps\": 20, \"image-size\": 512, \"depth-weight\": [1.0, 0.7], ...). The model set is loaded\n"
            "once; jobs of the shard run in order into OUTROOT/NAME. A job whose output folder is complete is\n"
            "skipped (rerun to resume); a failed job goes to OUTROOT/failed.jsonl and the run goes on.\n\n"
            "options:\n"
            "  --shard I/N    run the jobs whose index (0-based, manifest order) mod N is I (default\n"
            "                 SLURM_ARRAY_TASK_ID-SLURM_ARRAY_TASK_MIN / SLURM_ARRAY_TASK_COUNT, else 0/1)\n"
            "  --threads N    CPU threads (default: all)\n"
            "  --precision fp32|bf16, --device cpu|cuda   as for matex texture (default bf16, cpu)\n"
            "  --json         print the summary as JSON on stdout\n"
            "  --verbose      the progress lines of every job on stderr\n"
            "  --quiet        no per-job lines on stderr\n"
            "  -h, --help     this help\n"
            "exit: 0 all jobs done or skipped, 1 a job failed or a line is bad, 2 usage, 130 interrupted\n");
}

static int usage_error(const char *msg, const char *arg) {
    fprintf(stderr, "matex batch: %s%s%s\n(matex batch --help for usage)\n", msg, arg ? " " : "", arg ? arg : "");
    return 2;
}

static int parse_shard(const char *s, int *i, int *n) {
    char tail;
    return sscanf(s, "%d/%d%c", i, n, &tail) == 2 && *n >= 1 && *i >= 0 && *i < *n ? 0 : -1;
}

/* The shard from Slurm's array variables; 1 when they are not set, -1 when they make no sense. */
static int shard_from_slurm(int *i, int *n) {
    const char *id = getenv("SLURM_ARRAY_TASK_ID"), *count = getenv("SLURM_ARRAY_TASK_COUNT");
    const char *min = getenv("SLURM_ARRAY_TASK_MIN");
    if (!id || !count) return 1;
    char buf[64];
    snprintf(buf, sizeof buf, "%d/%s", atoi(id) - (min ? atoi(min) : 0), count);
    return parse_shard(buf, i, n);
}

static int parse_args(batch_args *a, int argc, char **argv) {
    memset(a, 0, sizeof *a);
    a->nshards = 1;
    a->precision = MATEX_PRECISION_BF16;
    int have_shard = 0;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i], *val = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) return batch_usage(stdout), 0;
        if (!strcmp(arg, "--json")) a->json = 1;
        else if (!strcmp(arg, "--quiet")) a->quiet = 1;
        else if (!strcmp(arg, "--verbose")) a->verbose = 1;
        else if (arg[0] == '-' && arg[1]) {
            if (!val) return usage_error("missing value after", arg);
            i++;
            if (!strcmp(arg, "--weights")) a->weights = val;
            else if (!strcmp(arg, "-o") || !strcmp(arg, "--output")) a->outroot = val;
            else if (!strcmp(arg, "--shard")) {
                if (parse_shard(val, &a->shard, &a->nshards)) return usage_error("--shard must be I/N with 0 <= I < N, not", val);
                have_shard = 1;
            } else if (!strcmp(arg, "--precision")) {
                if (strcmp(val, "fp32") && strcmp(val, "bf16")) return usage_error("--precision must be fp32 or bf16, not", val);
                a->precision = !strcmp(val, "fp32") ? MATEX_PRECISION_FP32 : MATEX_PRECISION_BF16;
            } else if (!strcmp(arg, "--device")) {
                a->device = val; /* checked when the model set opens */
            } else if (!strcmp(arg, "--threads")) {
                char *end;
                long t = strtol(val, &end, 10);
                if (*end || end == val || t < 0 || t > 1024) return usage_error("--threads must be in 0..1024, not", val);
                a->threads = (int)t;
            } else {
                return usage_error("unknown option", arg);
            }
        } else if (!a->manifest) {
            a->manifest = arg;
        } else {
            return usage_error("unexpected argument", arg);
        }
    }
    if (!a->manifest) return usage_error("missing MANIFEST", NULL);
    if (!a->weights) return usage_error("missing --weights FILE", NULL);
    if (!a->outroot) return usage_error("missing -o OUTROOT", NULL);
    if (!have_shard && shard_from_slurm(&a->shard, &a->nshards) < 0)
        return usage_error("SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT do not give a shard; use --shard I/N", NULL);
    return -1;
}

/* mkdir -p */
static int make_folders(const char *path, mx_status *st) {
    char p[4096];
    if ((size_t)snprintf(p, sizeof p, "%s", path) >= sizeof p) return mx_fail(st, MX_EINPUT, "%s: path too long", path);
    for (char *s = p + 1;; s++) {
        if (*s != '/' && *s) continue;
        char c = *s;
        *s = 0;
        if (mkdir(p, 0777) && errno != EEXIST) return mx_fail(st, MX_EIO, "%s: cannot create folder: %s", p, strerror(errno));
        *s = c;
        if (!c) return 0;
    }
}

/* A job's output folder is complete when the run published it (report.json is in it). */
static int job_complete(const mx_batch_job *j) {
    char p[4200];
    snprintf(p, sizeof p, "%s/report.json", j->c.o.out_dir);
    struct stat sb;
    return stat(p, &sb) == 0 && S_ISREG(sb.st_mode);
}

/* One line of OUTROOT/failed.jsonl, appended with a single write (shards share the file). */
static void record_failure(const batch_run *r, const mx_batch_job *j, const char *error) {
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"line\":%d,\"name\":", j->line);
    mx_buf_json_str(&b, j->name);
    mx_buf_printf(&b, ",\"shard\":\"%d/%d\",\"error\":", r->a->shard, r->a->nshards);
    mx_buf_json_str(&b, error);
    mx_buf_printf(&b, "}\n");
    char path[4200];
    snprintf(path, sizeof path, "%s/failed.jsonl", r->a->outroot);
    int fd = b.oom ? -1 : open(path, O_WRONLY | O_CREAT | O_APPEND, 0666);
    if (fd < 0 || write(fd, b.p, b.len) != (ssize_t)b.len) mx_error("%s: cannot record the failure of line %d", path, j->line);
    if (fd >= 0) close(fd);
    mx_buf_free(&b);
}

/* 0 done, 1 interrupted, -1 failed (error set). */
static int run_job(batch_run *r, const mx_batch_job *j, double *coverage, char *error, size_t cap) {
    matex_error err;
    matex_options o;
    mx_api_options_from_internal(&j->c.o, &o);
    o.verbose = r->a->verbose;
    o.cancel = r->stop;
    matex_result *res = NULL;
    int rc = matex_texture(r->models, &o, &res, &err);
    if (rc) snprintf(error, cap, "%s", err.message);
    else *coverage = res->coverage;
    matex_result_free(res);
    return rc ? (err.code == MATEX_ECANCELLED ? 1 : -1) : 0;
}

/* Counts the job, adds it to the summary and prints its line (error: NULL, or why it failed). */
static void add_result(batch_run *r, const mx_batch_job *j, int status, double seconds, double coverage,
                       const char *error) {
    r->count[status]++;
    if (status == JOB_DONE) r->job_seconds += seconds;
    mx_buf_printf(&r->results, "%s{\"line\":%d,\"name\":", r->results.len ? "," : "", j->line);
    mx_buf_json_str(&r->results, j->name);
    mx_buf_printf(&r->results, ",\"status\":\"%s\",\"seconds\":%.3f", STATUS_NAME[status], seconds);
    if (status == JOB_DONE) mx_buf_printf(&r->results, ",\"coverage\":%.6f", coverage);
    mx_buf_printf(&r->results, "}");
    if (error) fprintf(stderr, "matex batch: line %d (%s): failed: %s\n", j->line, j->name, error);
    else if (!r->a->quiet)
        fprintf(stderr, "matex batch: line %d (%s): %s (%.2f s)\n", j->line, j->name, STATUS_NAME[status], seconds);
}

static void batch_job(batch_run *r, const mx_batch_job *j) {
    if (j->error[0]) {
        char msg[1200];
        snprintf(msg, sizeof msg, "%s:%d: %s", r->a->manifest, j->line, j->error);
        record_failure(r, j, msg);
        add_result(r, j, JOB_FAILED, 0.0, 0.0, msg);
        return;
    }
    if (job_complete(j)) {
        add_result(r, j, JOB_SKIPPED, 0.0, 0.0, NULL);
        return;
    }
    matex_error err;
    matex_options mo;
    matex_options_default(&mo);
    mo.threads = r->a->threads;
    mo.precision = r->a->precision;
    mo.device = r->a->device;
    if (!r->models && !(r->models = matex_models_open(r->a->weights, &mo, &err))) {
        fprintf(stderr, "matex batch: %s\n", err.message);
        r->fatal = 1;
        return;
    }
    double t = mx_now(), coverage = 0.0;
    char error[1024];
    int rc = run_job(r, j, &coverage, error, sizeof error);
    if (rc < 0) record_failure(r, j, error);
    add_result(r, j, rc == 0 ? JOB_DONE : rc > 0 ? JOB_INTERRUPTED : JOB_FAILED, mx_now() - t, coverage,
               rc < 0 ? error : NULL);
}

static void print_summary(const batch_run *r, int jobs, double seconds) {
    const batch_args *a = r->a;
    double per_job = r->count[JOB_DONE] ? r->job_seconds / r->count[JOB_DONE] : 0.0;
    if (!a->json) {
        printf("matex batch: shard %d/%d, %d jobs: %d done, %d skipped, %d failed%s; %.2f s per job done, %.2f s in all\n",
               a->shard, a->nshards, jobs, r->count[JOB_DONE], r->count[JOB_SKIPPED], r->count[JOB_FAILED],
               r->count[JOB_INTERRUPTED] ? ", interrupted" : "", per_job, seconds);
        return;
    }
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"ok\":%s,\"manifest\":", r->count[JOB_FAILED] || r->count[JOB_INTERRUPTED] ? "false" : "true");
    mx_buf_json_str(&b, a->manifest);
    mx_buf_printf(&b, ",\"shard\":\"%d/%d\",\"jobs\":%d,\"done\":%d,\"skipped\":%d,\"failed\":%d,\"interrupted\":%s,"
                      "\"seconds\":%.3f,\"seconds_per_job\":%.3f,\"results\":[%s]}",
                  a->shard, a->nshards, jobs, r->count[JOB_DONE], r->count[JOB_SKIPPED], r->count[JOB_FAILED],
                  r->count[JOB_INTERRUPTED] ? "true" : "false", seconds, per_job, r->results.p ? r->results.p : "");
    puts(b.oom || r->results.oom ? "{\"ok\":false,\"error\":\"out of memory\"}" : b.p);
    mx_buf_free(&b);
}

int cmd_batch(int argc, char **argv) {
    batch_args a;
    int rc = parse_args(&a, argc, argv);
    if (rc >= 0) return rc;
    if (!a.verbose) mx_log_set_level(MX_LOG_ERROR);
    mx_status st;
    mx_status_clear(&st);
    mx_batch_manifest m;
    if (make_folders(a.outroot, &st) || mx_batch_manifest_read(&m, a.manifest, a.weights, a.outroot, a.shard, a.nshards, &st)) {
        fprintf(stderr, "matex batch: %s\n", st.msg);
        return 1;
    }
    batch_run r = {&a, NULL, 0, {0}, 0.0, {0}, mx_cli_signals_catch()};
    double t0 = mx_now();
    int jobs = 0;
    for (int i = 0; i < m.njobs; i++) jobs += m.jobs[i].index % a.nshards == a.shard;
    for (int i = 0; i < m.njobs && !*r.stop && !r.fatal; i++)
        if (m.jobs[i].index % a.nshards == a.shard) batch_job(&r, &m.jobs[i]);
    if (!r.fatal) print_summary(&r, jobs, mx_now() - t0);
    matex_models_close(r.models);
    mx_batch_manifest_free(&m);
    mx_buf_free(&r.results);
    if (r.fatal) return 1;
    return *r.stop || r.count[JOB_INTERRUPTED] ? 130 : r.count[JOB_FAILED] ? 1 : 0;
}
