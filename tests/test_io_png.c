/* matex's zlib PNG codec (pipeline/io/png_zlib.c) against OpenImageIO (libmatex_oiio.so, opened
 * here as image_files.c opens it): what ours writes both read back to the same floats, for 1, 3
 * and 4 channels (RGBA unpremultiplied) and odd sizes; a grey+alpha image with every row filter
 * (None, Sub, Up, Average, Paeth) decodes to its pixels widened to RGBA; damaged and unsupported
 * files fail with a message that names them, and a 16-bit PNG, which ours does not read, is read
 * through the adapter by mx_io_decode_image. */
#include <dlfcn.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "../pipeline/io/io.h"
#include "../pipeline/io/oiio_adapter.h"
#include "../pipeline/io/png_zlib.h"
#include "util_test.h"

/* A w x h x c image of 8-bit code values (as floats /255) from a fixed sequence. */
static mx_image coded_image(int w, int h, int c, unsigned seed) {
    mx_image img = {w, h, c, malloc((size_t)w * h * c * sizeof(float))};
    for (size_t i = 0; i < (size_t)w * h * c; i++) {
        seed = seed * 1664525u + 1013904223u;
        img.data[i] = (float)(seed >> 24) / 255.f;
    }
    return img;
}

/* The same 8-bit codes (exact: bits 1, the same floats). */
static int same_image(const mx_image *a, const mx_image *b, int bits) {
    if (!a->data || !b->data || a->w != b->w || a->h != b->h || a->c != b->c) return 0;
    for (size_t i = 0; i < (size_t)a->w * a->h * a->c; i++)
        if (bits ? a->data[i] != b->data[i] : lrintf(a->data[i] * 255.f) != lrintf(b->data[i] * 255.f)) return 0;
    return 1;
}

/* The adapter's decoder (the test's RUNPATH holds the build folder). */
static mx_oiio_decode_fn *oiio_decoder(void) {
    void *lib = dlopen(MX_OIIO_LIBRARY, RTLD_NOW | RTLD_LOCAL);
    if (!lib) printf("cannot load %s: %s\n", MX_OIIO_LIBRARY, dlerror());
    return lib ? (mx_oiio_decode_fn *)dlsym(lib, MX_OIIO_DECODE) : NULL;
}

static void round_trips(mx_oiio_decode_fn *oiio_decode, int w, int h, int c) {
    mx_status st;
    mx_image img = coded_image(w, h, c, (unsigned)(w * 131 + h * 7 + c)), back = {0}, theirs = {0};
    unsigned char *png = NULL;
    size_t len = 0;
    char what[64];
    snprintf(what, sizeof what, "%dx%dx%d", w, h, c);
    /* ours -> OpenImageIO and ours: both decoders give the same floats */
    CHECK(mx_io_encode_png(&img, &png, &len, &st) == 0);
    CHECK(oiio_decode && oiio_decode(png, len, "png", what, &theirs, &st) == 0 && same_image(&img, &theirs, 0));
    int ok = mx_io_decode_image(png, len, what, &back, &st) == 0 && same_image(&theirs, &back, 1);
    CHECK(ok);
    printf("png %s: %s\n", what, ok ? "ours and OpenImageIO read it alike" : "FAILED");
    free(back.data);
    free(theirs.data);
    free(png);
    free(img.data);
}

static void put_be32(unsigned char *p, uint32_t v) {
    p[0] = (unsigned char)(v >> 24), p[1] = (unsigned char)(v >> 16), p[2] = (unsigned char)(v >> 8), p[3] = (unsigned char)v;
}

static size_t put_chunk(unsigned char *buf, const char *type, const unsigned char *data, size_t len) {
    put_be32(buf, (uint32_t)len);
    memcpy(buf + 4, type, 4);
    if (len) memcpy(buf + 8, data, len);
    put_be32(buf + 8 + len, (uint32_t)crc32(0L, buf + 4, (uInt)(len + 4)));
    return 12 + len;
}

