/* EXR input through OpenEXR (pipeline/io/exr_read.cpp), without OpenImageIO: what
 * mx_io_write_exr writes (Y, RGB, RGBA, float, odd sizes, values outside [0, 1]) reads back to
 * the same floats, by file (mx_io_read_image) and from memory (mx_exr_decode); written on 4 threads
 * it is the same file, byte for byte; a truncated file and one whose header lies about an
 * attribute's size fail with a message naming them. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/io/exr_read.h"
#include "../pipeline/io/io.h"
#include "util_test.h"

static unsigned char *read_all(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    unsigned char *buf = malloc(1 << 20);
    *len = f && buf ? fread(buf, 1, 1 << 20, f) : 0;
    if (f) fclose(f);
    return buf;
}

static int same_floats(const mx_image *a, const mx_image *b) {
    return a->data && b->data && a->w == b->w && a->h == b->h && a->c == b->c &&
           !memcmp(a->data, b->data, (size_t)a->w * a->h * a->c * sizeof(float));
}

static void round_trip(const char *dir, int w, int h, int c) {
    mx_image img = {w, h, c, malloc((size_t)w * h * c * sizeof(float))}, back = {0}, mem = {0};
    mx_fill_random(img.data, (size_t)w * h * c, (uint64_t)(w * 31 + c), -2.f, 3.f);
    char path[512];
    snprintf(path, sizeof path, "%s/t%d.exr", dir, c);
    mx_status st;
    CHECK(mx_io_write_exr(path, &img, 1, &st) == 0);
    int ok = mx_io_read_image(path, &back, &st) == 0 && same_floats(&img, &back);
    CHECK(ok);
    size_t len;
    unsigned char *bytes = read_all(path, &len);
    int ok_mem = mx_exr_decode(bytes, len, path, &mem, &st) == 0 && same_floats(&img, &mem);
    CHECK(ok_mem);
    printf("exr %dx%dx%d: %s, %s\n", w, h, c, ok ? "file read back" : "FILE DIFFERS", ok_mem ? "memory read back" : "MEMORY DIFFERS");
    char threaded[512];
    snprintf(threaded, sizeof threaded, "%s/t%d_threads.exr", dir, c);
    CHECK(mx_io_write_exr(threaded, &img, 4, &st) == 0);
    size_t len4;
    unsigned char *bytes4 = read_all(threaded, &len4);
    int same = bytes && bytes4 && len4 == len && !memcmp(bytes, bytes4, len);
    CHECK(same);
    printf("exr %dx%dx%d: written on 4 threads %s\n", w, h, c, same ? "the same bytes" : "DIFFERENT BYTES");
    free(bytes4);
    /* damaged: cut in half, and a header attribute declaring more bytes than the file holds */
    mx_image bad = {0};
    CHECK(mx_exr_decode(bytes, len / 2, "cut.exr", &bad, &st) == -1 && bad.data == NULL && strstr(st.msg, "cut.exr"));
    unsigned char *type = memmem(bytes, len, "chlist", 7); /* the channel list's type; its size follows */
    CHECK(type != NULL);
    if (type) type[7 + 3] = 0x7f;                         /* the size's high byte: 2 GB */
    int refused = mx_exr_decode(bytes, len, "lying.exr", &bad, &st) == -1 && strstr(st.msg, "lying.exr");
    CHECK(refused);
    printf("exr %dx%dx%d: damaged files %s (%s)\n", w, h, c, refused ? "refused" : "NOT REFUSED", st.msg);
    free(bytes);
    free(img.data);
    free(back.data);
    free(mem.data);
}

int main(void) {
    char dir[] = "/tmp/matex_test_exr.XXXXXX";
    if (!mkdtemp(dir)) return 1;
    round_trip(dir, 1, 1, 1);
    round_trip(dir, 17, 5, 3);
    round_trip(dir, 64, 33, 4);
    round_trip(dir, 256, 200, 3); /* 13 blocks of 16 rows for the threads */
    char cmd[64];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd)) printf("could not remove %s\n", dir);
    return mx_test_finish("test_io_exr");
}
