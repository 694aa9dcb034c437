/* A mesh with its side files in a .zip (serve_zip.h). */
#include "serve_zip.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "../../../runtime/atomic_file.h"

#define RATIO_FREE ((uint64_t)1 << 20) /* entries up to this size may inflate any amount */
#define MAX_DEPTH 16

static const char *const mesh_kinds[] = {"obj", "ply", "stl", "off", "glb", "gltf"};

/* 1 when one '/'-separated component c[0..n) is allowed: not empty, ".", "..", and free of
 * backslash, colon and control bytes. */
static int component_ok(const char *c, size_t n) {
    if (n == 0 || (n == 1 && c[0] == '.') || (n == 2 && c[0] == '.' && c[1] == '.')) return 0;
    for (size_t i = 0; i < n; i++) {
        unsigned char b = (unsigned char)c[i];
        if (b < 0x20 || b == 0x7f || b == '\\' || b == ':') return 0;
    }
    return 1;
}

int mx_serve_zip_name_valid(const char *name) {
    size_t len = strlen(name), depth = 0;
    if (len == 0 || len > MX_SERVE_ZIP_NAME_MAX || name[0] == '/') return 0;
    for (size_t at = 0; at < len; depth++) {
        size_t k = at;
        while (k < len && name[k] != '/') k++;
        if (depth == MAX_DEPTH || !component_ok(name + at, k - at)) return 0;
        at = k + 1;
        if (k + 1 == len) break; /* "dir/": a directory entry */
    }
    return 1;
}

static int is_dir_entry(const mx_zip_entry *en) { return en->name[en->name_len - 1] == '/'; }
static int is_macos_fork(const mx_zip_entry *en) { return en->name_len >= 9 && !memcmp(en->name, "__MACOSX/", 9); }

/* 1 when the entry's name ends in a mesh extension (case-insensitive). */
static int is_mesh_name(const mx_zip_entry *en) {
    const char *dot = NULL;
    for (size_t i = 0; i < en->name_len; i++)
        if (en->name[i] == '.') dot = en->name + i;
        else if (en->name[i] == '/') dot = NULL;
    if (!dot) return 0;
    size_t n = en->name_len - (size_t)(dot + 1 - en->name);
    for (size_t k = 0; k < sizeof mesh_kinds / sizeof mesh_kinds[0]; k++)
        if (strlen(mesh_kinds[k]) == n && !strncasecmp(dot + 1, mesh_kinds[k], n)) return 1;
    return 0;
}

/* The checks of one entry's name and kind (see serve_zip.h). */
static int check_entry(const mx_zip_entry *en, mx_serve_error *e) {
    char name[MX_SERVE_ZIP_NAME_MAX + 1];
    int shown = en->name_len > 200 ? 200 : (int)en->name_len;
    if (en->name_len == 0 || en->name_len > MX_SERVE_ZIP_NAME_MAX || memchr(en->name, 0, en->name_len))
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": an entry name of %zu bytes is empty, too long or holds a NUL",
                             en->name_len);
    memcpy(name, en->name, en->name_len);
    name[en->name_len] = 0;
    if (!mx_serve_zip_name_valid(name))
        return mx_serve_fail(e, 400, "bad_zip",
                             "part \"mesh\": entry '%.*s': not a plain relative name (absolute, '..', '.', an empty "
                             "component, a backslash, colon or control byte, or deeper than %d folders)",
                             shown, en->name, MAX_DEPTH);
    if (en->is_link) return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.*s' is a symbolic link", shown, en->name);
    if (en->flags & 1) return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.*s' is encrypted", shown, en->name);
    if (en->method != 0 && en->method != 8)
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.*s': compression method %u (only stored and deflate)",
                             shown, en->name, en->method);
    if (en->method == 0 && en->csize != en->usize)
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.*s': stored sizes differ", shown, en->name);
    if (is_dir_entry(en) && en->usize != 0)
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": folder entry '%.*s' has data", shown, en->name);
    if (en->usize > RATIO_FREE && en->usize / MX_SERVE_ZIP_MAX_RATIO > en->csize)
        return mx_serve_fail(e, 413, "too_large", "part \"mesh\": entry '%.*s' inflates %llu bytes to %llu (a zip bomb? at most %dx)",
                             shown, en->name, (unsigned long long)en->csize, (unsigned long long)en->usize,
                             MX_SERVE_ZIP_MAX_RATIO);
    return 0;
}

void mx_serve_zip_free(mx_serve_zip *z) {
    free(z->entries);
    memset(z, 0, sizeof *z);
}

