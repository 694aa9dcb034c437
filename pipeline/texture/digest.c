#include "digest.h"

#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

static uint64_t mix64(uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

uint64_t mx_digest64(const void *data, uint64_t len) {
    const unsigned char *p = data;
    uint64_t h = len * 0x9E3779B97F4A7C15ull, n = (len + 7) / 8;
    for (uint64_t i = 0; i < n; i++) {
        uint64_t w = 0;
        uint64_t take = len - i * 8 < 8 ? len - i * 8 : 8;
        for (uint64_t k = 0; k < take; k++) w |= (uint64_t)p[i * 8 + k] << (8 * k);
        h ^= mix64(w + i);
        h = ((h << 27) | (h >> 37)) * 0x94D049BB133111EBull;
    }
    return mix64(h);
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
