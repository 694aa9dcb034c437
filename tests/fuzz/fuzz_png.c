/* matex's own PNG decoder (pipeline/io/png_zlib.c) on any bytes: it refuses them with a message
 * or returns an image of 1, 3 or 4 channels within its size limit, and that image encoded again
 * decodes to the same values. First byte odd: the chunks' CRCs are made right before decoding,
 * so that mutations reach the header, inflate and filter code instead of dying at the CRC. */
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "../../pipeline/geom/image.h"
#include "../../pipeline/io/png_zlib.h"
#include "fuzz.h"

static uint32_t be32(const uint8_t *p) { return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3]; }

/* Rewrites the CRC of every chunk whose length fits the buffer. */
static void fix_crcs(uint8_t *p, size_t n) {
    for (size_t pos = 8; n >= 12 && pos <= n - 12;) {
        size_t len = be32(p + pos);
        if (len > n - pos - 12) return;
        uint32_t crc = (uint32_t)crc32(0L, p + pos + 4, (uInt)(len + 4));
        for (int i = 0; i < 4; i++) p[pos + 8 + len + i] = (uint8_t)(crc >> (24 - 8 * i));
        pos += 12 + len;
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    mx_status st;
    mx_image img, back;
    if (!size) return 0;
    uint8_t *copy = malloc(size);
    memcpy(copy, data + 1, size - 1);
    if (data[0] & 1) fix_crcs(copy, size - 1);
    int rc = mx_png_decode(copy, size - 1, "fuzz", &img, &st);
    free(copy);
    if (rc) return 0;
    if (img.w <= 0 || img.h <= 0 || img.w > 16384 || img.h > 16384 || (img.c != 1 && img.c != 3 && img.c != 4))
        abort();
    unsigned char *png;
    size_t len, n = (size_t)img.w * img.h * img.c;
    if (mx_png_encode(&img, &png, &len, &st) || mx_png_decode(png, len, "fuzz again", &back, &st)) abort();
    for (size_t i = 0; i < n; i++)
        if (back.data[i] != img.data[i]) abort();
    free(png);
    mx_image_free(&img);
    mx_image_free(&back);
    return 0;
}
