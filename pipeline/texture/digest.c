#include "digest.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../runtime/backend.h" /* mx_cpu_best_isa */

#if defined(__x86_64__) && !defined(MX_NO_X86_SIMD)
#include <immintrin.h>
#define DIGEST_AVX512 1
#endif

#define LITTLE_ENDIAN_HOST (__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__)

static uint64_t mix64(uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static uint64_t word_at(const unsigned char *p, uint64_t len, uint64_t i) {
    uint64_t w = 0, take = len - i * 8 < 8 ? len - i * 8 : 8;
    if (take == 8 && LITTLE_ENDIAN_HOST)
        memcpy(&w, p + i * 8, 8);
    else
        for (uint64_t k = 0; k < take; k++) w |= (uint64_t)p[i * 8 + k] << (8 * k);
    return w;
}

static uint64_t lane_step(uint64_t h, uint64_t w, uint64_t i) {
    h ^= mix64(w + i);
    return ((h << 27) | (h >> 37)) * 0x94D049BB133111EBull;
}

static void lanes_init(uint64_t *lane, uint64_t len) {
    for (int k = 0; k < 8; k++) lane[k] = (len + (uint64_t)k) * 0x9E3779B97F4A7C15ull;
}

static uint64_t lanes_final(const uint64_t *lane) {
    uint64_t h = 0;
    for (int k = 0; k < 8; k++) h = mix64(h ^ lane[k]);
    return h;
}

/* Lanes k0..k1-1 (lane k takes the words k, k+8, ...) over one chunk of the input: the bytes
 * p[0, len) whose first word is word `first` of the input (a multiple of 8: lane k takes the
 * chunk's words k, k+8, ...). Lanes are independent, so threads may take disjoint sets of them. */
static void digest_lanes(const unsigned char *p, uint64_t len, uint64_t first, int k0, int k1, uint64_t *lane) {
    uint64_t h[8], n = (len + 7) / 8, i = 0; /* h: this thread's own copy (no false sharing) */
    for (int k = k0; k < k1; k++) h[k] = lane[k];
    for (; i + 8 <= n; i += 8)
        for (int k = k0; k < k1; k++) h[k] = lane_step(h[k], word_at(p, len, i + k), first + i + k);
    for (int k = k0; k < k1; k++)
        if (i + (uint64_t)k < n) h[k] = lane_step(h[k], word_at(p, len, i + k), first + i + k);
    for (int k = k0; k < k1; k++) lane[k] = h[k];
}

#ifdef DIGEST_AVX512

/* The eight lanes in one register over `rounds` whole rounds of 64 bytes: lane_step on eight
 * words at once (vpmullq), the same values as digest_lanes. Only called where the CPU has AVX-512
 * F and DQ (digest_simd). */
__attribute__((target("avx512f,avx512dq"))) static void digest_rounds_avx512(const unsigned char *p, uint64_t rounds,
                                                                             uint64_t first, uint64_t *lane) {
    const __m512i c1 = _mm512_set1_epi64((long long)0xBF58476D1CE4E5B9ull),
                  c2 = _mm512_set1_epi64((long long)0x94D049BB133111EBull), eight = _mm512_set1_epi64(8);
    __m512i h = _mm512_loadu_si512(lane), idx = _mm512_add_epi64(_mm512_set1_epi64((long long)first),
                                                                _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7));
    for (uint64_t r = 0; r < rounds; r++) {
        __m512i z = _mm512_add_epi64(_mm512_loadu_si512(p + 64 * r), idx); /* mix64(w + i) */
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 30)), c1);
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 27)), c2);
        z = _mm512_xor_si512(z, _mm512_srli_epi64(z, 31));
        h = _mm512_mullo_epi64(_mm512_rol_epi64(_mm512_xor_si512(h, z), 27), c2);
        idx = _mm512_add_epi64(idx, eight);
    }
    _mm512_storeu_si512(lane, h);
}
#endif

/* 1 where the lanes run as one AVX-512 register: x86 with AVX-512 F/DQ (not lowered by MATEX_ISA)
 * and a pool of fewer than DIGEST_SIMD_BELOW threads. The register's chain (xor, rotate, vpmullq:
 * ~17 cycles a round of 64 bytes) is one thread's; the scalar lanes split over 4 or more threads run
 * 4+ chains of ~5 cycles a word at once, so many threads are faster in that model. Measured on 2
 * shared vCPUs (Xeon EMR, 3.58 GB from the page cache): one register 1.0-1.4 s, the scalar lanes on
 * both threads 2.4-2.9 s. */
