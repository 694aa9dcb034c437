#include "outdir.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../geom/export.h"

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

int mx_outdir_open(mx_outdir *od, const char *dir, int force, mx_status *st) {
    memset(od, 0, sizeof *od);
    if (!dir || !*dir) return mx_fail(st, MX_EUSAGE, "no output folder given");
    if (resolve_dir(od, dir, st)) return -1;
    int content = od->exists ? folder_content(od->dir, st) : 0;
    if (content < 0) return -1;
    if (content && !force)
        return mx_fail(st, MX_EINPUT, "%s: the output folder exists and is not empty (--force replaces it)", dir);
    /* a guard against a slip like "-o ~ --force": an earlier output holds files only */
    if (content == 2)
        return mx_fail(st, MX_EINPUT, "%s: holds sub-folders; --force replaces only a folder of files (an earlier output)",
                       dir);
    int n = snprintf(od->stage, sizeof od->stage, "%s.partial-%ld", od->dir, (long)getpid());
    if (n < 0 || (size_t)n >= sizeof od->stage) return mx_fail(st, MX_EINPUT, "%s: path too long", dir);
    if (make_parents(od->dir, st)) return -1;
    remove_tree(od->stage); /* a stale one of an earlier process with the same id */
    if (mkdir(od->stage, 0777))
        return mx_fail(st, MX_EIO, "%s: cannot create the staging folder %s: %s", dir, od->stage, strerror(errno));
    od->staged = 1;
    if (od->exists && check_same_device(od, dir, st)) {
        mx_outdir_discard(od);
        return -1;
    }
    return 0;
}

void mx_outdir_discard(mx_outdir *od) {
    if (od->staged) remove_tree(od->stage);
    od->staged = 0;
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

int mx_outdir_publish(mx_outdir *od, const volatile sig_atomic_t *cancel, mx_status *st) {
    if (!od->staged) return mx_fail(st, MX_EINTERNAL, "%s: output folder not opened", od->dir);
    if (cancel && *cancel) {
        mx_outdir_discard(od);
        return mx_fail(st, MX_ECANCEL, "interrupted");
    }
    if (od->exists) return replace_existing(od, st);
    if (rename(od->stage, od->dir)) {
        int e = errno;
        mx_outdir_discard(od);
        return mx_fail(st, MX_EIO, "%s: cannot write: %s", od->dir, strerror(e));
    }
    od->staged = 0;
    return 0;
}
