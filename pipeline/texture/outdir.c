#include "outdir.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../runtime/atomic_file.h"
#include "../../runtime/buf.h"
#include "../../runtime/fileio.h"
#include "../io/export.h"

#define MARKER_HEADER "matex output folder: `--force` may replace it. The files matex wrote here:\n"
/* The marker of a staging folder from its creation until write_marker replaces it: a staging folder
 * left by a killed process is recognised as matex's by it (remove_stale_stages). */
#define STAGE_HEADER "matex staging folder: removed when its process has ended\n"
#define MARKER_MAX_BYTES (1 << 20)
#define MAX_SUBFOLDER_DEPTH 4 /* an output inside an output (demo/spot/views): how deep --force looks */

static int remove_entry(const char *path, const struct stat *sb, int type, struct FTW *ftw) {
    (void)sb, (void)type, (void)ftw;
    remove(path);
    return 0;
}

/* rm -r without following links (FTW_PHYS): a link inside is removed, never its target. */
static void remove_tree(const char *dir) { nftw(dir, remove_entry, 16, FTW_DEPTH | FTW_PHYS); }

static int make_folder(const char *path, mx_status *st) {
    if (mkdir(path, 0777) && errno != EEXIST)
        return mx_fail(st, MX_EIO, "%s: cannot create folder: %s", path, strerror(errno));
    return 0;
}

/* mkdir -p of the folder that will hold `dir` (its parent). */
static int make_parents(const char *dir, mx_status *st) {
    char path[4096];
    snprintf(path, sizeof path, "%s", dir);
    char *slash = strrchr(path, '/');
    if (!slash || slash == path) return 0;
    *slash = 0;
    for (char *p = path + 1; *p; p++) {
        if (*p != '/') continue;
        *p = 0;
        if (make_folder(path, st)) return -1;
        *p = '/';
    }
    return make_folder(path, st);
}

/* What an existing folder holds: 0 nothing, 1 only files (or links), 2 a sub-folder; -1 unreadable. */
static int folder_content(const char *dir, mx_status *st) {
    DIR *d = opendir(dir);
    if (!d) return mx_fail(st, MX_EIO, "%s: cannot read folder: %s", dir, strerror(errno));
    struct dirent *e;
    int content = 0;
    while (content < 2 && (e = readdir(d)) != NULL) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        struct stat sb;
        int is_dir = fstatat(dirfd(d), e->d_name, &sb, AT_SYMLINK_NOFOLLOW) == 0 && S_ISDIR(sb.st_mode);
        content = is_dir ? 2 : 1;
    }
    closedir(d);
    return content;
}

