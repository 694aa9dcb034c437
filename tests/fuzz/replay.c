/* Replays inputs through a fuzz harness without libFuzzer, so that `make test` (and
 * `make asan`) run every seed and every crash ever found. Arguments: files or folders;
 * without any, the harness's own tests/fuzz/seeds/<H> and tests/fuzz/regress/<H>
 * (the program is named replay_<H>). A crash ends the process: the test fails. */
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fuzz.h"

static int replay_file(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        perror(path);
        return -1;
    }
    uint8_t *buf = NULL;
    size_t n = 0, cap = 0;
    for (;;) {
        if (n == cap) {
            cap = cap ? 2 * cap : 4096;
            uint8_t *nb = realloc(buf, cap);
            if (!nb) break;
            buf = nb;
        }
        size_t got = fread(buf + n, 1, cap - n, f);
        n += got;
        if (!got) break;
    }
    int ok = !ferror(f) && buf;
    fclose(f);
    if (ok) LLVMFuzzerTestOneInput(buf, n);
    free(buf);
    if (!ok) fprintf(stderr, "%s: cannot read\n", path);
    return ok ? 1 : -1;
}

/* Returns the number of inputs replayed, -1 on an unreadable path. */
static int replay_path(const char *path) {
    struct stat sb;
    if (stat(path, &sb)) {
        perror(path);
        return -1;
    }
    if (!S_ISDIR(sb.st_mode)) return replay_file(path);
    DIR *d = opendir(path);
    if (!d) {
        perror(path);
        return -1;
    }
    int count = 0;
    for (struct dirent *e; (e = readdir(d)) && count >= 0;) {
        if (e->d_name[0] == '.') continue;
        char sub[4096];
        snprintf(sub, sizeof sub, "%s/%s", path, e->d_name);
        int r = replay_path(sub);
        count = r < 0 ? -1 : count + r;
    }
    closedir(d);
    return count;
}

int main(int argc, char **argv) {
    const char *base = strrchr(argv[0], '/') ? strrchr(argv[0], '/') + 1 : argv[0];
    const char *harness = strncmp(base, "replay_", 7) ? base : base + 7;
    char dflt[2][256];
    snprintf(dflt[0], sizeof dflt[0], "tests/fuzz/seeds/%s", harness);
    snprintf(dflt[1], sizeof dflt[1], "tests/fuzz/regress/%s", harness);
    int total = 0;
    for (int i = 1; i < (argc > 1 ? argc : 3); i++) {
        const char *p = argc > 1 ? argv[i] : dflt[i - 1];
        struct stat sb;
        if (argc == 1 && i == 2 && stat(p, &sb)) continue; /* no regression input yet */
        int r = replay_path(p);
        if (r < 0) return 1;
        total += r;
    }
    printf("%s: %d inputs replayed without a crash\n", harness, total);
    return total > 0 ? 0 : 1;
}
