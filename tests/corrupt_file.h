/* Hostile-file loops shared by the weight readers' tests (test_weights_safetensors.c,
 * test_weights_weightfile.c): a file's bytes, then every truncation of them and every byte set to
 * each of a few values, each written to one path and judged by the caller. Header-only. */
#ifndef MX_TEST_CORRUPT_FILE_H
#define MX_TEST_CORRUPT_FILE_H

#include <stdio.h>
#include <stdlib.h>

static inline int write_bytes(const char *path, const void *p, size_t n) {
    FILE *f = fopen(path, "wb");
    if (!f) return -1;
    size_t w = fwrite(p, 1, n, f);
    fclose(f);
    if (w != n) fprintf(stderr, "short write %s\n", path);
    return w == n ? 0 : -1;
}

static inline unsigned char *read_bytes(const char *path, size_t *n) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long len = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *p = malloc((size_t)len + 1);
    *n = p ? fread(p, 1, (size_t)len, f) : 0;
    fclose(f);
    return p;
}

/* 1 when the reader handled the file at `path` as it must (a clean error naming the file, or,
 * where allowed, a valid and fully readable file), else 0. */
typedef int (*corrupt_judge)(const char *path);

/* Writes each truncation buf[0..cut), cut < n, to path; returns how many the judge refused. */
static inline int each_truncation(const char *path, const unsigned char *buf, size_t n, corrupt_judge judge) {
    int refused = 0;
    for (size_t cut = 0; cut < n; cut++) {
        write_bytes(path, buf, cut);
        refused += !judge(path);
    }
    return refused;
}

/* Writes buf with each byte in turn set to each of vals[0..nvals) to path (buf is restored);
 * returns how many the judge refused. */
static inline int each_byte_set(const char *path, unsigned char *buf, size_t n, const unsigned char *vals, int nvals,
                                corrupt_judge judge) {
    int refused = 0;
    for (size_t pos = 0; pos < n; pos++) {
        unsigned char saved = buf[pos];
        for (int v = 0; v < nvals; v++) {
            buf[pos] = vals[v];
            write_bytes(path, buf, n);
            refused += !judge(path);
        }
        buf[pos] = saved;
    }
    return refused;
}

#endif
