/* PyTorch zip checkpoints (torchzip.h), over the zip reader of runtime/zip.h. */
#include "torchzip.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../runtime/zip.h"
#include "pickle.h"

#define ZIP_MAX_ENTRIES (1u << 20)
#define ZIP_MAX_PICKLE ((size_t)1 << 30)

typedef struct {
    const char *path;
    mx_zip_entry *entries;
    size_t n;
    const char *prefix; /* "NAME/" of NAME/data.pkl */
    size_t prefix_len;
} zip_archive;

int mx_torchzip_is_zip(const void *head, size_t n) { return mx_zip_is_zip(head, n); }

/* torch.save's entries: stored, unencrypted. */
static int check_stored(const zip_archive *z, const mx_zip_entry *e, mx_status *st) {
    int len = (int)e->name_len;
    if (e->flags & 1) return mx_fail(st, MX_EINPUT, "%s: entry '%.*s' is encrypted", z->path, len, e->name);
    if (e->method != 0)
        return mx_fail(st, MX_EINPUT,
                       "%s: entry '%.*s' is compressed (method %u); torch.save stores entries uncompressed and "
                       "only those are read",
                       z->path, len, e->name, e->method);
    if (e->csize != e->usize)
        return mx_fail(st, MX_EINPUT, "%s: entry '%.*s': stored sizes differ", z->path, len, e->name);
    return 0;
}

static int read_directory(zip_archive *z, const uint8_t *map, size_t len, mx_status *st) {
    if (mx_zip_read(map, len, z->path, ZIP_MAX_ENTRIES, &z->entries, &z->n, st)) return -1;
    for (size_t i = 0; i < z->n; i++)
        if (check_stored(z, &z->entries[i], st)) return -1;
    return 0;
}

static const mx_zip_entry *find_entry(const zip_archive *z, const char *suffix) {
    size_t sl = strlen(suffix);
    for (size_t i = 0; i < z->n; i++) {
        const mx_zip_entry *e = &z->entries[i];
        if (e->name_len == z->prefix_len + sl && !memcmp(e->name, z->prefix, z->prefix_len) &&
            !memcmp(e->name + z->prefix_len, suffix, sl))
            return e;
    }
    return NULL;
}

/* The archive's folder: the entry NAME/data.pkl with NAME free of '/'. */
static const mx_zip_entry *find_pickle(zip_archive *z, mx_status *st) {
    for (size_t i = 0; i < z->n; i++) {
        const mx_zip_entry *e = &z->entries[i];
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
    const mx_zip_entry *e = find_entry(z, suffix);
    if (!e) return mx_fail(st, MX_EINPUT, "%s: storage '%s' has no entry %.*s%s", z->path, key, (int)z->prefix_len,
                           z->prefix, suffix);
    *data = e->data;
    *nbytes = (size_t)e->usize;
    return 0;
}

static int check_byteorder(const zip_archive *z, mx_status *st) {
    const mx_zip_entry *e = find_entry(z, "byteorder");
    if (e && !(e->usize == 6 && !memcmp(e->data, "little", 6)))
        return mx_fail(st, MX_EINPUT, "%s: byteorder is not 'little' (big-endian checkpoints are not read)", z->path);
    return 0;
}

int mx_torchzip_open(mx_safetensors *f, const char *path, size_t *skipped, mx_status *st) {
    memset(f, 0, sizeof *f);
    if (!(f->path = strdup(path))) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    zip_archive z = {.path = path};
    int rc = mx_st_map_file(f, path, 22, "zip checkpoint", "a zip needs at least 22", st);
    if (!rc) rc = read_directory(&z, f->map, f->map_len, st);
    const mx_zip_entry *pkl = rc ? NULL : find_pickle(&z, st);
    if (!rc && !pkl) rc = -1;
    if (!rc) rc = check_byteorder(&z, st);
    if (!rc && pkl->usize > ZIP_MAX_PICKLE) rc = mx_fail(st, MX_EINPUT, "%s: data.pkl larger than 1 GiB", path);
    mx_pickle_result r;
    if (!rc) rc = mx_pickle_read_state_dict(pkl->data, (size_t)pkl->usize, path, storage_bytes, &z, &r, st);
    if (!rc) {
        f->tensors = r.tensors;
        f->count = r.count;
        if (skipped) *skipped = r.skipped;
    }
    free(z.entries);
    if (rc) mx_st_close(f);
    return rc;
}
