/* A whole file streamed to a device through a ring of staging buffers (file_stream.h).
 *
 * Slot s of the ring holds chunks s, s + nbufs, s + 2 nbufs, ... in turn. A reader claims the next
 * chunk k, waits until its slot has been released for k (the copy of chunk k - nbufs is done),
 * reads it and marks it filled. The caller's thread takes the chunks in file order: waits until
 * chunk k is filled, queues its copy, and releases the slot of chunk k - in_flight once that copy
 * is done. One mutex guards the ring's state; readers and the caller wait on one condition each. */
#include "file_stream.h"

#include <errno.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#include "log.h"

#define STREAM_MAX_READERS 64

typedef struct {
    int fd;
    const char *path;
    uint64_t len, nchunks;
    const mx_stream_ring *ring;
    pthread_mutex_t mu;
    pthread_cond_t slot_free, chunk_filled;
    uint64_t next_claim; /* the next chunk a reader takes */
    uint64_t *free_for;  /* per slot: the chunk it may receive */
    uint64_t *filled;    /* per slot: the chunk it holds + 1 (0: none) */
    int failed;          /* the first failure is in err; everyone stops */
    mx_status err;
    double read_s;
} stream;

static size_t chunk_bytes(const stream *s, uint64_t k) {
    uint64_t off = k * s->ring->chunk;
    return (size_t)(s->len - off < s->ring->chunk ? s->len - off : s->ring->chunk);
}

/* Records the first failure and wakes every waiter; call with mu held. */
static void fail_locked(stream *s, const mx_status *why) {
    if (!s->failed) s->err = *why;
    s->failed = 1;
    pthread_cond_broadcast(&s->slot_free);
    pthread_cond_broadcast(&s->chunk_filled);
}

/* All of buf[0, n) from offset off: 0, or -1 naming the offset of the early end or the error. */
static int read_all(const stream *s, unsigned char *buf, size_t n, uint64_t off, mx_status *st) {
    while (n > 0) {
        ssize_t got = pread(s->fd, buf, n, (off_t)off);
        if (got < 0 && errno == EINTR) continue;
        if (got < 0) return mx_fail(st, MX_EIO, "%s: read error at byte %llu: %s", s->path, (unsigned long long)off, strerror(errno));
        if (got == 0)
            return mx_fail(st, MX_EIO, "%s: ends at byte %llu, expected %llu bytes (cut while being read?)", s->path,
                           (unsigned long long)off, (unsigned long long)s->len);
        buf += got, n -= (size_t)got, off += (uint64_t)got;
    }
    return 0;
}

static void *reader_main(void *arg) {
    stream *s = arg;
    pthread_mutex_lock(&s->mu);
    while (!s->failed && s->next_claim < s->nchunks) {
        uint64_t k = s->next_claim++;
        int slot = (int)(k % (uint64_t)s->ring->nbufs);
        while (!s->failed && s->free_for[slot] != k) pthread_cond_wait(&s->slot_free, &s->mu);
        if (s->failed) break;
        pthread_mutex_unlock(&s->mu);
        mx_status st;
        double t0 = mx_now();
        int rc = read_all(s, s->ring->bufs[slot], chunk_bytes(s, k), k * s->ring->chunk, &st);
        double t = mx_now() - t0;
        pthread_mutex_lock(&s->mu);
        s->read_s += t;
        if (rc) {
            fail_locked(s, &st);
            break;
        }
        s->filled[slot] = k + 1;
        pthread_cond_broadcast(&s->chunk_filled);
    }
    pthread_mutex_unlock(&s->mu);
    return NULL;
}

/* Waits until chunk k is in its slot; -1 once any thread failed. */
static int wait_filled(stream *s, uint64_t k, mx_stream_stats *stats) {
    int slot = (int)(k % (uint64_t)s->ring->nbufs);
    double t0 = mx_now();
    pthread_mutex_lock(&s->mu);
    while (!s->failed && s->filled[slot] != k + 1) pthread_cond_wait(&s->chunk_filled, &s->mu);
    int rc = s->failed ? -1 : 0;
    pthread_mutex_unlock(&s->mu);
    stats->fill_wait_s += mx_now() - t0;
    return rc;
}

/* Waits for the copy of chunk k and gives its slot to chunk k + nbufs. */
static int release_chunk(stream *s, const mx_stream_sink *sink, uint64_t k, mx_stream_stats *stats) {
    int slot = (int)(k % (uint64_t)s->ring->nbufs);
    mx_status st;
    double t0 = mx_now();
    int rc = sink->wait(sink->arg, slot, &st);
    stats->copy_wait_s += mx_now() - t0;
    pthread_mutex_lock(&s->mu);
    if (rc) fail_locked(s, &st);
    s->filled[slot] = 0;
    s->free_for[slot] = k + (uint64_t)s->ring->nbufs;
    pthread_cond_broadcast(&s->slot_free);
    pthread_mutex_unlock(&s->mu);
    return rc;
}

static void fail_now(stream *s, const mx_status *why) {
    pthread_mutex_lock(&s->mu);
    fail_locked(s, why);
    pthread_mutex_unlock(&s->mu);
}

/* The caller's part: every chunk in order to the sink; then the copies still queued waited for
 * (also after a failure: the buffers must not be freed under a running copy). */
