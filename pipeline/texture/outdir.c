#include "outdir.h"

#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../geom/export.h"

/* dir + "/" + name into out; 0 when it fits. */
static int join_path(char *out, size_t cap, const char *dir, const char *name) {
    int n = snprintf(out, cap, "%s/%s", dir, name);
    return n < 0 || (size_t)n >= cap ? -1 : 0;
}

/* Removes the regular files of a folder, then the folder. */
static void remove_tree(const char *dir) {
    DIR *d = opendir(dir);
    if (d) {
        struct dirent *e;
        char path[4096];
        while ((e = readdir(d)) != NULL) {
            if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
            if (!join_path(path, sizeof path, dir, e->d_name)) unlink(path);
        }
        closedir(d);
    }
    rmdir(dir);
}

static int move_files(const char *from, const char *to, mx_status *st) {
    DIR *d = opendir(from);
    if (!d) return mx_fail(st, MX_EIO, "%s: cannot read staging folder: %s", from, strerror(errno));
    struct dirent *e;
    char src[4096], dst[4096];
    int rc = 0;
    while (!rc && (e = readdir(d)) != NULL) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        if (join_path(src, sizeof src, from, e->d_name) || join_path(dst, sizeof dst, to, e->d_name))
            rc = mx_fail(st, MX_EINPUT, "%s: path too long", to);
        else if (rename(src, dst)) rc = mx_fail(st, MX_EIO, "%s: cannot write: %s", dst, strerror(errno));
    }
    closedir(d);
    return rc;
}

static int make_folder(const char *path, mx_status *st) {
    if (mkdir(path, 0777) && errno != EEXIST)
        return mx_fail(st, MX_EIO, "%s: cannot create folder: %s", path, strerror(errno));
    return 0;
}

/* mkdir -p of the folder that will hold `dir` (its parent). */
static int make_parents(const char *dir, mx_status *st) {
    char path[4096];
    int n = snprintf(path, sizeof path, "%s", dir);
    if (n < 0 || (size_t)n >= sizeof path) return mx_fail(st, MX_EINPUT, "%s: path too long", dir);
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

int mx_outdir_write(const char *dir, const mx_mesh *m, const mx_image *textures, int ntex, const char *report_json,
                    mx_status *st) {
    char stage[4096];
    if (!dir || !*dir) return mx_fail(st, MX_EINPUT, "no output folder given");
    int n = snprintf(stage, sizeof stage, "%s.partial-%ld", dir, (long)getpid());
    if (n < 0 || (size_t)n >= sizeof stage) return mx_fail(st, MX_EINPUT, "%s: path too long", dir);
    struct stat sb;
    if (stat(dir, &sb) == 0 && !S_ISDIR(sb.st_mode))
        return mx_fail(st, MX_EINPUT, "%s: exists and is not a folder", dir);
    if (make_parents(dir, st)) return -1;
    remove_tree(stage);
    if (mx_write_outputs(stage, m, textures, ntex, report_json, st)) {
        remove_tree(stage);
        return -1;
    }
    if (stat(dir, &sb) != 0) {
        if (rename(stage, dir) == 0) return 0;
        if (make_folder(dir, st)) {
            remove_tree(stage);
            return -1;
        }
    }
    int rc = move_files(stage, dir, st);
    remove_tree(stage);
    return rc;
}
