#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../runtime/log.h"
#include "fuzz.h"

#define FUZZ_MAX_FILES 8

/* Harness-side state (a test driver, not the product): the temporary folder of this
 * process and the names written into it, removed at exit. */
static char dir[256];
static char names[FUZZ_MAX_FILES][64];
static char paths[FUZZ_MAX_FILES][512];

static void remove_files(void) {
    for (int i = 0; i < FUZZ_MAX_FILES && names[i][0]; i++) unlink(paths[i]);
    rmdir(dir);
}

static void make_dir(void) {
    const char *t = getenv("TMPDIR");
    snprintf(dir, sizeof dir, "%s/matex-fuzz-%ld", t && *t ? t : "/tmp", (long)getpid());
    if (mkdir(dir, 0700) && access(dir, W_OK)) {
        perror(dir);
        exit(2);
    }
    atexit(remove_files);
}

static int slot_of(const char *name) {
    for (int i = 0; i < FUZZ_MAX_FILES; i++) {
        if (!names[i][0]) {
            snprintf(names[i], sizeof names[i], "%s", name);
            snprintf(paths[i], sizeof paths[i], "%s/%s", dir, name);
        }
        if (!strcmp(names[i], name)) return i;
    }
    fprintf(stderr, "fuzz_file: more than %d file names\n", FUZZ_MAX_FILES);
    exit(2);
}

const char *fuzz_file(const char *name, const void *data, size_t len) {
    if (!dir[0]) make_dir();
    const char *path = paths[slot_of(name)];
    FILE *f = fopen(path, "wb");
    if (!f || (len && fwrite(data, 1, len, f) != len) || fclose(f)) {
        perror(path);
        exit(2);
    }
    return path;
}

void fuzz_split(const uint8_t *data, size_t size, const char *sep, size_t *first_len, const uint8_t **rest,
                size_t *rest_len) {
    size_t n = strlen(sep);
    for (size_t i = 0; n && i + n <= size; i++)
        if (!memcmp(data + i, sep, n)) {
            *first_len = i;
            *rest = data + i + n;
            *rest_len = size - i - n;
            return;
        }
    *first_len = size;
    *rest = NULL;
    *rest_len = 0;
}

void fuzz_quiet(void) { mx_log_set_level(MX_LOG_ERROR); }