static int paeth(int a, int b, int c) {
    int p = a + b - c, pa = abs(p - a), pb = abs(p - b), pc = abs(p - c);
    return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

/* A PNG of 8-bit pixels px (w x h x channels, colour type `type`), row y filtered with filter
 * y % 5, written into buf (large enough); returns its length. */
static size_t make_png(unsigned char *buf, const unsigned char *px, int w, int h, int channels, int type, int depth) {
    size_t stride = (size_t)w * channels, raw_len = (stride + 1) * h;
    unsigned char *raw = malloc(raw_len), ihdr[13] = {0};
    for (int y = 0; y < h; y++) {
        const unsigned char *row = px + y * stride, *up = y ? row - stride : NULL;
        unsigned char *dst = raw + y * (stride + 1);
        dst[0] = (unsigned char)(y % 5);
        for (size_t i = 0; i < stride; i++) {
            int a = i >= (size_t)channels ? row[i - channels] : 0, b = up ? up[i] : 0;
            int c = up && i >= (size_t)channels ? up[i - channels] : 0;
            int pred = dst[0] == 1 ? a : dst[0] == 2 ? b : dst[0] == 3 ? (a + b) / 2 : dst[0] == 4 ? paeth(a, b, c) : 0;
            dst[1 + i] = (unsigned char)(row[i] - pred);
        }
    }
    uLongf zlen = compressBound((uLong)raw_len);
    unsigned char *z = malloc(zlen);
    compress2(z, &zlen, raw, (uLong)raw_len, 9);
    put_be32(ihdr, (uint32_t)w);
    put_be32(ihdr + 4, (uint32_t)h);
    ihdr[8] = (unsigned char)depth;
    ihdr[9] = (unsigned char)type;
    memcpy(buf, "\x89PNG\r\n\x1a\n", 8);
    size_t n = 8 + put_chunk(buf + 8, "IHDR", ihdr, 13);
    n += put_chunk(buf + n, "IDAT", z, zlen);
    n += put_chunk(buf + n, "IEND", NULL, 0);
    free(raw);
    free(z);
    return n;
}

static void grey_alpha_all_filters(void) {
    enum { W = 13, H = 10 };
    unsigned char px[W * H * 2], buf[4096];
    for (int i = 0; i < W * H * 2; i++) px[i] = (unsigned char)(i * 37 + (i >> 3) * 11);
    size_t len = make_png(buf, px, W, H, 2, 4, 8);
    mx_image img = {0};
    mx_status st;
    CHECK(mx_png_decode(buf, len, "grey+alpha", &img, &st) == 0 && img.c == 4 && img.w == W && img.h == H);
    int bad = 0;
    for (int i = 0; img.data && i < W * H; i++)
        bad += img.data[4 * i] != px[2 * i] * (1.0f / 255.0f) || img.data[4 * i + 1] != img.data[4 * i] ||
               img.data[4 * i + 2] != img.data[4 * i] || img.data[4 * i + 3] != px[2 * i + 1] * (1.0f / 255.0f);
    CHECK(bad == 0);
    printf("png grey+alpha, filters 0-4: %d pixel(s) wrong\n", bad);
    free(img.data);
}

/* data fails to decode with a message naming "bad.png" and containing `want`. */
static void refused(const unsigned char *data, size_t len, const char *want, const char *what) {
    mx_image img = {0};
    mx_status st;
    int rc = mx_png_decode(data, len, "bad.png", &img, &st);
    int ok = rc == -1 && img.data == NULL && strstr(st.msg, "bad.png") && strstr(st.msg, want);
    CHECK(ok);
    printf("png %-28s %s (%s)\n", what, ok ? "refused ok" : "NOT refused as expected", rc ? st.msg : "decoded");
}

static void damaged_files(void) {
    unsigned char px[8 * 6 * 3], buf[4096], copy[4096];
    for (int i = 0; i < (int)sizeof px; i++) px[i] = (unsigned char)(i * 13);
    size_t len = make_png(buf, px, 8, 6, 3, 2, 8);
    refused(buf, len - 12, "truncated", "without IEND");
    refused(buf, 30, "truncated", "cut inside IHDR");
    memcpy(copy, buf, len);
    copy[45] ^= 0x40; /* a byte of the IDAT payload */
    refused(copy, len, "CRC", "flipped data byte");
    memcpy(copy, buf, len);
    copy[8] = 0x7f; /* IHDR's length: 2 GiB */
    refused(copy, len, "truncated", "huge chunk length");
    len = make_png(buf, px, 8, 6, 3, 2, 8);
    memcpy(copy, buf, len);
    put_be32(copy + 16, 9); /* width 9: the image data is a row short */
    put_be32(copy + 29, (uint32_t)crc32(0L, copy + 12, 17));
    refused(copy, len, "wrong size", "size unlike its data");
    put_be32(copy + 16, 16384);
    put_be32(copy + 20, 16384);
    put_be32(copy + 29, (uint32_t)crc32(0L, copy + 12, 17));
    refused(copy, len, "holds", "16384² in a tiny file");
    put_be32(copy + 20, 6);
    put_be32(copy + 16, 100000);
    put_be32(copy + 29, (uint32_t)crc32(0L, copy + 12, 17));
    refused(copy, len, "at most", "100000 pixels wide");
    len = make_png(buf, px, 4, 6, 3, 2, 16);
    refused(buf, len, "16-bit", "16-bit");
    /* a valid 16-bit RGB PNG of 4 x 6: rows of 24 bytes, made as 8 x 6 8-bit rows, width set to 4 */
    len = make_png(buf, px, 8, 6, 3, 2, 16);
    put_be32(buf + 16, 4);
    put_be32(buf + 29, (uint32_t)crc32(0L, buf + 12, 17));
    mx_image img = {0};
    mx_status st;
    int ok = mx_io_decode_image(buf, len, "16-bit.png", &img, &st) == 0 && img.w == 4 && img.h == 6 && img.c == 3;
    CHECK(ok);
    printf("png 16-bit through the adapter: %s\n", ok ? "read ok" : st.msg);
    free(img.data);
    len = make_png(buf, px, 4, 6, 1, 3, 8); /* palette indices (and no PLTE): the full build's */
    refused(buf, len, "colour type 3", "palette");
    refused((const unsigned char *)"GIF89a........", 14, "not a PNG", "not a PNG");
}

int main(void) {
    static const int sizes[][2] = {{1, 1}, {17, 5}, {64, 33}};
    mx_oiio_decode_fn *oiio_decode = oiio_decoder();
    for (int s = 0; s < 3; s++)
        for (int c = 1; c <= 4; c++)
            if (c != 2) round_trips(oiio_decode, sizes[s][0], sizes[s][1], c);
    grey_alpha_all_filters();
    damaged_files();
    return mx_test_finish("test_io_png");
}