int mx_serve_zip_check(const uint8_t *map, size_t len, mx_serve_zip *z, mx_serve_error *e) {
    mx_status st;
    size_t meshes = 0;
    uint64_t total = 0;
    memset(z, 0, sizeof *z);
    if (!mx_zip_is_zip(map, len)) return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": not a zip file");
    if (mx_zip_read(map, len, "part \"mesh\"", UINT64_MAX, &z->entries, &z->n, &st))
        return mx_serve_fail(e, st.code == MX_ENOMEM ? 503 : 400, st.code == MX_ENOMEM ? "internal" : "bad_zip", "%s", st.msg);
    if (z->n > MX_SERVE_ZIP_MAX_ENTRIES)
        return mx_serve_fail(e, 413, "too_large", "part \"mesh\": %zu zip entries (at most %d)", z->n, MX_SERVE_ZIP_MAX_ENTRIES);
    for (size_t i = 0; i < z->n; i++) {
        const mx_zip_entry *en = &z->entries[i];
        if (is_macos_fork(en)) continue;
        if (check_entry(en, e)) return -1;
        total += en->usize;
        if (total > MX_SERVE_ZIP_MAX_BYTES)
            return mx_serve_fail(e, 413, "too_large", "part \"mesh\": the archive holds more than %llu bytes uncompressed",
                                 (unsigned long long)MX_SERVE_ZIP_MAX_BYTES);
        if (!is_dir_entry(en) && is_mesh_name(en)) z->mesh = i, meshes++;
    }
    if (meshes != 1)
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": the archive holds %zu mesh files (.obj .ply .stl .off .glb "
                             ".gltf); it must hold exactly one, with its side files", meshes);
    return 0;
}

static int write_all(int fd, const uint8_t *p, size_t n) {
    while (fd >= 0 && n) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        p += w, n -= (size_t)w;
    }
    return 0;
}

/* Inflates a deflate entry into fd, refusing more or fewer bytes than it declares; its CRC into *crc. */
static int inflate_entry(const mx_zip_entry *en, int fd, uLong *crc, mx_serve_error *e) {
    uint8_t out[65536];
    uint64_t done = 0, in_left = en->csize;
    z_stream zs;
    memset(&zs, 0, sizeof zs);
    if (inflateInit2(&zs, -MAX_WBITS) != Z_OK) return mx_serve_fail(e, 503, "internal", "out of memory");
    zs.next_in = (Bytef *)en->data;
    int zr = Z_OK, rc = 0;
    while (!rc && zr != Z_STREAM_END) {
        if (zs.avail_in == 0 && in_left) { /* avail_in is a uInt: the data in pieces of at most 1 GiB */
            zs.avail_in = in_left > (1u << 30) ? (1u << 30) : (uInt)in_left;
            in_left -= zs.avail_in;
        }
        zs.next_out = out;
        zs.avail_out = sizeof out;
        zr = inflate(&zs, Z_NO_FLUSH);
        size_t got = sizeof out - zs.avail_out;
        if (zr != Z_OK && zr != Z_STREAM_END) rc = -2; /* damaged, or Z_BUF_ERROR: the data ends early */
        else if (got > en->usize - done) rc = -3;
        else if (write_all(fd, out, got)) rc = -4;
        else {
            done += got;
            *crc = crc32(*crc, out, (uInt)got);
        }
    }
    inflateEnd(&zs);
    int shown = en->name_len > 200 ? 200 : (int)en->name_len;
    if (rc == -4) return mx_serve_fail(e, 503, "storage", "cannot store the upload: %s", strerror(errno));
    if (rc == -3 || (!rc && done != en->usize))
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.*s' does not inflate to its declared %llu bytes", shown,
                             en->name, (unsigned long long)en->usize);
    if (rc) return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.*s': damaged compressed data", shown, en->name);
    return 0;
}

int mx_serve_zip_unpack(const mx_serve_zip *z, size_t i, int fd, mx_serve_error *e) {
    const mx_zip_entry *en = &z->entries[i];
    uLong crc = crc32(0, NULL, 0);
    if (en->method == 8) {
        if (inflate_entry(en, fd, &crc, e)) return -1;
    } else {
        for (uint64_t at = 0; at < en->usize;) { /* crc32 takes at most a uInt at once */
            uInt n = en->usize - at > (1u << 30) ? (1u << 30) : (uInt)(en->usize - at);
            crc = crc32(crc, en->data + at, n);
            at += n;
        }
        if (write_all(fd, en->data, (size_t)en->usize))
            return mx_serve_fail(e, 503, "storage", "cannot store the upload: %s", strerror(errno));
    }
    if (crc != en->crc)
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.*s': CRC mismatch (damaged)",
                             en->name_len > 200 ? 200 : (int)en->name_len, en->name);
    return 0;
}

