/* PyTorch zip checkpoints (torchzip.h). The zip records read are those of the PKWARE APPNOTE:
 * end of central directory (and its zip64 form), central directory entries (with the zip64
 * extra field), local headers. */
#include "torchzip.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pickle.h"

#define ZIP_MAX_ENTRIES (1u << 20)
#define ZIP_MAX_PICKLE ((size_t)1 << 30)

typedef struct {
    const char *name; /* inside the central directory, not NUL-terminated */
    size_t name_len;
    const uint8_t *data;
    size_t size;
} zip_entry;

typedef struct {
    const char *path;
    const uint8_t *map;
    size_t len;
    zip_entry *entries;
    size_t n;
    const char *prefix; /* "NAME/" of NAME/data.pkl */
    size_t prefix_len;
} zip_archive;

int mx_torchzip_is_zip(const void *head, size_t n) { return n >= 4 && !memcmp(head, "PK\3\4", 4); }

static uint64_t le(const uint8_t *p, int n) {
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}

/* Finds the central directory: *cd_off, *cd_size, *count from the (zip64) end record. */
static int find_central_dir(const zip_archive *z, uint64_t *cd_off, uint64_t *cd_size, uint64_t *count, mx_status *st) {
    size_t lo = z->len > 22 + 65535 ? z->len - 22 - 65535 : 0;
    size_t eocd = SIZE_MAX;
    for (size_t i = z->len - 22 + 1; i-- > lo;)
        if (le(z->map + i, 4) == 0x06054b50) {
            eocd = i;
            break;
        }
    if (eocd == SIZE_MAX) return mx_fail(st, MX_EINPUT, "%s: no zip end-of-directory record (truncated?)", z->path);
    const uint8_t *e = z->map + eocd;
    *count = le(e + 10, 2);
    *cd_size = le(e + 12, 4);
    *cd_off = le(e + 16, 4);
    if (*count == 0xFFFF || *cd_size == 0xFFFFFFFF || *cd_off == 0xFFFFFFFF) {
        /* zip64: the locator sits just before the end record and points at the zip64 record */
        if (eocd < 20 || le(e - 20, 4) != 0x07064b50)
            return mx_fail(st, MX_EINPUT, "%s: zip64 end-of-directory locator missing", z->path);
        uint64_t rec = le(e - 20 + 8, 8);
        if (z->len < 56 || rec > z->len - 56 || le(z->map + rec, 4) != 0x06064b50)
            return mx_fail(st, MX_EINPUT, "%s: zip64 end-of-directory record outside the file", z->path);
        *count = le(z->map + rec + 32, 8);
        *cd_size = le(z->map + rec + 40, 8);
        *cd_off = le(z->map + rec + 48, 8);
    }
    if (*cd_off > z->len || *cd_size > z->len - *cd_off)
        return mx_fail(st, MX_EINPUT, "%s: zip central directory outside the file", z->path);
    if (*count > ZIP_MAX_ENTRIES) return mx_fail(st, MX_EINPUT, "%s: %llu zip entries (at most %u)", z->path,
                                                 (unsigned long long)*count, ZIP_MAX_ENTRIES);
    return 0;
}

/* Replaces the 0xFFFFFFFF sizes/offset of an entry by its zip64 extra field's values. */
static int read_zip64_extra(const zip_archive *z, const uint8_t *extra, size_t extra_len, uint64_t *usize,
                            uint64_t *csize, uint64_t *off, mx_status *st) {
    for (size_t i = 0; i + 4 <= extra_len;) {
        size_t id = (size_t)le(extra + i, 2), len = (size_t)le(extra + i + 2, 2);
        if (len > extra_len - i - 4) break;
        if (id == 1) {
            const uint8_t *p = extra + i + 4, *end = p + len;
            uint64_t *fields[3] = {usize, csize, off};
            for (int k = 0; k < 3; k++) {
                if (*fields[k] != 0xFFFFFFFF) continue;
                if (end - p < 8) return mx_fail(st, MX_EINPUT, "%s: short zip64 extra field", z->path);
                *fields[k] = le(p, 8);
                p += 8;
            }
            return 0;
        }
        i += 4 + len;
    }
    if (*usize == 0xFFFFFFFF || *csize == 0xFFFFFFFF || *off == 0xFFFFFFFF)
        return mx_fail(st, MX_EINPUT, "%s: zip64 sizes without a zip64 extra field", z->path);
    return 0;
}

