#include "serve_jobs.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../../../runtime/atomic_file.h"
#include "../../../runtime/fileio.h"
#include "../cli_batch_manifest.h"
#include "../cli_progress.h"
#include "serve_zip.h"

#define MARKER ".matex-serve"
#define INCOMING ".incoming"
#define OPTIONS_MAX_BYTES ((size_t)64 << 10)

static const char *const STATE_NAME[] = {"queued", "running", "done", "failed", "cancelled"};

const char *mx_serve_state_name(mx_job_state s) { return s < MX_JOB_NONE ? STATE_NAME[s] : "none"; }

void mx_serve_jobs_path(const mx_serve_jobs *q, const char *id, const char *name, char out[4200]) {
    /* the folder is at most 4031 bytes (mx_serve_jobs_open), ids 40, the server's own names 64 */
    snprintf(out, 4200, "%.4031s/%.40s%s%.64s", q->dir, id, name ? "/" : "", name ? name : "");
}

/* ---- small files ---- */

/* A file of at most cap-1 bytes into buf (NUL-ended, final newline dropped); -1 when unreadable. */
static int read_small(const char *path, char *buf, size_t cap) {
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    ssize_t n = fd < 0 ? -1 : read(fd, buf, cap - 1);
    if (fd >= 0) close(fd);
    if (n < 0) return -1;
    buf[n] = 0;
    if (n > 0 && buf[n - 1] == '\n') buf[n - 1] = 0;
    return 0;
}

static int write_small(const mx_serve_jobs *q, const char *id, const char *name, const char *text) {
    char path[4200];
    mx_status st;
    mx_serve_jobs_path(q, id, name, path);
    return mx_atomic_write(path, text, strlen(text), &st);
}

mx_job_state mx_serve_jobs_state(mx_serve_jobs *q, const char *id) {
    char path[4200], word[32];
    mx_serve_jobs_path(q, id, "state", path);
    if (read_small(path, word, sizeof word)) return MX_JOB_NONE;
    for (int s = 0; s < MX_JOB_NONE; s++)
        if (!strcmp(word, STATE_NAME[s])) return (mx_job_state)s;
    return MX_JOB_NONE;
}

static int set_state(const mx_serve_jobs *q, const char *id, mx_job_state s) {
    char text[32];
    snprintf(text, sizeof text, "%s\n", STATE_NAME[s]);
    return write_small(q, id, "state", text);
}

static int attempts_of(const mx_serve_jobs *q, const char *id) {
    char path[4200], text[32];
    mx_serve_jobs_path(q, id, "attempts", path);
    return read_small(path, text, sizeof text) ? 0 : atoi(text);
}

/* failed, with the reason in the job's "error" file */
static void set_failed(const mx_serve_jobs *q, const char *id, const char *why) {
    char text[1100];
    snprintf(text, sizeof text, "%s\n", why);
    write_small(q, id, "error", text);
    set_state(q, id, MX_JOB_FAILED);
}

/* ---- folders ---- */

static int remove_entry(const char *path, const struct stat *sb, int flag, struct FTW *ftw) {
    (void)sb, (void)ftw;
    return flag == FTW_DP ? rmdir(path) : unlink(path);
}

/* rm -r without following links (nftw FTW_PHYS); only ever called on the server's own paths. */
static void remove_tree(const char *path) { nftw(path, remove_entry, 16, FTW_DEPTH | FTW_PHYS); }

