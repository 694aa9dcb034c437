/* The zip writer (runtime/zip.h, mx_zip_write) read back by the zip reader (mx_zip_read): names,
 * stored data, sizes and CRC-32 (the standard check value of "123456789") in the central
 * directory and in each local header (written after the data), a file larger than one copy
 * buffer, an empty file, an empty archive, the same bytes for the same files, and a missing
 * source file refused with its name. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../runtime/zip.h"
#include "util_test.h"

#define BIG_BYTES 200000 /* three copy buffers and a part */

static char dir[] = "/tmp/matex_test_zip_XXXXXX";

static void path_of(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", dir, name); }

static int write_bytes(const char *name, const void *p, size_t n) {
    char path[256];
    path_of(path, sizeof path, name);
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(p, 1, n, f) == n;
    return (f && fclose(f)) || !ok ? -1 : 0;
}

static uint32_t le32(const uint8_t *p) { return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24; }

/* The archive of src[0..n) in memory (NULL with st set when the writer fails). */
static uint8_t *zip_of(const mx_zip_source *src, size_t n, size_t *len, mx_status *st) {
    FILE *f = tmpfile();
    uint8_t *bytes = NULL;
    if (f && !mx_zip_write(f, src, n, "test.zip", st)) {
        long end = fseek(f, 0, SEEK_END) ? -1 : ftell(f);
        bytes = end >= 0 ? malloc((size_t)end + 1) : NULL;
        rewind(f);
        if (bytes && fread(bytes, 1, (size_t)end, f) == (size_t)end) *len = (size_t)end;
        else free(bytes), bytes = NULL;
    }
    if (f) fclose(f);
    return bytes;
}

/* Sources named inside[i] in the archive, read from dir/files[i] (paths: n buffers of 256). */
static void sources(mx_zip_source *src, char (*paths)[256], const char *const *inside, const char *const *files, size_t n) {
    for (size_t i = 0; i < n; i++) {
        path_of(paths[i], sizeof paths[i], files[i]);
        src[i] = (mx_zip_source){.name = inside[i], .path = paths[i]};
    }
}

static void test_round_trip(void) {
    uint8_t *big = malloc(BIG_BYTES);
    for (size_t i = 0; i < BIG_BYTES; i++) big[i] = (uint8_t)(i * 2654435761u >> 13);
    CHECK(write_bytes("check.txt", "123456789", 9) == 0);
    CHECK(write_bytes("empty", "", 0) == 0);
    CHECK(write_bytes("big.bin", big, BIG_BYTES) == 0);
    /* the names inside need not be the files' names: the sources here are flat, the names nested */
    const char *const files[] = {"check.txt", "empty", "big.bin"};
    const char *const inside[] = {"mesh.obj", "mat/empty.mtl", "mat/tex/big.png"};
    mx_zip_source src[3];
    char paths[3][256];
    sources(src, paths, inside, files, 3);
    mx_status st;
    size_t len = 0, n = 0;
    uint8_t *bytes = zip_of(src, 3, &len, &st);
    mx_zip_entry *e = NULL;
    CHECK(bytes && mx_zip_is_zip(bytes, len));
    CHECK(bytes && mx_zip_read(bytes, len, "test.zip", 16, &e, &n, &st) == 0);
    CHECK(n == 3);
    const void *data[3] = {"123456789", "", big};
    const uint64_t sizes[3] = {9, 0, BIG_BYTES};
    for (size_t i = 0; i < n && i < 3; i++) {
        CHECK(e[i].name_len == strlen(inside[i]) && !memcmp(e[i].name, inside[i], e[i].name_len));
        CHECK(e[i].method == 0 && e[i].flags == 0 && !e[i].is_link);
        CHECK(e[i].csize == sizes[i] && e[i].usize == sizes[i]);
        CHECK(!memcmp(e[i].data, data[i], sizes[i]));
        /* the local header, written before the data and completed after it, agrees */
        const uint8_t *local = e[i].data - 30 - e[i].name_len;
        CHECK(le32(local) == 0x04034b50);
        CHECK(le32(local + 14) == e[i].crc && le32(local + 18) == sizes[i] && le32(local + 22) == sizes[i]);
    }
    if (n == 3) {
        CHECK(e[0].crc == 0xCBF43926u); /* CRC-32 of "123456789" */
        CHECK(e[1].crc == 0);
    }
    size_t len2 = 0; /* the same files give the same bytes */
    uint8_t *again = zip_of(src, 3, &len2, &st);
    CHECK(bytes && again && len2 == len && !memcmp(again, bytes, len));
    free(again);
    free(e);
    free(bytes);
    free(big);
}

static void test_empty_archive(void) {
    mx_status st;
    size_t len = 0, n = 9;
    mx_zip_entry *e = NULL;
    uint8_t *bytes = zip_of(NULL, 0, &len, &st);
    CHECK(bytes && len == 22);
    CHECK(bytes && mx_zip_read(bytes, len, "empty.zip", 16, &e, &n, &st) == 0 && n == 0);
    free(e);
    free(bytes);
}

static void test_missing_source(void) {
    mx_status st;
    mx_status_clear(&st);
    size_t len = 0;
    const char *const files[] = {"check.txt", "nowhere.png"};
    mx_zip_source src[2];
    char paths[2][256];
    sources(src, paths, files, files, 2);
    CHECK(zip_of(src, 2, &len, &st) == NULL);
    CHECK(st.code == MX_EINPUT && strstr(st.msg, "nowhere.png: cannot open"));
}

int main(void) {
    if (!mkdtemp(dir)) return fprintf(stderr, "cannot make %s\n", dir), 1;
    test_round_trip();
    test_empty_archive();
    test_missing_source();
    const char *const files[] = {"check.txt", "empty", "big.bin"};
    for (int i = 0; i < 3; i++) {
        char path[256];
        path_of(path, sizeof path, files[i]);
        unlink(path);
    }
    rmdir(dir);
    return mx_test_finish("test_runtime_zip");
}