/* One central directory entry at *pos: checked and resolved to its data in the file. */
static int read_entry(zip_archive *z, uint64_t *pos, uint64_t cd_end, zip_entry *out, mx_status *st) {
    const uint8_t *c = z->map + *pos;
    if (cd_end - *pos < 46 || le(c, 4) != 0x02014b50)
        return mx_fail(st, MX_EINPUT, "%s: damaged zip central directory", z->path);
    size_t flags = (size_t)le(c + 8, 2), method = (size_t)le(c + 10, 2);
    uint64_t csize = le(c + 20, 4), usize = le(c + 24, 4), off = le(c + 42, 4);
    size_t name_len = (size_t)le(c + 28, 2), extra_len = (size_t)le(c + 30, 2), comment_len = (size_t)le(c + 32, 2);
    if (cd_end - *pos - 46 < (uint64_t)name_len + extra_len + comment_len)
        return mx_fail(st, MX_EINPUT, "%s: damaged zip central directory", z->path);
    const char *name = (const char *)c + 46;
    if (read_zip64_extra(z, c + 46 + name_len, extra_len, &usize, &csize, &off, st)) return -1;
    *pos += 46 + name_len + extra_len + comment_len;
    if (flags & 1) return mx_fail(st, MX_EINPUT, "%s: entry '%.*s' is encrypted", z->path, (int)name_len, name);
    if (method != 0)
        return mx_fail(st, MX_EINPUT,
                       "%s: entry '%.*s' is compressed (method %zu); torch.save stores entries uncompressed and "
                       "only those are read",
                       z->path, (int)name_len, name, method);
    if (csize != usize)
        return mx_fail(st, MX_EINPUT, "%s: entry '%.*s': stored sizes differ", z->path, (int)name_len, name);
    if (z->len < 30 || off > z->len - 30 || le(z->map + off, 4) != 0x04034b50)
        return mx_fail(st, MX_EINPUT, "%s: entry '%.*s': local header outside the file", z->path, (int)name_len, name);
    uint64_t data = off + 30 + le(z->map + off + 26, 2) + le(z->map + off + 28, 2);
    if (data > z->len || usize > z->len - data)
        return mx_fail(st, MX_EINPUT, "%s: entry '%.*s': %llu bytes extend past the end of the file (truncated?)",
                       z->path, (int)name_len, name, (unsigned long long)usize);
    *out = (zip_entry){.name = name, .name_len = name_len, .data = z->map + data, .size = (size_t)usize};
    return 0;
}

static int read_directory(zip_archive *z, mx_status *st) {
    uint64_t cd_off = 0, cd_size = 0, count = 0;
    if (find_central_dir(z, &cd_off, &cd_size, &count, st)) return -1;
    z->entries = calloc(count ? count : 1, sizeof *z->entries);
    if (!z->entries) return mx_fail(st, MX_ENOMEM, "%s: out of memory", z->path);
    uint64_t pos = cd_off;
    for (z->n = 0; z->n < count; z->n++)
        if (read_entry(z, &pos, cd_off + cd_size, &z->entries[z->n], st)) return -1;
    return 0;
}

static const zip_entry *find_entry(const zip_archive *z, const char *suffix) {
    size_t sl = strlen(suffix);
    for (size_t i = 0; i < z->n; i++) {
        const zip_entry *e = &z->entries[i];
        if (e->name_len == z->prefix_len + sl && !memcmp(e->name, z->prefix, z->prefix_len) &&
            !memcmp(e->name + z->prefix_len, suffix, sl))
            return e;
    }
    return NULL;
}

/* The archive's folder: the entry NAME/data.pkl with NAME free of '/'. */
static const zip_entry *find_pickle(zip_archive *z, mx_status *st) {
    for (size_t i = 0; i < z->n; i++) {
        const zip_entry *e = &z->entries[i];
        if (e->name_len < 9 || memcmp(e->name + e->name_len - 9, "/data.pkl", 9)) continue;
        if (memchr(e->name, '/', e->name_len - 9)) continue;
        z->prefix = e->name;
        z->prefix_len = e->name_len - 8;
        return e;
    }
    mx_fail(st, MX_EINPUT, "%s: a zip file without NAME/data.pkl: not a PyTorch checkpoint", z->path);
    return NULL;
}

static int storage_bytes(void *ctx, const char *key, const void **data, size_t *nbytes, mx_status *st) {
    const zip_archive *z = ctx;
    char suffix[80];
    snprintf(suffix, sizeof suffix, "data/%s", key);
    const zip_entry *e = find_entry(z, suffix);
    if (!e) return mx_fail(st, MX_EINPUT, "%s: storage '%s' has no entry %.*s%s", z->path, key, (int)z->prefix_len,
                           z->prefix, suffix);
    *data = e->data;
    *nbytes = e->size;
    return 0;
}

static int check_byteorder(const zip_archive *z, mx_status *st) {
    const zip_entry *e = find_entry(z, "byteorder");
    if (e && !(e->size == 6 && !memcmp(e->data, "little", 6)))
        return mx_fail(st, MX_EINPUT, "%s: byteorder is not 'little' (big-endian checkpoints are not read)", z->path);
    return 0;
}

int mx_torchzip_open(mx_safetensors *f, const char *path, size_t *skipped, mx_status *st) {
    memset(f, 0, sizeof *f);
    if (!(f->path = strdup(path))) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    zip_archive z = {.path = path};
    int rc = mx_st_map_file(f, path, 22, "zip checkpoint", "a zip needs at least 22", st);
    if (!rc) {
        z.map = f->map;
        z.len = f->map_len;
        rc = read_directory(&z, st);
    }
    const zip_entry *pkl = rc ? NULL : find_pickle(&z, st);
    if (!rc && !pkl) rc = -1;
    if (!rc) rc = check_byteorder(&z, st);
    if (!rc && pkl->size > ZIP_MAX_PICKLE) rc = mx_fail(st, MX_EINPUT, "%s: data.pkl larger than 1 GiB", path);
    mx_pickle_result r;
    if (!rc) rc = mx_pickle_read_state_dict(pkl->data, pkl->size, path, storage_bytes, &z, &r, st);
    if (!rc) {
        f->tensors = r.tensors;
        f->count = r.count;
        if (skipped) *skipped = r.skipped;
    }
    free(z.entries);
    if (rc) mx_st_close(f);
    return rc;
}
