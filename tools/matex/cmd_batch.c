/* matex batch MANIFEST.jsonl --weights W -o OUTROOT [--shard I/N]: a catalogue, one model set
 * loaded once, the jobs of one shard in order, resumable (tools/matex/cli_batch_manifest.h). */
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../runtime/buf.h"
#include "../../runtime/fileio.h"
#include "../../runtime/json.h"
#include "../../runtime/log.h"
#include "cli.h"
#include "cli_batch_manifest.h"
#include "cli_signals.h"
#include "serve/serve_client.h"

#define BATCH_MAX_DEFAULTS 64

typedef struct batch_args {
    const char *manifest, *weights, *outroot;
    const char *server, *token_file; /* --server URL: the jobs run on a `matex serve` (tools/matex/serve/serve_client.h) */
    int shard, nshards, json, quiet, verbose;
    int theme_from_first; /* the first job writes front.png, the style image of the jobs without their own */
    char theme_path[4200]; /* OUTROOT/NAME/front.png of the first job (theme_from_first) */
    mx_cli_texture table;  /* the table's options given to batch: the model set's, and the jobs' defaults */
    const char *defaults[2 * BATCH_MAX_DEFAULTS]; /* the jobs' defaults as given: name, value (NULL: a flag) */
    int ndefaults;
} batch_args;

enum { JOB_DONE, JOB_SKIPPED, JOB_FAILED, JOB_INTERRUPTED };
static const char *const STATUS_NAME[] = {"done", "skipped", "failed", "interrupted"};

typedef struct batch_run {
    const batch_args *a;
    matex_models *models; /* opened at the first job that runs */
    mx_serve_client *client; /* --server: the jobs run there instead */
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
            "\"name\" (output folder, default the mesh's file name) and any option of a job below without its\n"
            "dashes (\"seed\": 3, \"image-size\": 512, \"depth-weight\": [1.0, 0.7], \"fast\": true, ...). The model\n"
            "set is loaded once; jobs of the shard run in order into OUTROOT/NAME. A job whose output folder is\n"
            "complete is skipped (rerun to resume); a failed job goes to OUTROOT/failed.jsonl, which lists the\n"
            "failures of the latest run of each job, and the run goes on.\n\n"
            "options:\n"
            "  --shard I/N               run the jobs whose index (0-based, manifest order) mod N is I (default\n"
            "                            SLURM_ARRAY_TASK_ID-SLURM_ARRAY_TASK_MIN / SLURM_ARRAY_TASK_COUNT, else 0/1)\n"
            "  --server URL              run the jobs on a running `matex serve` (its model set: no --weights);\n"
            "                            the outputs are written here as a local batch writes them; a mesh with\n"
            "                            side files (an OBJ's .mtl and textures, a glTF's .bin and images) is\n"
            "                            sent as a zip of them, each inside the mesh's folder\n"
            "  --token-file F            the server's token (Authorization: Bearer; F: one line, mode 0600)\n"
            "  --theme FILE              one style image for the whole catalogue (--style-image FILE for every job;\n"
            "                            a line's \"style_image\" replaces it)\n"
            "  --theme-from-first        the first job of the manifest also writes front.png (its textured mesh\n"
            "                            from the front) and that image is the style image of every other job\n"
            "                            without its own; the other jobs wait for it: with shards, run the first\n"
            "                            job's shard first\n"
            "  --json                    print the summary as JSON on stdout\n"
            "  --verbose                 the progress lines of every job on stderr\n"
            "  --quiet                   no per-job lines on stderr\n"
            "  -h, --help                this help\n"
            "the model set's options (threads, precision, device) and the default of every job (a line's key\n"
            "overrides it):\n");
    mx_options_help(f, MX_VERB_BATCH);
    fprintf(f, "exit: 0 all jobs done or skipped, 1 a job failed or a line is bad, 2 usage, 130 interrupted\n");
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

