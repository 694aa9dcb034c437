/* 8-bit PNG on zlib (png_zlib.h). The format: an 8-byte signature, then chunks of
 * [length][type][data][CRC-32 of type+data], IHDR first, IDAT holding one zlib stream of the
 * filtered rows (each row: a filter byte, then w * channels bytes), IEND last. */
#include "png_zlib.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "io.h"
#include "io_write.h"

static const unsigned char SIGNATURE[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

static uint32_t be32(const unsigned char *p) {
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

static void put_be32(unsigned char *p, uint32_t v) {
    p[0] = (unsigned char)(v >> 24);
    p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);
    p[3] = (unsigned char)v;
}

/* ---- decoding ---- */

typedef struct {
    uint32_t w, h;
    int channels; /* in the file: 1, 2, 3 or 4 */
} png_header;

/* What mx_png_check found: the IHDR's 13 bytes and the total length of the IDAT chunks. */
typedef struct {
    const unsigned char *ihdr;
    size_t idat_len;
} png_layout;

/* Samples per pixel by colour type: 0 grey, 2 RGB, 3 palette index, 4 grey+alpha, 6 RGBA. */
static const int SAMPLES_OF_TYPE[7] = {1, 0, 3, 1, 2, 0, 4};

/* Bytes of the filtered rows an IHDR declares: per row a filter byte and the packed samples. */
static unsigned long long declared_row_bytes(const unsigned char *ihdr) {
    unsigned long long w = be32(ihdr), h = be32(ihdr + 4), depth = ihdr[8];
    int samples = ihdr[9] < 7 ? SAMPLES_OF_TYPE[ihdr[9]] : 0;
    return h * (1 + (w * (unsigned)samples * depth + 7) / 8);
}

static int check_declared_size(const png_layout *lay, const char *what, mx_status *st) {
    uint32_t w = be32(lay->ihdr), h = be32(lay->ihdr + 4);
    if (w == 0 || h == 0 || w > MX_IMAGE_MAX_SIDE || h > MX_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "%s: unsupported image size %ux%u (at most %d a side)", what, w, h,
                       MX_IMAGE_MAX_SIDE);
    if (declared_row_bytes(lay->ihdr) / 1032 > lay->idat_len + 64)
        return mx_fail(st, MX_EINPUT, "%s: PNG declares %ux%u pixels but holds %zu bytes of image data", what, w, h,
                       lay->idat_len);
    return 0;
}

/* Walks the chunks up to IEND, checking each length and CRC; other chunks (text, gamma, a
 * suggested palette) are skipped. */
static int scan_chunks(const unsigned char *p, size_t n, const char *what, png_layout *lay, mx_status *st) {
    lay->ihdr = NULL;
    lay->idat_len = 0;
    if (n < 8 || memcmp(p, SIGNATURE, 8)) return mx_fail(st, MX_EINPUT, "%s: not a PNG file", what);
    for (size_t pos = 8;;) {
        if (n - pos < 12) return mx_fail(st, MX_EINPUT, "%s: truncated PNG (no IEND chunk)", what);
        size_t len = be32(p + pos);
        if (len > n - pos - 12) return mx_fail(st, MX_EINPUT, "%s: truncated PNG chunk at byte %zu", what, pos);
        const unsigned char *type = p + pos + 4, *data = p + pos + 8;
        if (crc32(0L, type, (uInt)(len + 4)) != be32(data + len))
            return mx_fail(st, MX_EINPUT, "%s: corrupt PNG chunk '%.4s' at byte %zu (CRC mismatch)", what,
                           (const char *)type, pos);
        int is_ihdr = !memcmp(type, "IHDR", 4);
        if (is_ihdr != (pos == 8))
            return mx_fail(st, MX_EINPUT, "%s: %s", what, is_ihdr ? "PNG with two IHDR chunks" : "PNG without IHDR first");
        if (is_ihdr && len != 13) return mx_fail(st, MX_EINPUT, "%s: PNG IHDR of %zu bytes (13 expected)", what, len);
        if (is_ihdr) lay->ihdr = data;
        if (!memcmp(type, "IDAT", 4)) lay->idat_len += len;
        if (!memcmp(type, "IEND", 4))
            return lay->idat_len ? 0 : mx_fail(st, MX_EINPUT, "%s: PNG without image data", what);
        pos += 12 + len;
    }
}

static int check_layout(const void *data, size_t len, const char *what, png_layout *lay, mx_status *st) {
    return scan_chunks(data, len, what, lay, st) || check_declared_size(lay, what, st) ? -1 : 0;
}

int mx_png_check(const void *data, size_t len, const char *what, mx_status *st) {
    png_layout lay;
    return check_layout(data, len, what, &lay, st);
}

/* The subset this decoder reads, from an IHDR that check_layout accepted. */
static int parse_ihdr(const unsigned char *d, const char *what, png_header *hd, mx_status *st) {
    hd->w = be32(d);
    hd->h = be32(d + 4);
    int depth = d[8], type = d[9], interlace = d[12];
    if (d[10] != 0 || d[11] != 0 || interlace > 1 || type > 6)
        return mx_fail(st, MX_EINPUT, "%s: invalid PNG header", what);
    hd->channels = type == 3 ? 0 : SAMPLES_OF_TYPE[type]; /* a palette is not read here */
    if (depth != 8 || hd->channels == 0 || interlace)
        return mx_fail(st, MX_EINPUT,
                       "%s: a %d-bit PNG of colour type %d%s: this decoder reads only "
                       "non-interlaced 8-bit grey, grey+alpha, RGB and RGBA",
                       what, depth, type, interlace ? ", interlaced" : "");
    return 0;
}

int mx_png_zlib_reads(const void *data) {
    const unsigned char *ihdr = (const unsigned char *)data + 16; /* after the signature, length and type */
    return ihdr[8] == 8 && ihdr[9] <= 6 && SAMPLES_OF_TYPE[ihdr[9]] && ihdr[9] != 3 && ihdr[12] == 0;
}

/* The IDAT payloads of a checked PNG, joined into one malloc'ed buffer of lay->idat_len bytes. */
static unsigned char *joined_idat(const unsigned char *p, const png_layout *lay) {
    unsigned char *idat = malloc(lay->idat_len), *dst = idat;
    if (!idat) return NULL;
    for (size_t pos = 8; memcmp(p + pos + 4, "IEND", 4); pos += 12 + be32(p + pos)) {
        size_t len = be32(p + pos);
        if (!memcmp(p + pos + 4, "IDAT", 4)) memcpy(dst, p + pos + 8, len), dst += len;
    }
    return idat;
}

/* Inflates the zlib stream into exactly `size` bytes: a stream that ends early, runs over or is
 * damaged is an error. */
static int inflate_exact(const unsigned char *src, size_t src_len, unsigned char *dst, size_t size, const char *what,
                         mx_status *st) {
    z_stream z;
    memset(&z, 0, sizeof z);
    if (inflateInit(&z) != Z_OK) return mx_fail(st, MX_ENOMEM, "%s: out of memory (zlib)", what);
    z.next_in = (Bytef *)src;
    z.avail_in = (uInt)src_len;
    z.next_out = dst;
    z.avail_out = (uInt)size;
    int rc = inflate(&z, Z_FINISH);
    size_t out = z.total_out;
    inflateEnd(&z);
    if (rc != Z_STREAM_END || out != size)
        return mx_fail(st, MX_EINPUT, "%s: PNG image data %s (%zu of %zu bytes)", what,
                       rc == Z_STREAM_END || rc == Z_BUF_ERROR ? "of the wrong size" : "damaged", out, size);
    return 0;
}

static int paeth(int a, int b, int c) {
    int p = a + b - c, pa = abs(p - a), pb = abs(p - b), pc = abs(p - c);
    return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

/* Undoes the per-row filters in place; rows[y] = filter byte + stride bytes. bpp = bytes per pixel. */
static int unfilter(unsigned char *rows, uint32_t h, size_t stride, int bpp, const char *what, mx_status *st) {
    const unsigned char *prev = NULL;
    for (uint32_t y = 0; y < h; y++) {
        unsigned char *row = rows + y * (stride + 1), filter = row[0], *px = row + 1;
        if (filter > 4) return mx_fail(st, MX_EINPUT, "%s: PNG row %u has unknown filter %d", what, y, filter);
        for (size_t i = 0; i < stride; i++) {
            int a = i >= (size_t)bpp ? px[i - bpp] : 0, b = prev ? prev[i] : 0;
            int c = prev && i >= (size_t)bpp ? prev[i - bpp] : 0;
            int predicted = filter == 1 ? a : filter == 2 ? b : filter == 3 ? (a + b) / 2 : filter == 4 ? paeth(a, b, c) : 0;
            px[i] = (unsigned char)(px[i] + predicted);
        }
        prev = px;
    }
    return 0;
}

/* 8-bit rows to float values; grey+alpha widens to RGBA. */
static int to_image(const unsigned char *rows, const png_header *hd, const char *what, mx_image *out, mx_status *st) {
    int cin = hd->channels, cout = cin == 2 ? 4 : cin;
    size_t stride = (size_t)hd->w * cin;
    float *data = malloc((size_t)hd->w * hd->h * cout * sizeof *data);
    if (!data) return mx_fail(st, MX_ENOMEM, "%s: out of memory", what);
    for (uint32_t y = 0; y < hd->h; y++) {
        const unsigned char *px = rows + y * (stride + 1) + 1;
        float *dst = data + (size_t)y * hd->w * cout;
        for (uint32_t x = 0; x < hd->w; x++, px += cin, dst += cout) {
            if (cin == 2) {
                dst[0] = dst[1] = dst[2] = px[0] * (1.0f / 255.0f);
                dst[3] = px[1] * (1.0f / 255.0f);
            } else {
                for (int k = 0; k < cin; k++) dst[k] = px[k] * (1.0f / 255.0f);
            }
        }
    }
    out->w = (int)hd->w;
    out->h = (int)hd->h;
    out->c = cout;
    out->data = data;
    return 0;
}

int mx_png_decode(const void *data, size_t len, const char *what, mx_image *out, mx_status *st) {
    memset(out, 0, sizeof *out);
    png_layout lay;
    png_header hd = {0, 0, 0};
    if (check_layout(data, len, what, &lay, st) || parse_ihdr(lay.ihdr, what, &hd, st)) return -1;
    size_t stride = (size_t)hd.w * hd.channels, size = (stride + 1) * hd.h;
    unsigned char *idat = joined_idat(data, &lay), *rows = idat ? malloc(size) : NULL;
    int rc = rows ? 0 : mx_fail(st, MX_ENOMEM, "%s: out of memory", what);
    if (!rc) rc = inflate_exact(idat, lay.idat_len, rows, size, what, st);
    if (!rc) rc = unfilter(rows, hd.h, stride, hd.channels, what, st);
    if (!rc) rc = to_image(rows, &hd, what, out, st);
    free(idat);
    free(rows);
    return rc;
}

/* ---- encoding ---- */

/* Appends one chunk (length, type, data, CRC) at *pos. */
static void put_chunk(unsigned char *buf, size_t *pos, const char *type, const unsigned char *data, size_t len) {
    unsigned char *c = buf + *pos;
    put_be32(c, (uint32_t)len);
    memcpy(c + 4, type, 4);
    if (len && data != c + 8) memcpy(c + 8, data, len); /* IDAT is compressed in place */
    put_be32(c + 8 + len, (uint32_t)crc32(0L, c + 4, (uInt)(len + 4)));
    *pos += 12 + len;
}

/* The filtered rows: each row with the Sub filter (each byte minus the one a pixel before), which
 * compresses smooth textures well at no search cost. */
static unsigned char *filtered_rows(const unsigned char *px, const mx_image *img) {
    size_t stride = (size_t)img->w * img->c;
    unsigned char *rows = malloc((stride + 1) * img->h);
    if (!rows) return NULL;
    for (int y = 0; y < img->h; y++) {
        const unsigned char *src = px + (size_t)y * stride;
        unsigned char *dst = rows + (size_t)y * (stride + 1);
        dst[0] = 1;
        for (size_t i = 0; i < stride; i++) dst[1 + i] = (unsigned char)(src[i] - (i >= (size_t)img->c ? src[i - img->c] : 0));
    }
    return rows;
}

int mx_png_encode(const mx_image *img, unsigned char **data, size_t *len, mx_status *st) {
    static const unsigned char colour_type[5] = {0, 0, 0, 2, 6};
    *data = NULL;
    *len = 0;
    if (mx_io_check_writable(img, "PNG encoder", st)) return -1;
    if (img->w > MX_IMAGE_MAX_SIDE || img->h > MX_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "PNG encoder: image of %dx%d (at most %d a side)", img->w, img->h,
                       MX_IMAGE_MAX_SIDE);
    unsigned char *px = mx_io_to_8bit(img), *rows = px ? filtered_rows(px, img) : NULL;
    size_t raw = ((size_t)img->w * img->c + 1) * img->h;
    uLongf packed = compressBound((uLong)raw);
    unsigned char *buf = rows ? malloc(8 + 25 + 12 + packed + 12) : NULL, *z = buf ? buf + 8 + 25 + 8 : NULL;
    int rc = buf ? 0 : mx_fail(st, MX_ENOMEM, "PNG encoder: out of memory");
    if (!rc && compress2(z, &packed, rows, (uLong)raw, 6) != Z_OK)
        rc = mx_fail(st, MX_EINTERNAL, "PNG encoder: zlib failed");
    if (!rc) {
        unsigned char ihdr[13] = {0};
        put_be32(ihdr, (uint32_t)img->w);
        put_be32(ihdr + 4, (uint32_t)img->h);
        ihdr[8] = 8;
        ihdr[9] = colour_type[img->c];
        size_t pos = 8;
        memcpy(buf, SIGNATURE, 8);
        put_chunk(buf, &pos, "IHDR", ihdr, sizeof ihdr);
        put_chunk(buf, &pos, "IDAT", z, packed);
        put_chunk(buf, &pos, "IEND", NULL, 0);
        *data = buf;
        *len = pos;
        buf = NULL;
    }
    free(px);
    free(rows);
    free(buf);
    return rc;
}
