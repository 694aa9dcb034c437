/* The file stream of runtime/file_stream.h with a fake device and observer: a copy is only recorded when
 * queued and done (memcpy into host memory) when its buffer is waited for, as an asynchronous
 * device copy reads its buffer some time after it was queued. So a ring that refilled a buffer
 * before waiting for its copy, lost a copy, or queued chunks out of order gives wrong bytes or a
 * failed check. Awkward sizes (empty, one byte, chunk +- 1, odd chunks), ring shapes from one
 * reader to more readers than buffers, and the error paths: a file longer or shorter than said, a
 * file cut while read, an I/O error, a copy or a wait that fails; after each, no copy is left
 * queued. */
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../runtime/file_stream.h"
#include "util_test.h"

#define MAX_BUFS 16

typedef struct {
    unsigned char *dst; /* the "device" */
    uint64_t len;
    unsigned char *const *bufs;
    int queued[MAX_BUFS];     /* per slot: a copy queued and not yet done */
    size_t n[MAX_BUFS];
    uint64_t off[MAX_BUFS];
    uint64_t next_off;        /* chunks must come in file order, back to back */
    int bad_order, overwrite; /* a chunk out of order; a slot refilled under a queued copy */
    long copies, fail_copy_at, fail_wait_at, waits;
    const char *cut_path;     /* cut the file to half its length at the first copy */
    unsigned char *seen;      /* what the observer saw, where it saw it */
    uint64_t seen_next;
    int seen_bad_order;
} fake_device;

/* The observer (a digest in real use): every chunk once, in order, while its copy is queued. */
static void fake_seen(void *arg, const void *buf, size_t n, uint64_t off) {
    fake_device *d = arg;
    if (off != d->seen_next || off + n > d->len) {
        d->seen_bad_order = 1;
        return;
    }
    memcpy(d->seen + off, buf, n);
    d->seen_next = off + n;
}

static int fake_copy(void *arg, int slot, const void *buf, size_t n, uint64_t off, mx_status *st) {
    fake_device *d = arg;
    if (d->copies++ == d->fail_copy_at) return mx_fail(st, MX_EINTERNAL, "fake copy failed");
    if (buf != d->bufs[slot] || off != d->next_off || n == 0 || off + n > d->len) d->bad_order = 1;
    if (d->queued[slot]) d->overwrite = 1;
    d->next_off = off + n;
    d->queued[slot] = 1, d->n[slot] = n, d->off[slot] = off;
    if (d->cut_path && truncate(d->cut_path, (off_t)(d->len / 2)) == 0) d->cut_path = NULL;
    return 0;
}

static int fake_wait(void *arg, int slot, mx_status *st) {
    fake_device *d = arg;
    if (!d->queued[slot]) return 0;
    d->queued[slot] = 0;
    if (d->waits++ == d->fail_wait_at) return mx_fail(st, MX_EINTERNAL, "fake wait failed");
    memcpy(d->dst + d->off[slot], d->bufs[slot], d->n[slot]);
    return 0;
}

static int any_queued(const fake_device *d) {
    for (int i = 0; i < MAX_BUFS; i++)
        if (d->queued[i]) return 1;
    return 0;
}

typedef struct {
    char dir[64], path[96];
    unsigned char *data;
    uint64_t len;
} test_file;

static int file_make(test_file *f, uint64_t len, uint64_t seed) {
    snprintf(f->dir, sizeof f->dir, "/tmp/matex_test_stream.XXXXXX");
    if (!mkdtemp(f->dir)) return -1;
    snprintf(f->path, sizeof f->path, "%s/w.bin", f->dir);
    f->len = len;
    f->data = malloc(len ? len : 1);
    for (uint64_t i = 0; i < len; i++) f->data[i] = (unsigned char)((i * 2654435761u + seed) >> 7);
    FILE *fp = fopen(f->path, "wb");
    int ok = f->data && fp && fwrite(f->data, 1, len, fp) == len;
    if (fp) fclose(fp);
    return ok ? 0 : -1;
}

static void file_free(test_file *f) {
    unlink(f->path);
    rmdir(f->dir);
    free(f->data);
}

typedef struct {
    int nbufs, in_flight, readers;
    size_t chunk;
} ring_shape;

/* Streams f with the ring shape r into a fake device; returns the stream's rc. */
static int stream_into(const test_file *f, int fd, uint64_t len, const ring_shape *r, fake_device *d,
                       mx_stream_stats *stats, mx_status *st) {
    unsigned char *bufs[MAX_BUFS];
    for (int i = 0; i < r->nbufs; i++) bufs[i] = malloc(r->chunk);
    mx_stream_ring ring = {bufs, r->nbufs, r->chunk, r->readers, r->in_flight};
    d->dst = calloc(1, f->len + 1);
    d->seen = calloc(1, f->len + 1);
    d->len = len;
    d->bufs = bufs;
    mx_stream_sink sink = {d, fake_copy, fake_wait};
    mx_stream_observer obs = {fake_seen, d};
    int rc = mx_file_stream(fd, f->path, len, &ring, &sink, &obs, stats, st);
    for (int i = 0; i < r->nbufs; i++) free(bufs[i]);
    return rc;
}