/* An option of the table: the model set's, or a default of every job (checked here, applied per job). */
static int table_option(batch_args *a, const char *opt, const char *value) {
    mx_status st;
    if (mx_cli_texture_option(&a->table, opt, value, &st)) return usage_error(st.msg, NULL);
    const mx_option_spec *s = mx_option_find(opt, MX_VERB_BATCH);
    if (s->scope == MX_SCOPE_JOB) {
        if (a->ndefaults == BATCH_MAX_DEFAULTS) return usage_error("too many options", NULL);
        a->defaults[2 * a->ndefaults] = s->name;
        a->defaults[2 * a->ndefaults++ + 1] = value;
    }
    return -1;
}

static int parse_args(batch_args *a, int argc, char **argv) {
    memset(a, 0, sizeof *a);
    a->nshards = 1;
    matex_options_default(&a->table.o);
    a->table.verb = MX_VERB_BATCH;
    int have_shard = 0;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i], *val = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) return batch_usage(stdout), 0;
        if (!strcmp(arg, "--json")) a->json = 1;
        else if (!strcmp(arg, "--quiet")) a->quiet = 1;
        else if (!strcmp(arg, "--verbose")) a->verbose = 1;
        else if (!strcmp(arg, "--theme-from-first")) a->theme_from_first = 1;
        else if (!strcmp(arg, "--theme")) { /* the style image of every job */
            if (!val) return usage_error("missing value after", arg);
            int rc = table_option(a, "--style-image", argv[++i]);
            if (rc >= 0) return rc;
        }
        else if (!strcmp(arg, "--weights") || !strcmp(arg, "-o") || !strcmp(arg, "--output") || !strcmp(arg, "--shard") ||
                 !strcmp(arg, "--server") || !strcmp(arg, "--token-file")) {
            if (!val) return usage_error("missing value after", arg);
            i++;
            if (!strcmp(arg, "--weights")) a->weights = val;
            else if (!strcmp(arg, "--server")) a->server = val;
            else if (!strcmp(arg, "--token-file")) a->token_file = val;
            else if (!strcmp(arg, "--shard")) {
                if (parse_shard(val, &a->shard, &a->nshards)) return usage_error("--shard must be I/N with 0 <= I < N, not", val);
                have_shard = 1;
            } else a->outroot = val;
        } else if (arg[0] == '-' && arg[1]) { /* --name value, --name=value or a flag */
            char opt[128];
            const char *eq = arg[1] == '-' ? strchr(arg, '=') : NULL;
            snprintf(opt, sizeof opt, "%.*s", eq ? (int)(eq - arg) : (int)strlen(arg), arg);
            const mx_option_spec *s = mx_option_find(opt, MX_VERB_BATCH);
            const char *value = eq ? eq + 1 : s && s->arg ? val : NULL;
            i += !eq && s && s->arg && val;
            int rc = table_option(a, opt, value);
            if (rc >= 0) return rc;
        } else if (!a->manifest) {
            a->manifest = arg;
        } else {
            return usage_error("unexpected argument", arg);
        }
    }
    if (!a->manifest) return usage_error("missing MANIFEST", NULL);
    if (!a->weights && !a->server) return usage_error("missing --weights FILE (or --server URL)", NULL);
    if (a->weights && a->server) return usage_error("--server runs the jobs with the server's model set: give no --weights", NULL);
    if (a->token_file && !a->server) return usage_error("--token-file is the token of a --server", NULL);
    if (!a->outroot) return usage_error("missing -o OUTROOT", NULL);
    if (a->theme_from_first && a->table.o.style_images[0])
        return usage_error("--theme-from-first takes the style image from the first job: give no --theme or --style-image", NULL);
    if (!have_shard && shard_from_slurm(&a->shard, &a->nshards) < 0)
        return usage_error("SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT do not give a shard; use --shard I/N", NULL);
    return -1;
}

/* A job's output folder is complete when the run published it (report.json is in it). */
static int job_complete(const mx_batch_job *j) {
    char p[4200];
    snprintf(p, sizeof p, "%s/report.json", j->c.o.out_dir);
    struct stat sb;
    return stat(p, &sb) == 0 && S_ISREG(sb.st_mode);
}

static void failures_path(const batch_run *r, char *path, size_t cap) {
    snprintf(path, cap, "%s/failed.jsonl", r->a->outroot);
}

