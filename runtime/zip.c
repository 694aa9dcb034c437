/* Zip archives in memory (zip.h). */
#include "zip.h"

#include <stdlib.h>
#include <string.h>

typedef struct {
    const char *path;
    const uint8_t *map;
    size_t len;
} zip_file;

int mx_zip_is_zip(const void *head, size_t n) { return n >= 4 && !memcmp(head, "PK\3\4", 4); }

static uint64_t le(const uint8_t *p, int n) {
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}

/* Finds the central directory: *cd_off, *cd_size, *count from the (zip64) end record. */
static int find_central_dir(const zip_file *z, uint64_t *cd_off, uint64_t *cd_size, uint64_t *count,
                            uint64_t max_entries, mx_status *st) {
    if (z->len < 22) return mx_fail(st, MX_EINPUT, "%s: %zu bytes: too short for a zip file", z->path, z->len);
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
    if (*count > *cd_size / 46) /* a central directory entry takes at least 46 bytes */
        return mx_fail(st, MX_EINPUT, "%s: %llu zip entries in a central directory of %llu bytes (damaged)", z->path,
                       (unsigned long long)*count, (unsigned long long)*cd_size);
    if (*count > max_entries)
        return mx_fail(st, MX_EINPUT, "%s: %llu zip entries (at most %llu)", z->path, (unsigned long long)*count,
                       (unsigned long long)max_entries);
    return 0;
}

/* Replaces the 0xFFFFFFFF sizes/offset of an entry by its zip64 extra field's values. */
static int read_zip64_extra(const zip_file *z, const uint8_t *extra, size_t extra_len, uint64_t *usize,
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
static int read_entry(const zip_file *z, uint64_t *pos, uint64_t cd_end, mx_zip_entry *out, mx_status *st) {
    const uint8_t *c = z->map + *pos;
    if (cd_end - *pos < 46 || le(c, 4) != 0x02014b50)
        return mx_fail(st, MX_EINPUT, "%s: damaged zip central directory", z->path);
    unsigned made_on = (unsigned)le(c + 5, 1), flags = (unsigned)le(c + 8, 2), method = (unsigned)le(c + 10, 2);
    uint64_t csize = le(c + 20, 4), usize = le(c + 24, 4), off = le(c + 42, 4);
    size_t name_len = (size_t)le(c + 28, 2), extra_len = (size_t)le(c + 30, 2), comment_len = (size_t)le(c + 32, 2);
    uint32_t mode = (uint32_t)(le(c + 38, 4) >> 16);
    if (cd_end - *pos - 46 < (uint64_t)name_len + extra_len + comment_len)
        return mx_fail(st, MX_EINPUT, "%s: damaged zip central directory", z->path);
    const char *name = (const char *)c + 46;
    if (read_zip64_extra(z, c + 46 + name_len, extra_len, &usize, &csize, &off, st)) return -1;
    *pos += 46 + name_len + extra_len + comment_len;
    if (z->len < 30 || off > z->len - 30 || le(z->map + off, 4) != 0x04034b50)
        return mx_fail(st, MX_EINPUT, "%s: entry '%.*s': local header outside the file", z->path, (int)name_len, name);
    uint64_t data = off + 30 + le(z->map + off + 26, 2) + le(z->map + off + 28, 2);
    if (data > z->len || csize > z->len - data)
        return mx_fail(st, MX_EINPUT, "%s: entry '%.*s': %llu bytes extend past the end of the file (truncated?)",
                       z->path, (int)name_len, name, (unsigned long long)csize);
    *out = (mx_zip_entry){.name = name,
                          .name_len = name_len,
                          .method = method,
                          .flags = flags,
                          .is_link = made_on == 3 && (mode & 0170000) == 0120000, /* 3: Unix */
                          .crc = (uint32_t)le(c + 16, 4),
                          .data = z->map + data,
                          .csize = csize,
                          .usize = usize};
    return 0;
}

int mx_zip_read(const uint8_t *map, size_t len, const char *path, uint64_t max_entries, mx_zip_entry **entries,
                size_t *n, mx_status *st) {
    zip_file z = {.path = path, .map = map, .len = len};
    uint64_t cd_off = 0, cd_size = 0, count = 0, pos;
    *entries = NULL;
    *n = 0;
    if (find_central_dir(&z, &cd_off, &cd_size, &count, max_entries, st)) return -1;
    *entries = calloc(count ? count : 1, sizeof **entries);
    if (!*entries) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    for (pos = cd_off; *n < count; ++*n)
        if (read_entry(&z, &pos, cd_off + cd_size, &(*entries)[*n], st)) {
            free(*entries);
            *entries = NULL;
            *n = 0;
            return -1;
        }
    return 0;
}
