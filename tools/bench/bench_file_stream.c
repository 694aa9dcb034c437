/* The host side of putting a weight file on a GPU (issue 39: 3.6 GB in under 1 s), measured
 * without a GPU on the SD1.5-size fp16 set (bench_sd15.h; or the file given): the file is in the
 * page cache (one read first), then, alternated in each of ROUNDS rounds so that a busy machine
 * affects all alike:
 *   mapped      a fresh mapping copied into one 8 MiB staging buffer by one thread (the per-tensor
 *               upload of before: a page fault per 4 KiB page of the mapping)
 *   stream xN   runtime/file_stream.h with N reader threads into a ring of 4 MiB buffers, the
 *               device copy a no-op (the copy engine's part is not the host's)
 *   digest      the weight file's digest (pipeline/texture/digest.h) read alone, on a pool of all CPUs
 *   stream x2 + digest   the stream with the digest taken from it (what loading onto a GPU does)
 * Prints the median of each in seconds and GB/s. */
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../pipeline/texture/digest.h"
#include "../../runtime/file_stream.h"
#include "../../runtime/log.h"
#include "../../runtime/threadpool.h"
#include "bench_sd15.h"

#define ROUNDS 5
#define STAGING ((size_t)8 << 20)
#define CHUNK ((size_t)4 << 20)
#define IN_FLIGHT 4
#define MAX_READERS 8
#define MODES (3 + 4) /* mapped, digest, stream x2 + digest, stream x1 x2 x4 x8 */

static int noop_copy(void *arg, int slot, const void *buf, size_t n, uint64_t off, mx_status *st) {
    (void)arg, (void)slot, (void)buf, (void)n, (void)off, (void)st;
    return 0;
}

static int noop_wait(void *arg, int slot, mx_status *st) {
    (void)arg, (void)slot, (void)st;
    return 0;
}

/* A fresh mapping copied out through one staging buffer; seconds, or -1. */
static double run_mapped(int fd, size_t len, unsigned char *staging) {
    double t0 = mx_now();
    const unsigned char *m = mmap(NULL, len, PROT_READ, MAP_PRIVATE, fd, 0);
    if (m == MAP_FAILED) return -1;
    for (size_t off = 0; off < len; off += STAGING) memcpy(staging, m + off, len - off < STAGING ? len - off : STAGING);
    munmap((void *)m, len);
    return mx_now() - t0;
}

static void digest_seen(void *arg, const void *buf, size_t n, uint64_t off) { mx_digest_stream_add(arg, buf, n, off); }

/* The stream with `readers` threads, the digest taken from it when pool is not NULL. */
static double run_stream(int fd, const char *path, size_t len, unsigned char **bufs, int readers, mx_pool *pool) {
    mx_stream_ring ring = {bufs, readers + IN_FLIGHT, CHUNK, readers, IN_FLIGHT};
    mx_stream_sink sink = {NULL, noop_copy, noop_wait};
    mx_digest_stream d;
    mx_digest_stream_init(&d, pool, len);
    mx_stream_observer obs = {digest_seen, &d};
    mx_stream_stats stats;
    mx_status st;
    if (mx_file_stream(fd, path, len, &ring, &sink, pool ? &obs : NULL, &stats, &st)) {
        fprintf(stderr, "bench_file_stream: %s\n", st.msg);
        return -1;
    }
    char hex[32];
    mx_digest_stream_hex(&d, hex);
    return pool && !strcmp(hex, "unreadable") ? -1 : stats.wall_s;
}

static double run_digest(mx_pool *pool, const char *path) {
    char hex[32];
    double t0 = mx_now();
    mx_file_digest_hex(pool, path, hex);
    return strcmp(hex, "unreadable") ? mx_now() - t0 : -1;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

int main(int argc, char **argv) {
    char path[1100]; /* bench_sd15_file's folder (1024) and file name */
    if (argc > 1) snprintf(path, sizeof path, "%s", argv[1]);
    else if (bench_sd15_weights(path, sizeof path)) return 1;
    int fd = open(path, O_RDONLY);
    struct stat sb;
    if (fd < 0 || fstat(fd, &sb) != 0) {
        fprintf(stderr, "bench_file_stream: cannot open %s\n", path);
        return 1;
    }
    size_t len = (size_t)sb.st_size;
    long cpus = sysconf(_SC_NPROCESSORS_ONLN);
    mx_status st;
    mx_pool *pool = mx_pool_create(0, &st);
    unsigned char *bufs[MAX_READERS + IN_FLIGHT], *staging = malloc(STAGING);
    for (int i = 0; i < MAX_READERS + IN_FLIGHT; i++) bufs[i] = malloc(CHUNK);
    const char *names[MODES] = {"mapped, 1 thread", "digest, pool", "stream x2 + digest", "stream x1", "stream x2",
                                "stream x4", "stream x8"};
    double t[MODES][ROUNDS];
    printf("%s: %.2f GB, %ld CPUs, %d rounds alternated\n", path, len / 1e9, cpus, ROUNDS);
    run_stream(fd, path, len, bufs, 1, NULL); /* into the page cache */
    int rc = 0;
    for (int r = 0; r < ROUNDS && !rc; r++)
        for (int m = 0; m < MODES && !rc; m++) {
            t[m][r] = m == 0   ? run_mapped(fd, len, staging)
                      : m == 1 ? run_digest(pool, path)
                      : m == 2 ? run_stream(fd, path, len, bufs, 2, pool)
                               : run_stream(fd, path, len, bufs, 1 << (m - 3), NULL);
            rc = t[m][r] < 0;
        }
    for (int m = 0; m < MODES && !rc; m++) {
        qsort(t[m], ROUNDS, sizeof t[m][0], cmp_double);
        printf("  %-18s %.3f s  %5.2f GB/s  (min %.3f, max %.3f)\n", names[m], t[m][ROUNDS / 2],
               len / 1e9 / t[m][ROUNDS / 2], t[m][0], t[m][ROUNDS - 1]);
    }
    for (int i = 0; i < MAX_READERS + IN_FLIGHT; i++) free(bufs[i]);
    free(staging);
    mx_pool_destroy(pool);
    close(fd);
    return rc;
}