static void test_sizes(void) {
    static const ring_shape rings[] = {
        {2, 1, 1, 7}, {3, 1, 2, 4096}, {8, 2, 4, 65539}, {5, 4, 8, 1}, {16, 2, 12, 1000}, {4, 1, 3, 64},
    };
    for (size_t r = 0; r < sizeof rings / sizeof rings[0]; r++) {
        size_t c = rings[r].chunk;
        uint64_t lens[] = {0, 1, 63, c - 1 ? c - 1 : 2, c, c + 1, 7 * c + 13, c >= 64 ? 300001 : 3001};
        for (size_t l = 0; l < sizeof lens / sizeof lens[0]; l++) {
            test_file f;
            fake_device d = {.fail_copy_at = -1, .fail_wait_at = -1};
            mx_stream_stats stats;
            mx_status st = {0};
            if (file_make(&f, lens[l], r * 31 + l)) {
                CHECK(!"cannot write the test file");
                continue;
            }
            int fd = open(f.path, O_RDONLY);
            int rc = stream_into(&f, fd, f.len, &rings[r], &d, &stats, &st);
            int same = f.len == 0 || (memcmp(d.dst, f.data, f.len) == 0 && memcmp(d.seen, f.data, f.len) == 0);
            same = same && !d.seen_bad_order && d.seen_next == f.len;
            if (rc || !same || d.bad_order || d.overwrite || any_queued(&d) || stats.bytes != f.len)
                fprintf(stderr, "ring %zu (%d bufs of %zu, %d in flight, %d readers), %llu bytes: rc %d same %d order %d "
                        "overwrite %d bytes %llu: %s\n", r, rings[r].nbufs, c, rings[r].in_flight, rings[r].readers,
                        (unsigned long long)f.len, rc, same, d.bad_order, d.overwrite, (unsigned long long)stats.bytes,
                        rc ? st.msg : "");
            CHECK(rc == 0 && same && !d.bad_order && !d.overwrite && !any_queued(&d) && stats.bytes == f.len);
            CHECK(stats.readers >= (f.len ? 1 : 0) && stats.readers <= rings[r].readers);
            close(fd);
            free(d.dst);
            free(d.seen);
            file_free(&f);
        }
    }
}

/* Runs one failing stream; checks it fails with a message holding `want` and leaves no copy queued. */
static void expect_failure(const char *what, const test_file *f, int fd, uint64_t len, fake_device *d, const char *want) {
    ring_shape r = {4, 2, 3, 1000};
    mx_status st = {0};
    int rc = stream_into(f, fd, len, &r, d, NULL, &st);
    int named = strstr(st.msg, want) != NULL;
    if (rc == 0 || !named || any_queued(d)) fprintf(stderr, "%s: rc %d, message '%s'\n", what, rc, st.msg);
    CHECK(rc == -1 && named && !any_queued(d));
    free(d->dst);
    free(d->seen);
}

static void test_errors(void) {
    test_file f;
    if (file_make(&f, 50000, 7)) {
        CHECK(!"cannot write the test file");
        return;
    }
    int fd = open(f.path, O_RDONLY);
    fake_device d = {.fail_copy_at = -1, .fail_wait_at = -1};
    expect_failure("file longer than said", &f, fd, f.len - 1, &d, "is 50000 bytes, expected 49999");
    d = (fake_device){.fail_copy_at = -1, .fail_wait_at = -1};
    expect_failure("file shorter than said", &f, fd, f.len + 64, &d, "expected 50064");
    d = (fake_device){.fail_copy_at = 3, .fail_wait_at = -1};
    expect_failure("a copy fails", &f, fd, f.len, &d, "fake copy failed");
    d = (fake_device){.fail_copy_at = -1, .fail_wait_at = 5};
    expect_failure("a wait fails", &f, fd, f.len, &d, "fake wait failed");
    d = (fake_device){.fail_copy_at = -1, .fail_wait_at = -1, .cut_path = f.path};
    expect_failure("file cut while read", &f, fd, f.len, &d, ", expected 50000 bytes (cut while being read?)"); /* at byte 25000 or, raced, a later chunk */
    close(fd);
    file_free(&f);

    CHECK(file_make(&f, 5000, 9) == 0);
    int wfd = open(f.path, O_WRONLY); /* pread on it fails (EBADF): an I/O error */
    d = (fake_device){.fail_copy_at = -1, .fail_wait_at = -1};
    expect_failure("an I/O error", &f, wfd, f.len, &d, "read error at byte 0");
    close(wfd);

    unsigned char *one[1] = {f.data};
    mx_stream_ring bad = {one, 1, 1000, 1, 1}; /* one buffer cannot hold a copy in flight and a read */
    mx_stream_sink sink = {&d, fake_copy, fake_wait};
    mx_status st = {0};
    fd = open(f.path, O_RDONLY);
    CHECK(mx_file_stream(fd, f.path, f.len, &bad, &sink, NULL, NULL, &st) == -1 && st.code == MX_EINTERNAL &&
          strstr(st.msg, "bad staging ring"));
    close(fd);
    file_free(&f);
}

int main(void) {
    test_sizes();
    test_errors();
    return mx_test_finish("test_runtime_file_stream");
}
