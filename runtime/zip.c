/* Zip archives: reading in memory, writing from files (zip.h). */
#include "zip.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>

#include "buf.h"

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

/* ---- writing ---- */

#define ZIP32_MAX 0xFFFFFFFFu /* sizes and offsets past this need zip64, which the writer has not */
#define DOS_DATE_1980_01_01 0x0021u
#define UNIX_REGULAR_0644 0100644u

static void put_le(uint8_t *p, uint32_t v, int n) {
    for (int i = 0; i < n; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* CRC-32 (the zip and PNG one: reflected polynomial 0xEDB88320), one table per archive written. */
static void crc32_table(uint32_t t[256]) {
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int k = 0; k < 8; k++) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        t[i] = c;
    }
}

static uint32_t crc32_update(const uint32_t t[256], uint32_t crc, const uint8_t *p, size_t n) {
    crc = ~crc;
    for (size_t i = 0; i < n; i++) crc = t[(crc ^ p[i]) & 0xFF] ^ (crc >> 8);
    return ~crc;
}

/* The fields a local header and a central directory entry share, from "version needed" to the
 * name's length (26 bytes); the extra field's length (0) follows in both. */
static void put_common(uint8_t *p, uint32_t crc, uint32_t size, size_t name_len) {
    put_le(p, 10, 2);                       /* version needed: 1.0, stored data */
    put_le(p + 2, 0, 2);                    /* flags */
    put_le(p + 4, 0, 2);                    /* method: stored */
    put_le(p + 6, 0, 2);                    /* time 00:00 */
    put_le(p + 8, DOS_DATE_1980_01_01, 2);  /* date */
    put_le(p + 10, crc, 4);
    put_le(p + 14, size, 4);                /* compressed size */
    put_le(p + 18, size, 4);                /* uncompressed size */
    put_le(p + 22, (uint32_t)name_len, 2);
    put_le(p + 24, 0, 2);                   /* extra field length */
}

/* Copies the file at path to out after its local header; its CRC and size into *crc, *size. */
static int copy_data(FILE *out, const char *path, const uint32_t t[256], uint32_t *crc, uint64_t *size, mx_status *st) {
    FILE *in = fopen(path, "rb");
    if (!in) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
    uint8_t buf[65536];
    size_t got;
    int rc = 0;
    *crc = 0;
    *size = 0;
    while (!rc && (got = fread(buf, 1, sizeof buf, in)) > 0) {
        *crc = crc32_update(t, *crc, buf, got);
        *size += got;
        if (*size >= ZIP32_MAX) rc = mx_fail(st, MX_EINPUT, "%s: 4 GiB or more: too large for a zip without zip64", path);
        else if (fwrite(buf, 1, got, out) != got) rc = mx_fail(st, MX_EIO, "cannot write the zip: %s", strerror(errno));
    }
    if (!rc && ferror(in)) rc = mx_fail(st, MX_EINPUT, "%s: cannot read: %s", path, strerror(errno));
    fclose(in);
    return rc;
}

/* One entry: local header, name and data at *at; its central directory entry appended to cd. */
static int write_entry(FILE *out, const mx_zip_source *s, const uint32_t t[256], uint64_t *at, mx_buf *cd,
                       const char *what, mx_status *st) {
    size_t name_len = strlen(s->name);
    uint8_t h[46];
    uint32_t crc;
    uint64_t size;
    if (name_len == 0 || name_len > 0xFFFF) return mx_fail(st, MX_EINPUT, "%s: an entry name of %zu bytes", what, name_len);
    if (*at >= ZIP32_MAX) return mx_fail(st, MX_EINPUT, "%s: 4 GiB or more: too large for a zip without zip64", what);
    put_le(h, 0x04034b50, 4);
    put_common(h + 4, 0, 0, name_len); /* the CRC and size once the data is written */
    if (fwrite(h, 1, 30, out) != 30 || fwrite(s->name, 1, name_len, out) != name_len)
        return mx_fail(st, MX_EIO, "%s: cannot write: %s", what, strerror(errno));
    if (copy_data(out, s->path, t, &crc, &size, st)) return -1;
    put_common(h + 4, crc, (uint32_t)size, name_len);
    if (fseeko(out, (off_t)*at + 14, SEEK_SET) || fwrite(h + 14, 1, 12, out) != 12 || fseeko(out, 0, SEEK_END))
        return mx_fail(st, MX_EIO, "%s: cannot write: %s", what, strerror(errno));
    put_le(h, 0x02014b50, 4);
    put_le(h + 4, 3u << 8 | 20, 2); /* made by: Unix (3), APPNOTE 2.0 */
    put_common(h + 6, crc, (uint32_t)size, name_len);
    put_le(h + 32, 0, 2);                          /* comment length */
    put_le(h + 34, 0, 2);                          /* disk */
    put_le(h + 36, 0, 2);                          /* internal attributes */
    put_le(h + 38, UNIX_REGULAR_0644 << 16, 4);    /* external attributes: the Unix mode */
    put_le(h + 42, (uint32_t)*at, 4);              /* the local header's offset */
    mx_buf_put(cd, h, 46);
    mx_buf_put(cd, s->name, name_len);
    *at += 30 + name_len + size;
    return 0;
}

int mx_zip_write(FILE *out, const mx_zip_source *src, size_t n, const char *what, mx_status *st) {
    uint32_t t[256];
    uint64_t at = 0;
    mx_buf cd = {0};
    uint8_t end[22];
    if (n > 0xFFFF) return mx_fail(st, MX_EINPUT, "%s: %zu files: more than a zip without zip64 holds", what, n);
    crc32_table(t);
    for (size_t i = 0; i < n; i++)
        if (write_entry(out, &src[i], t, &at, &cd, what, st)) return mx_buf_free(&cd), -1;
    if (cd.oom) return mx_buf_free(&cd), mx_fail(st, MX_ENOMEM, "%s: out of memory", what);
    if (at + cd.len >= ZIP32_MAX)
        return mx_buf_free(&cd), mx_fail(st, MX_EINPUT, "%s: 4 GiB or more: too large for a zip without zip64", what);
    put_le(end, 0x06054b50, 4);
    put_le(end + 4, 0, 4);                 /* this disk, the directory's disk */
    put_le(end + 8, (uint32_t)n, 2);       /* entries on this disk */
    put_le(end + 10, (uint32_t)n, 2);      /* entries */
    put_le(end + 12, (uint32_t)cd.len, 4); /* the directory's size */
    put_le(end + 16, (uint32_t)at, 4);     /* and offset */
    put_le(end + 20, 0, 2);                /* comment length */
    int rc = (cd.len && fwrite(cd.p, 1, cd.len, out) != cd.len) || fwrite(end, 1, 22, out) != 22 || fflush(out)
                 ? mx_fail(st, MX_EIO, "%s: cannot write: %s", what, strerror(errno))
                 : 0;
    mx_buf_free(&cd);
    return rc;
}