/* One line of OUTROOT/failed.jsonl, appended with a single write under the file's lock (shards share it). */
static void record_failure(const batch_run *r, const mx_batch_job *j, const char *error) {
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"line\":%d,\"name\":", j->line);
    mx_buf_json_str(&b, j->name);
    mx_buf_printf(&b, ",\"shard\":\"%d/%d\",\"error\":", r->a->shard, r->a->nshards);
    mx_buf_json_str(&b, error);
    mx_buf_printf(&b, "}\n");
    char path[4200];
    failures_path(r, path, sizeof path);
    int fd = b.oom ? -1 : open(path, O_WRONLY | O_CREAT | O_APPEND, 0666);
    if (fd < 0 || flock(fd, LOCK_EX) || write(fd, b.p, b.len) != (ssize_t)b.len)
        mx_error("%s: cannot record the failure of line %d", path, j->line);
    if (fd >= 0) close(fd);
    mx_buf_free(&b);
}

/* Does a line of failed.jsonl name a job of this run's shard? */
static int names_own_job(const char *text, size_t len, const mx_batch_manifest *m, int shard, int nshards) {
    mx_status st;
    mx_json *e = mx_json_parse(text, len, "failed.jsonl", &st);
    int line = e ? (int)mx_json_get_num(e, "line", -1) : -1, own = 0;
    mx_json_free(e);
    for (int i = 0; i < m->njobs && !own; i++) own = m->jobs[i].line == line && m->jobs[i].index % nshards == shard;
    return own;
}

/* failed.jsonl lists the failures of the latest run of each job: this shard's jobs are run again,
 * so their earlier entries go (rewritten in place under the lock; other shards' lines stay). */
static void forget_own_failures(const batch_run *r, const mx_batch_manifest *m) {
    char path[4200];
    failures_path(r, path, sizeof path);
    int fd = open(path, O_RDWR);
    if (fd < 0) return; /* none yet */
    mx_status st;
    size_t len = 0;
    char *text = flock(fd, LOCK_EX) ? NULL : mx_read_file(path, (size_t)1 << 30, &len, &st);
    mx_buf kept = {0};
    for (size_t at = 0; text && at < len;) {
        size_t end = at;
        while (end < len && text[end] != '\n') end++;
        if (end > at && !names_own_job(text + at, end - at, m, r->a->shard, r->a->nshards))
            mx_buf_printf(&kept, "%.*s\n", (int)(end - at), text + at);
        at = end + 1;
    }
    if (!text || kept.oom || ftruncate(fd, 0) || (kept.len && pwrite(fd, kept.p, kept.len, 0) != (ssize_t)kept.len))
        mx_error("%s: cannot update the list of failures", path);
    free(text);
    mx_buf_free(&kept);
    close(fd);
}

/* 0 done, 1 interrupted, -1 failed (error set). */
static int run_job(batch_run *r, const mx_batch_job *j, double *coverage, char *error, size_t cap) {
    matex_error err;
    matex_options o = j->c.o;
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
    char label[160]; /* "line 5 (chair_a)"; a job that has no name yet (a bad line) is its line alone */
    snprintf(label, sizeof label, j->name[0] ? "line %d (%s)" : "line %d", j->line, j->name);
    if (error) fprintf(stderr, "matex batch: %s: failed: %s\n", label, error);
    else if (!r->a->quiet) fprintf(stderr, "matex batch: %s: %s (%.2f s)\n", label, STATUS_NAME[status], seconds);
}

/* --theme-from-first: the first job writes front.png, the style image of every later job whose line
 * gives none (their options borrow a->theme_path). */
static void theme_from_first(batch_args *a, mx_batch_manifest *m) {
    if (!m->njobs) return;
    mx_batch_job *first = &m->jobs[0];
    first->c.o.front_render = 1;
    snprintf(a->theme_path, sizeof a->theme_path, "%s/%s/front.png", a->outroot, first->name);
    for (int i = 1; i < m->njobs; i++)
        if (!m->jobs[i].c.o.style_images[0]) m->jobs[i].c.o.style_images[0] = a->theme_path;
}