/* Makes the folders of name (relative, checked) under root: each made here or already made
 * here (the root is new and the server's own, so nothing in it is a link). */
static int make_parents(const char *root, const char *name, mx_serve_error *e) {
    char path[4600];
    int len = snprintf(path, sizeof path, "%s/%s", root, name);
    if (len < 0 || (size_t)len >= sizeof path) return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": a name is too long");
    for (char *s = path + strlen(root) + 1; (s = strchr(s, '/')); s++) {
        *s = 0;
        int err = mkdir(path, 0700) && errno != EEXIST ? errno : 0;
        *s = '/';
        if (err == ENOTDIR) return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": '%.200s' is both a file and a folder", name);
        if (err) return mx_serve_fail(e, 503, "storage", "cannot store the upload: %s", strerror(err));
    }
    return 0;
}

/* Writes entry i under root (its parents made); a name given twice is an error. */
static int extract_entry(const mx_serve_zip *z, size_t i, const char *root, mx_serve_error *e) {
    const mx_zip_entry *en = &z->entries[i];
    char name[MX_SERVE_ZIP_NAME_MAX + 1], path[4600];
    memcpy(name, en->name, en->name_len);
    name[en->name_len] = 0;
    if (make_parents(root, name, e)) return -1;
    if (is_dir_entry(en)) return 0;
    snprintf(path, sizeof path, "%s/%s", root, name);
    int fd = open(path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, 0600);
    if (fd < 0 && (errno == EEXIST || errno == ENOTDIR || errno == EISDIR))
        return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": entry '%.200s' comes twice, or is also a folder", name);
    if (fd < 0) return mx_serve_fail(e, 503, "storage", "cannot store the upload: %s", strerror(errno));
    int rc = mx_serve_zip_unpack(z, i, fd, e);
    if (close(fd) && !rc) rc = mx_serve_fail(e, 503, "storage", "cannot store the upload: %s", strerror(errno));
    return rc;
}

/* The file job_dir/MX_SERVE_ZIP_MESH_FILE: the mesh's path inside the job folder. */
static int write_mesh_file(const char *job_dir, const char *rel, mx_serve_error *e) {
    char path[4300];
    mx_status st;
    snprintf(path, sizeof path, "%.4200s/" MX_SERVE_ZIP_MESH_FILE, job_dir);
    if (mx_atomic_write(path, rel, strlen(rel), &st)) return mx_serve_fail(e, 503, "storage", "cannot store the job's mesh path");
    return 0;
}

int mx_serve_zip_extract(const char *zip_path, const char *job_dir, char *mesh, size_t cap, mx_serve_error *e) {
    char root[4300], rel[MX_SERVE_ZIP_NAME_MAX + sizeof MX_SERVE_ZIP_DIR + 1];
    struct stat sb;
    int fd = open(zip_path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0 || fstat(fd, &sb)) {
        if (fd >= 0) close(fd);
        return mx_serve_fail(e, 503, "storage", "cannot read the stored upload: %s", strerror(errno));
    }
    void *map = sb.st_size > 0 ? mmap(NULL, (size_t)sb.st_size, PROT_READ, MAP_PRIVATE, fd, 0) : MAP_FAILED;
    close(fd);
    if (map == MAP_FAILED) return mx_serve_fail(e, 400, "bad_zip", "part \"mesh\": not a zip file");
    mx_serve_zip z;
    int rc = mx_serve_zip_check(map, (size_t)sb.st_size, &z, e);
    snprintf(root, sizeof root, "%.4200s/" MX_SERVE_ZIP_DIR, job_dir);
    if (!rc && mkdir(root, 0700)) rc = mx_serve_fail(e, 503, "storage", "cannot store the upload: %s", strerror(errno));
    for (size_t i = 0; !rc && i < z.n; i++)
        if (!is_macos_fork(&z.entries[i])) rc = extract_entry(&z, i, root, e);
    if (!rc) {
        const mx_zip_entry *m = &z.entries[z.mesh];
        snprintf(rel, sizeof rel, MX_SERVE_ZIP_DIR "/%.*s", (int)m->name_len, m->name);
        snprintf(mesh, cap, "%s/%s", job_dir, rel);
        rc = write_mesh_file(job_dir, rel, e);
    }
    mx_serve_zip_free(&z);
    munmap(map, (size_t)sb.st_size);
    return rc;
}
