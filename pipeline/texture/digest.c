#include "digest.h"

#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

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

uint64_t mx_digest64(const void *data, uint64_t len) {
    const unsigned char *p = data;
    uint64_t lane[8], n = (len + 7) / 8, i = 0;
    for (int k = 0; k < 8; k++) lane[k] = (len + (uint64_t)k) * 0x9E3779B97F4A7C15ull;
    for (; i + 8 <= n; i += 8)
        for (int k = 0; k < 8; k++) lane[k] = lane_step(lane[k], word_at(p, len, i + k), i + k);
    for (; i < n; i++) lane[i % 8] = lane_step(lane[i % 8], word_at(p, len, i), i);
    uint64_t h = 0;
    for (int k = 0; k < 8; k++) h = mix64(h ^ lane[k]);
    return h;
}

void mx_file_digest_hex(const char *path, char out[32]) {
    snprintf(out, 32, "unreadable");
    int fd = open(path, O_RDONLY);
    if (fd < 0) return;
    struct stat sb;
    if (fstat(fd, &sb) == 0 && sb.st_size > 0) {
        void *map = mmap(NULL, (size_t)sb.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
        if (map != MAP_FAILED) {
            snprintf(out, 32, "%016llx", (unsigned long long)mx_digest64(map, (uint64_t)sb.st_size));
            munmap(map, (size_t)sb.st_size);
        }
    }
    close(fd);
}