/* A later job of --theme-from-first needs the first job's front.png (the message says where it comes from). */
static int theme_missing(const batch_run *r, const mx_batch_job *j, char *error, size_t cap) {
    const batch_args *a = r->a;
    struct stat sb;
    if (!a->theme_from_first || j->index == 0 || j->c.o.style_images[0] != a->theme_path || !stat(a->theme_path, &sb))
        return 0;
    snprintf(error, cap,
             "%s: the theme image is not there: the first job of the manifest writes it (with --theme-from-first; "
             "run its shard first, or remove its folder if it was made without the option)",
             a->theme_path);
    return 1;
}

static void batch_job(batch_run *r, const mx_batch_job *j) {
    char theme_error[4400];
    if (theme_missing(r, j, theme_error, sizeof theme_error)) {
        record_failure(r, j, theme_error);
        add_result(r, j, JOB_FAILED, 0.0, 0.0, theme_error);
        return;
    }
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
    if (!r->client && !r->models && !(r->models = matex_models_open(r->a->weights, &r->a->table.o, &err))) {
        fprintf(stderr, "matex batch: %s\n", err.message);
        r->fatal = 1;
        return;
    }
    double t = mx_now(), coverage = 0.0;
    char error[1024];
    mx_cli_signals_output(j->c.o.out_dir);
    int rc = r->client ? mx_serve_client_run(r->client, r->a->manifest, j, r->a->defaults, r->a->ndefaults, r->stop,
                                             &coverage, error, sizeof error)
                       : run_job(r, j, &coverage, error, sizeof error);
    mx_cli_signals_output(NULL); /* the job's folder and lock are its own no more */
    if (rc < 0) record_failure(r, j, error);
    add_result(r, j, rc == 0 ? JOB_DONE : rc > 0 ? JOB_INTERRUPTED : JOB_FAILED, mx_now() - t, coverage,
               rc < 0 ? error : NULL);
}

static void print_summary(const batch_run *r, int jobs, double seconds) {
    const batch_args *a = r->a;
    double per_job = r->count[JOB_DONE] ? r->job_seconds / r->count[JOB_DONE] : 0.0;
    if (!a->json) {
        printf("matex batch: shard %d/%d, %d job%s: %d done, %d skipped, %d failed%s; %.2f s per job done, %.2f s in all\n",
               a->shard, a->nshards, jobs, jobs == 1 ? "" : "s", r->count[JOB_DONE], r->count[JOB_SKIPPED], r->count[JOB_FAILED],
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
    struct stat sb;
    int made_root = stat(a.outroot, &sb) != 0; /* removed at the end if still empty (rmdir: never a file in it) */
    if (mx_make_folders(a.outroot, 0777, &st) || mx_batch_manifest_read(&m, a.manifest, a.defaults, a.ndefaults, a.outroot, a.shard, a.nshards, &st)) {
        fprintf(stderr, "matex batch: %s\n", st.msg);
        if (made_root) rmdir(a.outroot);
        return 1;
    }
    if (a.theme_from_first) theme_from_first(&a, &m);
    mx_serve_client client;
    if (a.server && mx_serve_client_open(&client, a.server, a.token_file, &st)) {
        fprintf(stderr, "matex batch: %s\n", st.msg);
        mx_batch_manifest_free(&m);
        return st.code == MX_EUSAGE ? 2 : 1;
    }
    batch_run r = {&a, NULL, a.server ? &client : NULL, 0, {0}, 0.0, {0}, mx_cli_signals_catch()};
    forget_own_failures(&r, &m);
    double t0 = mx_now();
    int jobs = 0;
    for (int i = 0; i < m.njobs; i++) jobs += m.jobs[i].index % a.nshards == a.shard;
    for (int i = 0; i < m.njobs && !*r.stop && !r.fatal; i++)
        if (m.jobs[i].index % a.nshards == a.shard) batch_job(&r, &m.jobs[i]);
    if (!r.fatal) print_summary(&r, jobs, mx_now() - t0);
    matex_models_close(r.models);
    mx_batch_manifest_free(&m);
    mx_buf_free(&r.results);
    if (made_root) rmdir(a.outroot); /* an interrupt before the first job wrote anything */
    if (r.fatal) return 1;
    return *r.stop || r.count[JOB_INTERRUPTED] ? 130 : r.count[JOB_FAILED] ? 1 : 0;
}