/* od->dir: an existing path resolved (links, ".", trailing "/"), a new one without trailing "/". */
static int resolve_dir(mx_outdir *od, const char *dir, mx_status *st) {
    struct stat sb;
    if (stat(dir, &sb) == 0) {
        char *real = realpath(dir, NULL);
        if (!real) return mx_fail(st, MX_EIO, "%s: cannot resolve the path: %s", dir, strerror(errno));
        int n = snprintf(od->dir, sizeof od->dir, "%s", real);
        free(real);
        if (n < 0 || (size_t)n >= sizeof od->dir) return mx_fail(st, MX_EINPUT, "%s: path too long", dir);
        if (!S_ISDIR(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: exists and is not a folder", dir);
        if (!strcmp(od->dir, "/")) return mx_fail(st, MX_EINPUT, "%s: the root folder cannot be an output folder", dir);
        od->exists = 1;
        return 0;
    }
    if (errno != ENOENT) return mx_fail(st, MX_EIO, "%s: %s", dir, strerror(errno));
    int n = snprintf(od->dir, sizeof od->dir, "%s", dir);
    if (n < 0 || (size_t)n >= sizeof od->dir) return mx_fail(st, MX_EINPUT, "%s: path too long", dir);
    while (n > 1 && od->dir[n - 1] == '/') od->dir[--n] = 0;
    return 0;
}

/* An existing folder must be replaceable by a rename from its parent: not a mount point. */
static int check_same_device(const mx_outdir *od, const char *given, mx_status *st) {
    struct stat a, b;
    if (stat(od->dir, &a) || stat(od->stage, &b)) return mx_fail(st, MX_EIO, "%s: %s", given, strerror(errno));
    if (a.st_dev != b.st_dev)
        return mx_fail(st, MX_EINPUT,
                       "%s: is a mount point (another file system than its parent), so it cannot be replaced "
                       "atomically; give a folder inside it",
                       given);
    return 0;
}

/* Is the resolved path `path` the folder `dir` or inside it? */
static int path_within(const char *path, const char *dir) {
    size_t n = strlen(dir);
    return !strncmp(path, dir, n) && (path[n] == 0 || path[n] == '/');
}

/* Is `file` (or, for a link, the link itself: its folder resolved) inside `dir`? */
static int file_within(const char *file, const char *dir) {
    char *real = realpath(file, NULL);
    int inside = real && path_within(real, dir);
    free(real);
    char folder[4096];
    snprintf(folder, sizeof folder, "%s", file);
    char *slash = strrchr(folder, '/');
    if (slash == folder) folder[1] = 0;
    else if (slash) *slash = 0;
    else snprintf(folder, sizeof folder, ".");
    real = realpath(folder, NULL);
    inside = inside || (real && path_within(real, dir));
    free(real);
    return inside;
}

/* An existing output folder is replaced by a new one, so it must not be (or hold) the current
 * folder, nor hold a file the run reads. */
static int check_holds_nothing_needed(const mx_outdir *od, const char *given, const char *const *inputs, int ninputs,
                                      mx_status *st) {
    char *cwd = realpath(".", NULL);
    int holds_cwd = cwd && path_within(cwd, od->dir);
    free(cwd);
    if (holds_cwd)
        return mx_fail(st, MX_EINPUT, "%s: is the current folder (or holds it), which an output folder cannot be; give another",
                       given);
    for (int i = 0; i < ninputs; i++)
        if (inputs[i] && file_within(inputs[i], od->dir))
            return mx_fail(st, MX_EINPUT, "%s: holds the input %s, which an output folder cannot; give another", given,
                           inputs[i]);
    return 0;
}

/* Is `name` one of the lines of the marker text? */
static int marker_lists(const char *marker, const char *name) {
    size_t n = strlen(name);
    for (const char *p = strstr(marker, name); p; p = strstr(p + 1, name))
        if (p > marker && p[-1] == '\n' && p[n] == '\n') return 1;
    return 0;
}

/* The marker of `dir` when it starts with `header`, else NULL (the caller frees it). */
static char *read_marker(const char *dir, const char *header) {
    char path[4300];
    snprintf(path, sizeof path, "%s/%s", dir, MX_OUTDIR_MARKER);
    mx_status ignored;
    char *marker = mx_read_file(path, MARKER_MAX_BYTES, NULL, &ignored);
    if (marker && strncmp(marker, header, strlen(header))) {
        free(marker);
        return NULL;
    }
    return marker;
}

/* Is the entry `name` of the folder listed by its marker and matex's: a plain file listed as
 * "name", or a sub-folder listed as "name/" that is itself a folder matex wrote (an output written
 * into an output, as `make demo`'s views/)? */
static int check_written_by_matex_at(const char *dir, const char *given, int depth, mx_status *st);

static int entry_written_by_matex(DIR *d, const char *dir, const char *marker, const char *name, int depth) {
    struct stat sb;
    if (fstatat(dirfd(d), name, &sb, AT_SYMLINK_NOFOLLOW)) return 0;
    if (S_ISREG(sb.st_mode)) return marker_lists(marker, name);
    char listed[300], sub[4400];
    snprintf(listed, sizeof listed, "%s/", name);
    snprintf(sub, sizeof sub, "%s/%s", dir, name);
    mx_status ignored;
    return S_ISDIR(sb.st_mode) && depth < MAX_SUBFOLDER_DEPTH && marker_lists(marker, listed) &&
           check_written_by_matex_at(sub, sub, depth + 1, &ignored) == 0;
}

/* --force replaces only what matex wrote: a folder with the marker, every entry of which the marker
 * lists (entry_written_by_matex). Anything else (an older matex's output included) is refused, with why. */
static int check_written_by_matex(const char *dir, const char *given, mx_status *st) {
    return check_written_by_matex_at(dir, given, 0, st);
}

static int check_written_by_matex_at(const char *dir, const char *given, int depth, mx_status *st) {
    char *marker = read_marker(dir, MARKER_HEADER);
    if (!marker) {
        return mx_fail(st, MX_EINPUT,
                       "%s: was not written by matex (no %s in it): --force replaces only a folder of matex's own output; "
                       "empty it yourself or give another folder",
                       given, MX_OUTDIR_MARKER);
    }
    DIR *d = opendir(dir);
    if (!d) {
        free(marker);
        return mx_fail(st, MX_EIO, "%s: cannot read folder: %s", given, strerror(errno));
    }
    int rc = 0;
    struct dirent *e;
    while (!rc && (e = readdir(d)) != NULL) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..") || !strcmp(e->d_name, MX_OUTDIR_MARKER)) continue;
        if (!entry_written_by_matex(d, dir, marker, e->d_name, depth))
            rc = mx_fail(st, MX_EINPUT,
                         "%s: holds %s, which matex did not write there: --force replaces only a folder of matex's own "
                         "output; move it away or give another folder",
                         given, e->d_name);
    }
    closedir(d);
    free(marker);
    return rc;
}

/* od->stage and od->lock from the resolved od->dir. */
static int name_stage_and_lock(mx_outdir *od, const char *given, mx_status *st) {
    int n = snprintf(od->stage, sizeof od->stage, "%s.partial-%ld", od->dir, (long)getpid());
    int k = snprintf(od->lock, sizeof od->lock, "%s.matex-lock", od->dir);
    if (n < 0 || (size_t)n >= sizeof od->stage || k < 0 || (size_t)k >= sizeof od->lock)
        return mx_fail(st, MX_EINPUT, "%s: path too long", given);
    return 0;
}

int mx_outdir_names(const char *dir, char stage[4200], char lock[4200]) {
    mx_outdir od;
    memset(&od, 0, sizeof od);
    if (!dir || resolve_dir(&od, dir, NULL) || name_stage_and_lock(&od, dir, NULL)) return -1;
    memcpy(stage, od.stage, sizeof od.stage);
    memcpy(lock, od.lock, sizeof od.lock);
    return 0;
}

/* The lock of the folder (flock: the kernel drops it when the process ends, whatever the way). A
 * lock file unlinked by its last holder between our open and our flock is not the lock: retry. */
static int take_lock(mx_outdir *od, const char *given, mx_status *st) {
    for (int attempt = 0; attempt < 8; attempt++) {
        int fd = open(od->lock, O_RDWR | O_CREAT | O_CLOEXEC, 0666);
        if (fd < 0) /* the lock sits beside the folder: failing to make it means the folder cannot be written */
            return mx_fail(st, MX_EIO, "%s: cannot create the output folder there: %s", given, strerror(errno));
        if (flock(fd, LOCK_EX | LOCK_NB)) {
            int busy = errno == EWOULDBLOCK;
            close(fd);
            if (busy)
                return mx_fail(st, MX_EINPUT,
                               "%s: another matex run is writing this output folder now (it holds %s); wait for it to "
                               "end or give another folder",
                               given, od->lock);
            return mx_fail(st, MX_EIO, "%s: cannot lock %s: %s", given, od->lock, strerror(errno));
        }
        struct stat a, b;
        if (fstat(fd, &a) == 0 && stat(od->lock, &b) == 0 && a.st_ino == b.st_ino && a.st_dev == b.st_dev) {
            od->lock_fd = fd;
            od->locked = 1;
            return 0;
        }
        close(fd);
    }
    return mx_fail(st, MX_EIO, "%s: cannot lock %s: it keeps changing", given, od->lock);
}

static void release_lock(mx_outdir *od) {
    if (!od->locked) return;
    unlink(od->lock); /* before the close: no one can hold it while it is unlinked but us */
    close(od->lock_fd);
    od->locked = 0;
}

/* Is the process `pid` gone? (EPERM: it exists, another user's.) */
static int process_gone(long pid) { return pid > 0 && kill((pid_t)pid, 0) && errno == ESRCH; }

/* Staging folders "DIR.partial-PID" beside DIR left by a process that is gone (kill -9, a power
 * cut): removed when they carry matex's marker (a staging one, or a complete one not yet moved),
 * never otherwise. Called under the folder's lock, so no live run of this folder is staging. */
static void remove_stale_stages(const mx_outdir *od) {
    char parent[4096], prefix[4200];
    snprintf(parent, sizeof parent, "%s", od->dir);
    char *slash = strrchr(parent, '/');
    const char *base = slash ? slash + 1 : parent;
    snprintf(prefix, sizeof prefix, "%s.partial-", base);
    if (slash == parent) parent[1] = 0;
    else if (slash) *slash = 0;
    else snprintf(parent, sizeof parent, ".");
    DIR *d = opendir(parent);
    if (!d) return;
    struct dirent *e;
    size_t n = strlen(prefix);
    while ((e = readdir(d)) != NULL) {
        char *end;
        if (strncmp(e->d_name, prefix, n)) continue;
        long pid = strtol(e->d_name + n, &end, 10);
        if (*end || end == e->d_name + n || pid == (long)getpid() || !process_gone(pid)) continue;
        char path[8400];
        snprintf(path, sizeof path, "%s/%s", parent, e->d_name);
        char *marker = read_marker(path, STAGE_HEADER);
        if (!marker) marker = read_marker(path, MARKER_HEADER);
        if (marker) remove_tree(path);
        free(marker);
    }
    closedir(d);
}

/* The staging folder, marked as matex's from the start (STAGE_HEADER). */
static int make_stage(mx_outdir *od, const char *given, mx_status *st) {
    char path[4300];
    remove_tree(od->stage); /* a stale one of an earlier process with the same id */
    if (mkdir(od->stage, 0777))
        return mx_fail(st, MX_EIO, "%s: cannot create the staging folder %s: %s", given, od->stage, strerror(errno));
    od->staged = 1;
    return mx_path_join(path, sizeof path, od->stage, MX_OUTDIR_MARKER, st) ||
                   mx_atomic_write(path, STAGE_HEADER, strlen(STAGE_HEADER), st)
               ? -1
               : 0;
}

/* Past the lock: the content (force), then the staging folder. */
static int open_checked(mx_outdir *od, const char *dir, int force, mx_status *st) {
    int content = od->exists ? folder_content(od->dir, st) : 0;
    if (content < 0) return -1;
    if (content && !force)
        return mx_fail(st, MX_EINPUT, "%s: the output folder exists and is not empty (--force replaces it)", dir);
    /* a guard against a slip like "-o ~ --force": an earlier output holds files, and sub-folders
     * only where its marker lists them */
    char *marker = content == 2 ? read_marker(od->dir, MARKER_HEADER) : NULL;
    free(marker);
    if (content == 2 && !marker)
        return mx_fail(st, MX_EINPUT, "%s: holds sub-folders; --force replaces only a folder of files (an earlier output)",
                       dir);
    if (content && check_written_by_matex(od->dir, dir, st)) return -1;
    remove_stale_stages(od);
    if (make_stage(od, dir, st)) return -1;
    return od->exists ? check_same_device(od, dir, st) : 0;
}

int mx_outdir_open(mx_outdir *od, const char *dir, int force, const char *const *inputs, int ninputs, mx_status *st) {
    memset(od, 0, sizeof *od);
    if (!dir || !*dir) return mx_fail(st, MX_EUSAGE, "no output folder given");
    if (resolve_dir(od, dir, st) || name_stage_and_lock(od, dir, st)) return -1;
    if (od->exists && check_holds_nothing_needed(od, dir, inputs, ninputs, st)) return -1;
    if (make_parents(od->dir, st) || take_lock(od, dir, st)) return -1;
    if (open_checked(od, dir, force, st)) {
        mx_outdir_discard(od);
        return -1;
    }
    return 0;
}

/* The marker, listing every file of the staging folder: written last, so a folder holding it is complete. */
static int write_marker(const mx_outdir *od, mx_status *st) {
    DIR *d = opendir(od->stage);
    if (!d) return mx_fail(st, MX_EIO, "%s: cannot read folder: %s", od->stage, strerror(errno));
    mx_buf b = {0};
    mx_buf_printf(&b, "%s", MARKER_HEADER);
    struct dirent *e;
    while ((e = readdir(d)) != NULL)
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..") && strcmp(e->d_name, MX_OUTDIR_MARKER))
            mx_buf_printf(&b, "%s\n", e->d_name);
    closedir(d);
    char path[4300];
    int rc = b.oom ? mx_fail(st, MX_ENOMEM, "%s: out of memory", od->stage)
                   : mx_path_join(path, sizeof path, od->stage, MX_OUTDIR_MARKER, st) ||
                         mx_atomic_write(path, b.p, b.len, st);
    mx_buf_free(&b);
    return rc ? -1 : 0;
}

void mx_outdir_discard(mx_outdir *od) {
    if (od->staged) remove_tree(od->stage);
    od->staged = 0;
    release_lock(od);
}

/* Swaps the staging folder with the existing dir (atomic where the kernel can), then removes the
 * old content, which the swap left under the staging name. */
static int replace_existing(mx_outdir *od, mx_status *st) {
#ifdef RENAME_EXCHANGE
    if (renameat2(AT_FDCWD, od->stage, AT_FDCWD, od->dir, RENAME_EXCHANGE) == 0) {
        remove_tree(od->stage);
        od->staged = 0;
        return 0;
    }
    if (errno != EINVAL && errno != ENOSYS)
        return mx_fail(st, MX_EIO, "%s: cannot replace: %s", od->dir, strerror(errno));
#endif
    /* no exchange on this file system: move the old folder aside, then the new one in */
    char old[4300];
    snprintf(old, sizeof old, "%s.old-%ld", od->dir, (long)getpid());
    remove_tree(old);
    if (rename(od->dir, old)) return mx_fail(st, MX_EIO, "%s: cannot replace: %s", od->dir, strerror(errno));
    if (rename(od->stage, od->dir)) {
        int e = errno;
        rename(old, od->dir);
        return mx_fail(st, MX_EIO, "%s: cannot write: %s", od->dir, strerror(e));
    }
    od->staged = 0;
    remove_tree(old);
    return 0;
}

int mx_outdir_commit(mx_outdir *od, const mx_mesh *m, const mx_image *textures, int ntex, const char *report_json,
                     const volatile sig_atomic_t *cancel, mx_status *st) {
    if (!od->staged) return mx_fail(st, MX_EINTERNAL, "%s: output folder not opened", od->dir);
    if (mx_write_outputs(od->stage, m, textures, ntex, report_json, st)) {
        mx_outdir_discard(od);
        return -1;
    }
    return mx_outdir_publish(od, cancel, st);
}

/* An output written into a folder of matex's output (`make demo`: demo/spot/views) is listed in that
 * folder's marker as "NAME/", so that --force may replace the outer folder with it. Best effort: an
 * unlisted sub-folder only makes --force refuse the outer folder. */
static void note_in_parent_marker(const mx_outdir *od) {
    char parent[4096];
    snprintf(parent, sizeof parent, "%s", od->dir);
    char *slash = strrchr(parent, '/');
    if (!slash || slash == parent) return;
    *slash = 0;
    char entry[300];
    snprintf(entry, sizeof entry, "%s/", slash + 1);
    char *marker = read_marker(parent, MARKER_HEADER);
    if (marker && !marker_lists(marker, entry)) {
        mx_buf b = {0};
        char path[4300];
        mx_status ignored;
        mx_buf_printf(&b, "%s%s\n", marker, entry);
        if (!b.oom && !mx_path_join(path, sizeof path, parent, MX_OUTDIR_MARKER, &ignored))
            mx_atomic_write(path, b.p, b.len, &ignored);
        mx_buf_free(&b);
    }
    free(marker);
}

int mx_outdir_publish(mx_outdir *od, const volatile sig_atomic_t *cancel, mx_status *st) {
    if (!od->staged) return mx_fail(st, MX_EINTERNAL, "%s: output folder not opened", od->dir);
    if (cancel && *cancel) {
        mx_outdir_discard(od);
        return mx_fail(st, MX_ECANCEL, "interrupted");
    }
    if (write_marker(od, st)) {
        mx_outdir_discard(od);
        return -1;
    }
    if (od->exists) {
        int rc = replace_existing(od, st);
        if (!rc) note_in_parent_marker(od);
        mx_outdir_discard(od); /* the lock (and a staging folder left by a failure) */
        return rc;
    }
    if (rename(od->stage, od->dir)) {
        int e = errno;
        mx_outdir_discard(od);
        return mx_fail(st, MX_EIO, "%s: cannot write: %s", od->dir, strerror(e));
    }
    od->staged = 0;
    note_in_parent_marker(od);
    release_lock(od);
    return 0;
}