static void copy_in_order(stream *s, const mx_stream_sink *sink, const mx_stream_observer *obs,
                          mx_stream_stats *stats) {
    const mx_stream_ring *r = s->ring;
    uint64_t queued = 0, released = 0;
    for (uint64_t k = 0; k < s->nchunks; k++) {
        if (wait_filled(s, k, stats)) break;
        mx_status st;
        int slot = (int)(k % (uint64_t)r->nbufs);
        size_t n = chunk_bytes(s, k);
        if (sink->copy(sink->arg, slot, r->bufs[slot], n, k * r->chunk, &st)) {
            fail_now(s, &st);
            break;
        }
        queued = k + 1;
        stats->bytes += n;
        if (obs) {
            double t0 = mx_now();
            obs->seen(obs->arg, r->bufs[slot], n, k * r->chunk);
            stats->seen_s += mx_now() - t0;
        }
        if (queued - released > (uint64_t)r->in_flight && release_chunk(s, sink, released++, stats)) break;
    }
    while (released < queued) release_chunk(s, sink, released++, stats);
}

static int check_ring(const char *path, const mx_stream_ring *r, mx_status *st) {
    if (!r->bufs || r->chunk == 0 || r->in_flight < 1 || r->nbufs <= r->in_flight || r->readers < 1)
        return mx_fail(st, MX_EINTERNAL, "%s: bad staging ring (%d buffers of %zu bytes, %d in flight, %d readers)",
                       path, r->nbufs, r->chunk, r->in_flight, r->readers);
    for (int i = 0; i < r->nbufs; i++)
        if (!r->bufs[i]) return mx_fail(st, MX_EINTERNAL, "%s: staging buffer %d missing", path, i);
    return 0;
}

static int check_length(int fd, const char *path, uint64_t len, mx_status *st) {
    struct stat sb;
    if (fstat(fd, &sb) != 0) return mx_fail(st, MX_EIO, "%s: cannot stat: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: not a regular file", path);
    if ((uint64_t)sb.st_size != len)
        return mx_fail(st, MX_EINPUT, "%s: is %llu bytes, expected %llu (changed since it was opened?)", path,
                       (unsigned long long)sb.st_size, (unsigned long long)len);
    return 0;
}

static int stream_init(stream *s, int fd, const char *path, uint64_t len, const mx_stream_ring *r, mx_status *st) {
    memset(s, 0, sizeof *s);
    s->fd = fd;
    s->path = path;
    s->len = len;
    s->ring = r;
    s->nchunks = len / r->chunk + (len % r->chunk != 0);
    s->free_for = calloc((size_t)r->nbufs, sizeof *s->free_for);
    s->filled = calloc((size_t)r->nbufs, sizeof *s->filled);
    if (!s->free_for || !s->filled) {
        free(s->free_for);
        free(s->filled);
        return mx_fail(st, MX_ENOMEM, "%s: out of memory for the staging ring", path);
    }
    for (int i = 0; i < r->nbufs; i++) s->free_for[i] = (uint64_t)i;
    pthread_mutex_init(&s->mu, NULL);
    pthread_cond_init(&s->slot_free, NULL);
    pthread_cond_init(&s->chunk_filled, NULL);
    return 0;
}

static void stream_fini(stream *s) {
    pthread_cond_destroy(&s->chunk_filled);
    pthread_cond_destroy(&s->slot_free);
    pthread_mutex_destroy(&s->mu);
    free(s->free_for);
    free(s->filled);
}

/* More readers than chunks, or than the ring lets run ahead, would only wait. */
static int readers_wanted(const stream *s) {
    uint64_t n = (uint64_t)s->ring->readers;
    uint64_t ahead = (uint64_t)(s->ring->nbufs - s->ring->in_flight);
    if (n > ahead) n = ahead;
    if (n > s->nchunks) n = s->nchunks;
    return (int)(n < STREAM_MAX_READERS ? n : STREAM_MAX_READERS);
}

int mx_file_stream(int fd, const char *path, uint64_t len, const mx_stream_ring *ring, const mx_stream_sink *sink,
                   const mx_stream_observer *obs, mx_stream_stats *stats, mx_status *st) {
    mx_stream_stats local;
    if (!stats) stats = &local;
    memset(stats, 0, sizeof *stats);
    double t0 = mx_now();
    if (check_ring(path, ring, st) || check_length(fd, path, len, st)) return -1;
    stream s;
    if (stream_init(&s, fd, path, len, ring, st)) return -1;
    pthread_t tid[STREAM_MAX_READERS];
    int want = readers_wanted(&s), started = 0;
    while (started < want && pthread_create(&tid[started], NULL, reader_main, &s) == 0) started++;
    if (started == 0 && want > 0) {
        stream_fini(&s);
        return mx_fail(st, MX_ENOMEM, "%s: cannot start a reader thread", path);
    }
    /* Every path out of it either copied all chunks (so each reader has run out of chunks) or
     * marked the stream failed (which wakes each reader): the joins cannot hang. */
    copy_in_order(&s, sink, obs, stats);
    for (int i = 0; i < started; i++) pthread_join(tid[i], NULL);
    int rc = s.failed ? -1 : 0;
    if (rc && st) *st = s.err;
    stats->read_s = s.read_s;
    stats->readers = started;
    stats->wall_s = mx_now() - t0;
    stream_fini(&s);
    return rc;
}
