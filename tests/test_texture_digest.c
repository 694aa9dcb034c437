/* The weight-file digest (pipeline/texture/digest.h, "mxd64"): the value against a plain
 * word-by-word reading of its definition, on every length around the 8-word rounds; the lanes
 * split over pools of 1, 2, 3, 5 and 8 threads give the same value; a file's digest is its
 * bytes' digest (one chunk, and several), and a file that can't be read says so; the digest fed
 * chunk by chunk (mx_digest_stream) is the file's. All of it on the AVX-512 lanes (where the CPU has
 * them) and on the scalar lanes. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/texture/digest.h"
#include "util_test.h"

static uint64_t mix(uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/* The definition of digest.h, word by word in file order. */
static uint64_t digest_by_definition(const unsigned char *p, uint64_t len) {
    uint64_t h[8];
    for (int k = 0; k < 8; k++) h[k] = (len + (uint64_t)k) * 0x9E3779B97F4A7C15ull;
    for (uint64_t i = 0; i * 8 < len; i++) {
        uint64_t w = 0;
        for (uint64_t b = 0; b < 8 && i * 8 + b < len; b++) w |= (uint64_t)p[i * 8 + b] << (8 * b);
        uint64_t x = h[i % 8] ^ mix(w + i);
        h[i % 8] = ((x << 27) | (x >> 37)) * 0x94D049BB133111EBull;
    }
    uint64_t d = 0;
    for (int k = 0; k < 8; k++) d = mix(d ^ h[k]);
    return d;
}

static void test_lengths_and_pools(const unsigned char *buf, size_t big) {
    int threads[] = {1, 2, 3, 5, 8};
    for (size_t t = 0; t < sizeof threads / sizeof *threads; t++) {
        mx_status st = {0};
        mx_pool *pool = mx_pool_create(threads[t], &st);
        CHECK(pool != NULL);
        for (uint64_t len = 0; len <= 200; len++) {
            uint64_t want = digest_by_definition(buf, len);
            CHECK(mx_digest64(buf, len) == want);
            CHECK(mx_digest64_on(pool, buf, len) == want);
        }
        CHECK(mx_digest64_on(pool, buf, big) == digest_by_definition(buf, big));
        mx_pool_destroy(pool);
    }
}

static void test_file(const unsigned char *buf, size_t n) {
    char dir[] = "/tmp/matex_test_digest.XXXXXX", path[64], hex[32], want[32];
    CHECK(mkdtemp(dir) != NULL);
    snprintf(path, sizeof path, "%s/w.bin", dir);
    FILE *f = fopen(path, "wb");
    CHECK(f && fwrite(buf, 1, n, f) == n);
    if (f) fclose(f);
    mx_status st = {0};
    mx_pool *pool = mx_pool_create(2, &st);
    snprintf(want, sizeof want, "%016llx", (unsigned long long)digest_by_definition(buf, n));
    mx_file_digest_hex(pool, path, hex);
    CHECK(!strcmp(hex, want));
    mx_file_digest_hex(NULL, path, hex);
    CHECK(!strcmp(hex, want));
    unlink(path);
    mx_file_digest_hex(pool, path, hex);
    CHECK(!strcmp(hex, "unreadable"));
    rmdir(dir);
    mx_pool_destroy(pool);
}

/* The digest fed chunk by chunk (a weight file's stream to a GPU) equals the file digest, for
 * chunks of any multiple of 64 bytes and a short last one; chunks out of order, misaligned, or
 * missing give "unreadable". */
static void test_stream(const unsigned char *buf, size_t n) {
    char hex[32], want[32];
    mx_status st = {0};
    mx_pool *pool = mx_pool_create(2, &st);
    snprintf(want, sizeof want, "%016llx", (unsigned long long)digest_by_definition(buf, n));
    static const size_t chunks[] = {64, 4096, 65536 * 3 + 64, (size_t)4 << 20};
    for (size_t c = 0; c < sizeof chunks / sizeof chunks[0]; c++) {
        mx_digest_stream d;
        mx_digest_stream_init(&d, c % 2 ? pool : NULL, n);
        for (size_t off = 0; off < n; off += chunks[c]) mx_digest_stream_add(&d, buf + off, n - off < chunks[c] ? n - off : chunks[c], off);
        mx_digest_stream_hex(&d, hex);
        CHECK(!strcmp(hex, want));
    }
    mx_digest_stream d;
    mx_digest_stream_init(&d, NULL, n); /* the second chunk before the first */
    mx_digest_stream_add(&d, buf + 4096, n - 4096, 4096);
    mx_digest_stream_add(&d, buf, 4096, 0);
    mx_digest_stream_hex(&d, hex);
    CHECK(!strcmp(hex, "unreadable"));
    mx_digest_stream_init(&d, NULL, n); /* a chunk boundary inside a lane round */
    mx_digest_stream_add(&d, buf, 100, 0);
    mx_digest_stream_add(&d, buf + 100, n - 100, 100);
    mx_digest_stream_hex(&d, hex);
    CHECK(!strcmp(hex, "unreadable"));
    mx_digest_stream_init(&d, NULL, n); /* the tail never added */
    mx_digest_stream_add(&d, buf, 4096, 0);
    mx_digest_stream_hex(&d, hex);
    CHECK(!strcmp(hex, "unreadable"));
    mx_pool_destroy(pool);
}

int main(void) {
    size_t big = (size_t)1 << 20 | 13;  /* past many rounds, and not a whole one */
    size_t file = (size_t)3 << 20 | 13; /* a file read in 4 chunks (digest.c), the last one short */
    unsigned char *buf = malloc(file);
    CHECK(buf != NULL);
    if (!buf) return 1;
    uint32_t s = 12345;
    for (size_t i = 0; i < file; i++) buf[i] = (unsigned char)((s = s * 1664525u + 1013904223u) >> 24);
    /* twice: as this CPU runs it (the AVX-512 lanes where it has them), then the scalar lanes split
     * over the pool (MATEX_ISA below avx512, read at each digest) */
    for (int pass = 0; pass < 2; pass++) {
        if (pass == 1) setenv("MATEX_ISA", "avx2", 1);
        test_lengths_and_pools(buf, big);
        test_file(buf, 4099);
        test_file(buf, file);
        test_stream(buf, file);
    }
    unsetenv("MATEX_ISA");
    free(buf);
    if (mx_test_failures) fprintf(stderr, "test_texture_digest: %d failures\n", mx_test_failures);
    else printf("test_texture_digest: all checks passed\n");
    return mx_test_failures != 0;
}