#define DIGEST_SIMD_BELOW 4
static int digest_simd(mx_pool *pool) {
#ifdef DIGEST_AVX512
    return mx_pool_threads(pool) < DIGEST_SIMD_BELOW && mx_isa_min(MX_ISA_AVX512, mx_cpu_best_isa()) == MX_ISA_AVX512;
#else
    (void)pool;
    return 0;
#endif
}

typedef struct {
    const unsigned char *p;
    uint64_t len, first;
    int per; /* lanes per task */
    uint64_t *lane;
} digest_job;

static void digest_task(void *arg, int task, int thread) {
    (void)thread;
    digest_job *j = arg;
    int k0 = task * j->per, k1 = k0 + j->per < 8 ? k0 + j->per : 8;
    digest_lanes(j->p, j->len, j->first, k0, k1, j->lane);
}

/* One chunk into the lanes: its whole rounds in one register where simd (the pool unused), else
 * the lanes split over the pool's threads; the last partial round by digest_lanes. */
static void digest_chunk(mx_pool *pool, int simd, const unsigned char *p, uint64_t len, uint64_t first,
                         uint64_t *lane) {
#ifdef DIGEST_AVX512
    if (simd) {
        uint64_t rounds = len / 64;
        digest_rounds_avx512(p, rounds, first, lane);
        digest_lanes(p + 64 * rounds, len - 64 * rounds, first + 8 * rounds, 0, 8, lane);
        return;
    }
#else
    (void)simd;
#endif
    int threads = mx_pool_threads(pool), per = threads >= 8 ? 1 : (8 + threads - 1) / threads;
    digest_job j = {.p = p, .len = len, .first = first, .per = per, .lane = lane};
    mx_pool_for(pool, (8 + per - 1) / per, digest_task, &j);
}

uint64_t mx_digest64_on(mx_pool *pool, const void *data, uint64_t len) {
    uint64_t lane[8];
    lanes_init(lane, len);
    digest_chunk(pool, digest_simd(pool), data, len, 0, lane);
    return lanes_final(lane);
}

uint64_t mx_digest64(const void *data, uint64_t len) { return mx_digest64_on(NULL, data, len); }

/* All of buf[0, n) from the file at off; 0, or -1 on an error or an early end. */
static int read_at(int fd, unsigned char *buf, size_t n, off_t off) {
    while (n > 0) {
        ssize_t got = pread(fd, buf, n, off);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return -1;
        buf += got, n -= (size_t)got, off += got;
    }
    return 0;
}

/* Read in chunks through one buffer rather than mapped: each 4 KiB page of a mapping costs a page
 * walk (touching one word per page of 3.6 GB of SD1.5 weights: ~1 s in a VM), a reused buffer
 * none, and the lanes' threads read each chunk from the cache. 3.6 GB, Zen 5 VM, 2 threads, in
 * the page cache: 2.0 s mapped, 0.9 s read (1, 4 or 16 MiB chunks alike). */
#define DIGEST_CHUNK ((size_t)1 << 20) /* a multiple of 64 bytes: chunks start at a lane-0 word */

void mx_digest_stream_init(mx_digest_stream *d, mx_pool *pool, uint64_t len) {
    memset(d, 0, sizeof *d);
    d->pool = pool;
    d->simd = digest_simd(pool);
    d->len = len;
    lanes_init(d->lane, len);
}

void mx_digest_stream_add(mx_digest_stream *d, const void *chunk, uint64_t n, uint64_t off) {
    if (off != d->next || off % 64 || n > d->len - off) d->broken = 1;
    if (d->broken) return;
    digest_chunk(d->pool, d->simd, chunk, n, off / 8, d->lane);
    d->next = off + n;
}

void mx_digest_stream_hex(const mx_digest_stream *d, char out[32]) {
    if (d->broken || d->next != d->len) snprintf(out, 32, "unreadable");
    else snprintf(out, 32, "%016llx", (unsigned long long)lanes_final(d->lane));
}

void mx_file_digest_hex(mx_pool *pool, const char *path, char out[32]) {
    snprintf(out, 32, "unreadable");
    int fd = open(path, O_RDONLY);
    if (fd < 0) return;
    struct stat sb;
    unsigned char *buf = malloc(DIGEST_CHUNK);
    if (buf && fstat(fd, &sb) == 0 && sb.st_size > 0) {
        mx_digest_stream d;
        mx_digest_stream_init(&d, pool, (uint64_t)sb.st_size);
        for (uint64_t off = 0; off < d.len; off += DIGEST_CHUNK) {
            size_t n = d.len - off < DIGEST_CHUNK ? (size_t)(d.len - off) : DIGEST_CHUNK;
            if (read_at(fd, buf, n, (off_t)off)) break;
            mx_digest_stream_add(&d, buf, n, off);
        }
        mx_digest_stream_hex(&d, out);
    }
    free(buf);
    close(fd);
}
