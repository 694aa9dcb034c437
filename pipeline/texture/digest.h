/* A fast 64-bit digest of a file, to identify the weights a texture was made with.
 * "mxd64": the file is read as 8-byte little-endian words w_i (the tail zero-padded); eight
 * lanes k = 0..7 start at h_k = (len + k) * 0x9E3779B97F4A7C15 and take the words i = k mod 8:
 * h_k = rotl(h_k ^ mix(w_i + i), 27) * 0x94D049BB133111EB, mix = the splitmix64 finaliser;
 * then h = 0; for k: h = mix(h ^ h_k). Eight independent lanes keep it near memory speed.
 * Not cryptographic. */
#ifndef MX_DIGEST_H
#define MX_DIGEST_H

#include <stdint.h>

#include "../../runtime/threadpool.h"

/* Writes 16 hex digits + NUL into out (at least 17 bytes); "unreadable" when the file can't be
 * read. The lanes are split over the pool's threads (NULL: this thread), the value the same. */
void mx_file_digest_hex(mx_pool *pool, const char *path, char out[32]);
uint64_t mx_digest64(const void *data, uint64_t len);
/* The file digest of bytes read once for another purpose (the weight file's stream to a GPU):
 * mx_digest_stream_add takes the file's chunks in order, back to back, each starting at a
 * multiple of 64 bytes (the lanes' round); mx_digest_stream_hex then writes what
 * mx_file_digest_hex would, or "unreadable" unless exactly the len bytes were added that way. */
typedef struct mx_digest_stream {
    mx_pool *pool;
    int simd; /* the lanes in one AVX-512 register (digest.c) */
    uint64_t lane[8];
    uint64_t len, next; /* the file's length; the offset the next chunk must start at */
    int broken;         /* a chunk out of order or misaligned */
} mx_digest_stream;
void mx_digest_stream_init(mx_digest_stream *d, mx_pool *pool, uint64_t len);
void mx_digest_stream_add(mx_digest_stream *d, const void *chunk, uint64_t n, uint64_t off);
void mx_digest_stream_hex(const mx_digest_stream *d, char out[32]);
uint64_t mx_digest64_on(mx_pool *pool, const void *data, uint64_t len);

#endif