/* The space a folder takes (links not followed), by blocks as du counts them. */
static uint64_t tree_bytes(int at, const char *name) {
    struct stat sb;
    if (fstatat(at, name, &sb, AT_SYMLINK_NOFOLLOW)) return 0;
    uint64_t bytes = (uint64_t)sb.st_blocks * 512u;
    int fd = S_ISDIR(sb.st_mode) ? openat(at, name, O_RDONLY | O_DIRECTORY | O_CLOEXEC | O_NOFOLLOW) : -1;
    DIR *d = fd >= 0 ? fdopendir(fd) : NULL;
    struct dirent *e;
    while (d && (e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) bytes += tree_bytes(dirfd(d), e->d_name);
    if (d) closedir(d);
    else if (fd >= 0) close(fd);
    return bytes;
}

static int is_job_entry(const struct dirent *d) { return mx_serve_id_valid(d->d_name); }

/* The job ids, oldest first (free each and the array); the count, or -1. */
static int job_ids(const mx_serve_jobs *q, struct dirent ***ids) { return scandir(q->dir, ids, is_job_entry, alphasort); }

static void free_ids(struct dirent **ids, int n) {
    for (int i = 0; i < n; i++) free(ids[i]);
    free(ids);
}

static int count_active(mx_serve_jobs *q) {
    struct dirent **ids;
    int n = job_ids(q, &ids), active = 0;
    for (int i = 0; i < n; i++) {
        mx_job_state s = mx_serve_jobs_state(q, ids[i]->d_name);
        active += s == MX_JOB_QUEUED || s == MX_JOB_RUNNING;
    }
    if (n >= 0) free_ids(ids, n);
    return active;
}

/* ---- open, close ---- */

static int folder_is_empty(const char *path) {
    DIR *d = opendir(path);
    struct dirent *e;
    int empty = d != NULL;
    while (d && empty && (e = readdir(d))) empty = !strcmp(e->d_name, ".") || !strcmp(e->d_name, "..");
    if (d) closedir(d);
    return empty;
}

/* The folder is the server's: marked, or empty (then marked now). */
static int claim_folder(const mx_serve_jobs *q, mx_status *st) {
    char marker[4200];
    struct stat sb;
    snprintf(marker, sizeof marker, "%s/%s", q->dir, MARKER);
    if (lstat(q->dir, &sb) || !S_ISDIR(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: not a folder", q->dir);
    if (!lstat(marker, &sb)) return S_ISREG(sb.st_mode) ? 0 : mx_fail(st, MX_EINPUT, "%s: not a file", marker);
    if (!folder_is_empty(q->dir))
        return mx_fail(st, MX_EINPUT, "%s: not a jobs folder of matex serve (it has files and no %s): give an empty or new folder",
                       q->dir, MARKER);
    static const char text[] = "matex serve jobs folder: its jobs, their uploads and outputs\n";
    return mx_atomic_write(marker, text, sizeof text - 1, st);
}

static int lock_folder(mx_serve_jobs *q, mx_status *st) {
    char path[4200];
    snprintf(path, sizeof path, "%s/.lock", q->dir);
    q->lock_fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0600);
    if (q->lock_fd < 0) return mx_fail(st, MX_EIO, "%s: cannot open: %s", path, strerror(errno));
    if (!flock(q->lock_fd, LOCK_EX | LOCK_NB)) return 0;
    close(q->lock_fd);
    q->lock_fd = -1;
    return mx_fail(st, MX_EINPUT, "%s: another matex serve uses this jobs folder", q->dir);
}

/* Jobs an earlier server left running run again once, then fail. */
static void recover_running(mx_serve_jobs *q) {
    struct dirent **ids;
    int n = job_ids(q, &ids);
    for (int i = 0; i < n; i++) {
        const char *id = ids[i]->d_name;
        if (mx_serve_jobs_state(q, id) != MX_JOB_RUNNING) continue;
        if (attempts_of(q, id) >= MX_SERVE_MAX_ATTEMPTS)
            set_failed(q, id, "the server stopped while running this job, twice (killed or crashed): not run again");
        else set_state(q, id, MX_JOB_QUEUED);
    }
    if (n >= 0) free_ids(ids, n);
}

int mx_serve_jobs_open(mx_serve_jobs *q, const char *dir, const mx_serve_limits *limits, mx_status *st) {
    memset(q, 0, sizeof *q);
    q->lock_fd = -1;
    q->limits = *limits;
    if ((size_t)snprintf(q->dir, sizeof q->dir, "%s", dir) >= sizeof q->dir - 64) return mx_fail(st, MX_EINPUT, "%s: path too long", dir);
    if (mx_make_folders(dir, 0700, st) || claim_folder(q, st) || lock_folder(q, st)) return -1;
    char incoming[4200];
    snprintf(incoming, sizeof incoming, "%s/%s", q->dir, INCOMING);
    remove_tree(incoming);
    if (mkdir(incoming, 0700)) {
        mx_serve_jobs_close(q);
        return mx_fail(st, MX_EIO, "%s: cannot create folder: %s", incoming, strerror(errno));
    }
    recover_running(q);
    pthread_mutex_init(&q->mu, NULL);
    pthread_cond_init(&q->wake, NULL);
    return 0;
}

void mx_serve_jobs_close(mx_serve_jobs *q) {
    if (q->lock_fd < 0) return;
    close(q->lock_fd);
    q->lock_fd = -1;
    pthread_mutex_destroy(&q->mu);
    pthread_cond_destroy(&q->wake);
}

/* ---- submission ---- */

static void stage_path(const mx_serve_jobs *q, const char *id, char out[4200]) {
    snprintf(out, 4200, "%s/%s/%s", q->dir, INCOMING, id);
}

static int queue_full(mx_serve_jobs *q, mx_serve_error *e) {
    if (count_active(q) < q->limits.max_queued) return 0;
    return mx_serve_fail(e, 429, "queue_full", "the queue is full (%d jobs waiting or running): try again later",
                         q->limits.max_queued);
}

int mx_serve_jobs_stage(mx_serve_jobs *q, char id[MX_SERVE_ID_MAX + 1], char stage[4200], mx_serve_error *e) {
    pthread_mutex_lock(&q->mu);
    int rc = queue_full(q, e);
    if (!rc) {
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        uint64_t ms = (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
        if (ms <= q->last_ms) ms = q->last_ms, q->counter++; /* the same millisecond, or a clock step back */
        else q->last_ms = ms, q->counter = 0;
        snprintf(id, MX_SERVE_ID_MAX + 1, "%012llx%04x", (unsigned long long)ms, q->counter & 0xffffu);
        stage_path(q, id, stage);
        if (mkdir(stage, 0700)) rc = mx_serve_fail(e, 503, "storage", "cannot create the upload folder: %s", strerror(errno));
    }
    pthread_mutex_unlock(&q->mu);
    return rc;
}

void mx_serve_jobs_unstage(mx_serve_jobs *q, const char *id) {
    char stage[4200];
    stage_path(q, id, stage);
    remove_tree(stage);
}

static int sync_path(const char *path) {
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    int bad = fd < 0 || fsync(fd);
    if (fd >= 0) close(fd);
    return bad ? -1 : 0;
}

/* fsync of every file of a flat folder and of the folder itself. */
static int sync_folder(const char *path) {
    DIR *d = opendir(path);
    struct dirent *e;
    int bad = d == NULL;
    while (d && (e = readdir(d))) {
        int fd = e->d_name[0] == '.' ? -1 : openat(dirfd(d), e->d_name, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
        if (fd >= 0) bad |= fsync(fd), close(fd);
    }
    if (d) bad |= fsync(dirfd(d)), closedir(d);
    return bad ? -1 : 0;
}

int mx_serve_jobs_commit(mx_serve_jobs *q, const char *id, mx_serve_error *e) {
    char stage[4200], final[4200], state[4300];
    stage_path(q, id, stage);
    mx_serve_jobs_path(q, id, NULL, final);
    snprintf(state, sizeof state, "%s/state", stage);
    mx_status st;
    pthread_mutex_lock(&q->mu);
    int rc = queue_full(q, e);
    if (!rc && (mx_atomic_write(state, "queued\n", 7, &st) || sync_folder(stage) || rename(stage, final) ||
                sync_path(q->dir)))
        rc = mx_serve_fail(e, 503, "storage", "cannot store the job in the jobs folder: %s", strerror(errno));
    if (!rc) pthread_cond_signal(&q->wake);
    pthread_mutex_unlock(&q->mu);
    if (rc) mx_serve_jobs_unstage(q, id);
    return rc;
}

/* ---- queries ---- */

/* The last line of the job's events.jsonl into b as a JSON value (null when none). */
static void latest_progress(const mx_serve_jobs *q, const char *id, mx_buf *b) {
    char path[4200], tail[4096];
    mx_serve_jobs_path(q, id, "events.jsonl", path);
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    struct stat sb;
    ssize_t n = -1;
    if (fd >= 0 && !fstat(fd, &sb)) {
        off_t at = sb.st_size > (off_t)sizeof tail - 1 ? sb.st_size - (off_t)sizeof tail + 1 : 0;
        n = pread(fd, tail, sizeof tail - 1, at);
    }
    if (fd >= 0) close(fd);
    while (n > 0 && tail[n - 1] == '\n') n--;
    ssize_t start = n;
    while (start > 0 && tail[start - 1] != '\n') start--;
    if (n > 0 && tail[start] == '{') mx_buf_printf(b, "%.*s", (int)(n - start), tail + start);
    else mx_buf_printf(b, "null");
}

static int is_output_file(const struct dirent *d) { return mx_serve_name_valid(d->d_name); }

static void output_files(const mx_serve_jobs *q, const char *id, mx_buf *b) {
    char out[4200];
    struct dirent **names;
    mx_serve_jobs_path(q, id, "out", out);
    int n = scandir(out, &names, is_output_file, alphasort);
    mx_buf_printf(b, "[");
    for (int i = 0; i < n; i++) {
        mx_buf_printf(b, "%s", i ? "," : "");
        mx_buf_json_str(b, names[i]->d_name);
    }
    mx_buf_printf(b, "]");
    if (n >= 0) free_ids(names, n);
}

static int describe(mx_serve_jobs *q, const char *id, mx_buf *b) {
    mx_job_state s = mx_serve_jobs_state(q, id);
    if (s == MX_JOB_NONE) return -1;
    mx_buf_printf(b, "{\"id\":\"%s\",\"state\":\"%s\",\"attempts\":%d,\"progress\":", id, STATE_NAME[s], attempts_of(q, id));
    latest_progress(q, id, b);
    char path[4200], error[1100];
    mx_serve_jobs_path(q, id, "error", path);
    if (s == MX_JOB_FAILED && !read_small(path, error, sizeof error)) {
        mx_buf_printf(b, ",\"error\":");
        mx_buf_json_str(b, error);
    }
    if (s == MX_JOB_DONE) {
        mx_buf_printf(b, ",\"files\":");
        output_files(q, id, b);
    }
    mx_buf_printf(b, "}");
    return 0;
}

/* Under the mutex: a job reads as finished only once finish_job has also removed the finished
 * jobs beyond the retention limits (a client that sees "done" sees the retention applied). */
int mx_serve_jobs_describe(mx_serve_jobs *q, const char *id, mx_buf *out, mx_serve_error *e) {
    pthread_mutex_lock(&q->mu);
    int rc = describe(q, id, out);
    pthread_mutex_unlock(&q->mu);
    return rc ? mx_serve_fail(e, 404, "not_found", "no job %s", id) : 0;
}

void mx_serve_jobs_list(mx_serve_jobs *q, mx_buf *out) {
    struct dirent **ids;
    int n = job_ids(q, &ids), listed = 0;
    mx_buf_printf(out, "{\"jobs\":[");
    for (int i = 0; i < n; i++) {
        size_t at = out->len;
        if (listed) mx_buf_printf(out, ",");
        if (describe(q, ids[i]->d_name, out)) out->len = at; /* removed meanwhile */
        else listed++;
    }
    mx_buf_printf(out, "]}");
    if (n >= 0) free_ids(ids, n);
}

int mx_serve_jobs_delete(mx_serve_jobs *q, const char *id, int *status, mx_buf *out, mx_serve_error *e) {
    pthread_mutex_lock(&q->mu);
    mx_job_state s = mx_serve_jobs_state(q, id);
    int rc = 0;
    if (s == MX_JOB_NONE) rc = mx_serve_fail(e, 404, "not_found", "no job %s", id);
    else if (s == MX_JOB_QUEUED) {
        set_state(q, id, MX_JOB_CANCELLED);
        *status = 200;
        mx_buf_printf(out, "{\"id\":\"%s\",\"state\":\"cancelled\"}", id);
    } else if (s == MX_JOB_RUNNING) {
        if (!strcmp(q->running, id)) q->cancel = 1;
        *status = 202;
        mx_buf_printf(out, "{\"id\":\"%s\",\"state\":\"running\",\"cancelling\":true}", id);
    } else {
        char path[4200];
        mx_serve_jobs_path(q, id, NULL, path);
        remove_tree(path);
        *status = 200;
        mx_buf_printf(out, "{\"id\":\"%s\",\"state\":\"%s\",\"removed\":true}", id, STATE_NAME[s]);
    }
    pthread_mutex_unlock(&q->mu);
    return rc;
}

int mx_serve_jobs_open_file(mx_serve_jobs *q, const char *id, const char *name, int *fd, uint64_t *size,
                            mx_serve_error *e) {
    mx_job_state s = mx_serve_jobs_state(q, id);
    if (s == MX_JOB_NONE) return mx_serve_fail(e, 404, "not_found", "no job %s", id);
    if (s != MX_JOB_DONE)
        return mx_serve_fail(e, 409, "not_done", "job %s is %s: its files come when it is done", id, STATE_NAME[s]);
    char out[4200];
    struct stat sb;
    mx_serve_jobs_path(q, id, "out", out);
    int dfd = open(out, O_RDONLY | O_DIRECTORY | O_CLOEXEC | O_NOFOLLOW);
    *fd = dfd < 0 ? -1 : openat(dfd, name, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (dfd >= 0) close(dfd);
    if (*fd >= 0 && !fstat(*fd, &sb) && S_ISREG(sb.st_mode)) {
        *size = (uint64_t)sb.st_size;
        return 0;
    }
    if (*fd >= 0) close(*fd);
    return mx_serve_fail(e, 404, "not_found", "job %s has no file %s", id, name);
}

/* ---- the worker ---- */

/* The oldest queued job into id; 0, or -1 when none. */
static int next_queued(mx_serve_jobs *q, char id[MX_SERVE_ID_MAX + 1]) {
    struct dirent **ids;
    int n = job_ids(q, &ids), found = -1;
    for (int i = 0; i < n && found; i++)
        if (mx_serve_jobs_state(q, ids[i]->d_name) == MX_JOB_QUEUED) found = 0, snprintf(id, MX_SERVE_ID_MAX + 1, "%.40s", ids[i]->d_name);
    if (n >= 0) free_ids(ids, n);
    return found;
}

/* What an interrupted run left in the job's folder: the output folder, its staging folder and lock. */
static void clear_outputs(const mx_serve_jobs *q, const char *id) {
    char dir[4200], path[4500];
    mx_serve_jobs_path(q, id, NULL, dir);
    DIR *d = opendir(dir);
    struct dirent *e;
    while (d && (e = readdir(d)))
        if (!strcmp(e->d_name, "out") || !strncmp(e->d_name, "out.", 4)) {
            snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
            remove_tree(path);
        }
    if (d) closedir(d);
}

static int is_style_entry(const struct dirent *d) { return !strncmp(d->d_name, "style_", 6); }

/* The mesh of a job sent as a zip: the path inside the job folder that MX_SERVE_ZIP_MESH_FILE
 * names (checked again as an entry name). */
static int find_zip_mesh(const char *dir, char mesh[4200]) {
    char path[4300], rel[MX_SERVE_ZIP_NAME_MAX + sizeof MX_SERVE_ZIP_DIR + 2];
    snprintf(path, sizeof path, "%.4100s/" MX_SERVE_ZIP_MESH_FILE, dir);
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    ssize_t n = fd < 0 ? -1 : read(fd, rel, sizeof rel - 1);
    if (fd >= 0) close(fd);
    if (n <= 0) return -1;
    rel[n] = 0;
    if (strncmp(rel, MX_SERVE_ZIP_DIR "/", sizeof MX_SERVE_ZIP_DIR) || !mx_serve_zip_name_valid(rel + sizeof MX_SERVE_ZIP_DIR))
        return -1;
    snprintf(mesh, 4200, "%.3900s/%.270s", dir, rel);
    return 0;
}

/* The job's inputs as stored at submission: mesh.EXT (or a zip's mesh) and style_K.EXT (K in order). */
static int find_inputs(const mx_serve_jobs *q, const char *id, char mesh[4200], char styles[][4200], int *nstyle) {
    char dir[4200];
    mx_serve_jobs_path(q, id, NULL, dir);
    static const char *const kinds[] = {"obj", "ply", "stl", "off", "glb"};
    struct stat sb;
    mesh[0] = 0;
    for (size_t k = 0; k < sizeof kinds / sizeof kinds[0] && !mesh[0]; k++) {
        snprintf(mesh, 4200, "%.4100s/mesh.%s", dir, kinds[k]);
        if (lstat(mesh, &sb)) mesh[0] = 0;
    }
    if (!mesh[0] && find_zip_mesh(dir, mesh)) mesh[0] = 0;
    struct dirent **names;
    int n = scandir(dir, &names, is_style_entry, alphasort);
    *nstyle = 0;
    for (int i = 0; i < n && *nstyle < MATEX_MAX_STYLE_IMAGES; i++)
        snprintf(styles[(*nstyle)++], 4200, "%.4100s/%.64s", dir, names[i]->d_name);
    if (n >= 0) free_ids(names, n);
    return mesh[0] ? 0 : -1;
}

/* Runs one job: 0 done, 1 cancelled, -1 failed (why in error). */
static int run_job(mx_serve_jobs *q, matex_models *m, const char *id, char *error, size_t cap) {
    char mesh[4200], styles[MATEX_MAX_STYLE_IMAGES][4200], options[4200], out[4200], events[4200];
    const char *style_list[MATEX_MAX_STYLE_IMAGES];
    int nstyle;
    mx_status st;
    size_t len;
    clear_outputs(q, id);
    mx_serve_jobs_path(q, id, "options.json", options);
    mx_serve_jobs_path(q, id, "out", out);
    mx_serve_jobs_path(q, id, "events.jsonl", events);
    if (find_inputs(q, id, mesh, styles, &nstyle)) return snprintf(error, cap, "the job's mesh is missing"), -1;
    for (int i = 0; i < nstyle; i++) style_list[i] = styles[i];
    char *text = mx_read_file(options, OPTIONS_MAX_BYTES, &len, &st);
    if (!text) return snprintf(error, cap, "%s", st.msg), -1;
    mx_batch_job j;
    int rc = mx_batch_job_from_options(&j, text, len, mesh, out, style_list, nstyle);
    free(text);
    FILE *ev = rc ? NULL : fopen(events, "we");
    if (rc) snprintf(error, cap, "options: %.900s", j.error);
    else if (!ev) rc = -1, snprintf(error, cap, "%.900s: cannot write: %s", events, strerror(errno));
    else {
        matex_options o = j.c.o;
        matex_error err;
        o.verbose = 0;
        o.progress = mx_cli_progress_api_event;
        o.progress_user = ev;
        o.cancel = &q->cancel;
        rc = matex_texture(m, &o, NULL, &err);
        if (rc) rc = err.code == MATEX_ECANCELLED ? 1 : -1, snprintf(error, cap, "%s", err.message);
        fclose(ev);
    }
    mx_batch_job_free(&j);
    return rc;
}

/* Finished jobs beyond the count or the size the server keeps, oldest first (the newest stays). */
static void prune_finished(mx_serve_jobs *q) {
    struct dirent **ids;
    int n = job_ids(q, &ids), finished = 0;
    uint64_t bytes = 0;
    char path[4200];
    for (int i = n - 1; i >= 0; i--) {
        mx_job_state s = mx_serve_jobs_state(q, ids[i]->d_name);
        if (s != MX_JOB_DONE && s != MX_JOB_FAILED && s != MX_JOB_CANCELLED) continue;
        mx_serve_jobs_path(q, ids[i]->d_name, NULL, path);
        bytes += tree_bytes(AT_FDCWD, path);
        if (++finished > 1 && (finished > q->limits.keep_jobs || bytes > q->limits.keep_bytes)) remove_tree(path);
    }
    if (n >= 0) free_ids(ids, n);
}

/* The state a finished run leaves (called under the mutex). */
static void finish_job(mx_serve_jobs *q, const char *id, int rc, const char *error) {
    if (rc == 0) set_state(q, id, MX_JOB_DONE);
    else if (rc > 0 && q->requeue) set_state(q, id, MX_JOB_QUEUED);
    else if (rc > 0) set_state(q, id, MX_JOB_CANCELLED);
    else set_failed(q, id, error);
    q->running[0] = 0;
    prune_finished(q);
}

void mx_serve_jobs_work(mx_serve_jobs *q, matex_models *m) {
    pthread_mutex_lock(&q->mu);
    while (!q->stop) {
        char id[MX_SERVE_ID_MAX + 1], error[1024] = "", text[32];
        if (next_queued(q, id)) {
            struct timespec until;
            clock_gettime(CLOCK_REALTIME, &until);
            until.tv_sec += 1;
            pthread_cond_timedwait(&q->wake, &q->mu, &until);
            continue;
        }
        snprintf(text, sizeof text, "%d\n", attempts_of(q, id) + 1);
        if (write_small(q, id, "attempts", text) || set_state(q, id, MX_JOB_RUNNING)) {
            set_failed(q, id, "cannot record the job's state in the jobs folder");
            continue;
        }
        snprintf(q->running, sizeof q->running, "%s", id);
        q->cancel = 0;
        pthread_mutex_unlock(&q->mu);
        int rc = run_job(q, m, id, error, sizeof error);
        pthread_mutex_lock(&q->mu);
        finish_job(q, id, rc, error);
    }
    pthread_mutex_unlock(&q->mu);
}

void mx_serve_jobs_stop(mx_serve_jobs *q, int cancel_running) {
    pthread_mutex_lock(&q->mu);
    q->stop = 1;
    if (cancel_running && q->running[0]) q->requeue = 1, q->cancel = 1;
    pthread_cond_signal(&q->wake);
    pthread_mutex_unlock(&q->mu);
}
