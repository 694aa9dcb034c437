/* A whole file streamed to a device: several host threads read it (pread) into a ring of staging
 * buffers, and the caller's thread hands the chunks, in file order, to a device copy that runs
 * while the next chunks are read. Plain C: the device is the sink's two callbacks (the CUDA
 * backend's are cudaMemcpyAsync + an event per buffer, ops/cuda/cuda_memory.cu; the tests' a
 * memcpy), so the chunking, the ring, the ordering and every error path are tested without a GPU.
 *
 * Why pread and not the mapping: copying 3.6 GB out of a fresh mapping takes a page fault per
 * 4 KiB page (~900 k); pread copies from the page cache into buffers that stay faulted in (the
 * host side measured by tools/bench/bench_file_stream.c). */
#ifndef MX_FILE_STREAM_H
#define MX_FILE_STREAM_H

#include <stddef.h>
#include <stdint.h>

#include "status.h"

/* The device side. copy queues the copy of buf[0, n) (ring buffer `slot`) to byte `off` of the
 * destination and may return before it is done; wait returns once the copies queued from `slot`
 * are done, so that the buffer may be refilled. Both return 0, or -1 with a message in st. */
typedef struct mx_stream_sink {
    void *arg;
    int (*copy)(void *arg, int slot, const void *buf, size_t n, uint64_t off, mx_status *st);
    int (*wait)(void *arg, int slot, mx_status *st);
} mx_stream_sink;

/* Optional: sees every chunk in file order, on the caller's thread, once its copy is queued (so
 * that the copy runs meanwhile): a digest of the file computed from the same pass. */
typedef struct mx_stream_observer {
    void (*seen)(void *arg, const void *buf, size_t n, uint64_t off);
    void *arg;
} mx_stream_observer;

/* The ring: nbufs buffers of chunk bytes each (chunk k of the file goes through buffer k % nbufs),
 * `readers` host threads, and at most in_flight + 1 copies queued at a time (the readers run up to
 * nbufs - in_flight chunks ahead of the copies). Needs nbufs > in_flight >= 1, readers >= 1. */
typedef struct mx_stream_ring {
    unsigned char *const *bufs;
    int nbufs;
    size_t chunk;
    int readers, in_flight;
} mx_stream_ring;

/* Where the time went (seconds of the caller's thread unless said otherwise). */
typedef struct mx_stream_stats {
    double wall_s;      /* the whole stream, threads started and joined */
    double read_s;      /* in pread, summed over the reader threads */
    double fill_wait_s; /* waiting for a chunk to be read (the stream was read-bound) */
    double copy_wait_s; /* waiting for a buffer's copy to finish (the stream was copy-bound) */
    double seen_s;      /* in the observer */
    uint64_t bytes;     /* handed to the sink */
    int readers;        /* threads that ran */
} mx_stream_stats;

/* Streams bytes [0, len) of the open file fd (path names it in messages) to the sink, showing each
 * chunk to obs (NULL: none); the chunks start at multiples of the ring's chunk size. The file
 * must be len bytes long; a file that is shorter or longer, a read that ends early (the file cut
 * while read), an I/O error or a failing copy stops the stream with one message naming the file,
 * the offset and the cause. Every copy queued has completed (waited for) when this returns,
 * whether it succeeded or not, so the buffers may be freed. stats may be NULL. */
int mx_file_stream(int fd, const char *path, uint64_t len, const mx_stream_ring *ring, const mx_stream_sink *sink,
                   const mx_stream_observer *obs, mx_stream_stats *stats, mx_status *st);

#endif
