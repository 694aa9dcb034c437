// Image adapter: OpenImageIO for reading (PNG/JPEG/TIFF/...) and PNG writing (EXR output is
// exrio.cpp). No colour conversion anywhere: 8-bit code values map to [0,1] as is.
#include "io.h"
#include "io_write.h"
#include "png_zlib.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <sys/stat.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

namespace {

// Reads all pixels of an opened input as floats (w*h*nchannels). Reading in the file's own
// format and converting here matters: OIIO's read_image with a type conversion goes through a
// 64 MB scratch buffer whatever the image size (100 ms per tiny texture under ASan).
int read_pixels(OIIO::ImageInput &in, std::vector<float> &buf) {
    const OIIO::ImageSpec &spec = in.spec();
    size_t values = (size_t)spec.width * spec.height * spec.nchannels;
    if (!spec.channelformats.empty()) { // per-channel formats (mixed EXR): OIIO converts
        buf.resize(values);
        return in.read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, buf.data()) ? 0 : -1;
    }
    std::vector<unsigned char> native(values * spec.format.size());
    if (!in.read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UNKNOWN, native.data())) return -1;
    buf.resize(values);
    return OIIO::convert_pixel_values(spec.format, native.data(), OIIO::TypeDesc::FLOAT, buf.data(), (int)values) ? 0 : -1;
}

// Converts an opened OIIO input into an mx_image (channels as described in io.h).
int read_opened(OIIO::ImageInput &in, const char *what, mx_image *out, mx_status *st) {
    const OIIO::ImageSpec &spec = in.spec();
    int w = spec.width, h = spec.height, nch = spec.nchannels;
    if (w <= 0 || h <= 0 || nch <= 0 || w > MX_IMAGE_MAX_SIDE || h > MX_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "%s: unsupported image size %dx%d with %d channels", what, w, h, nch);
    std::vector<float> buf;
    if (read_pixels(in, buf)) return mx_fail(st, MX_EINPUT, "%s: cannot decode image: %s", what, in.geterror().c_str());
    int c = nch == 1 ? 1 : nch == 3 ? 3 : 4; // gray+alpha -> RGBA, >4 channels -> first 4
    float *data = (float *)malloc((size_t)w * h * c * sizeof(float));
    if (!data) return mx_fail(st, MX_ENOMEM, "%s: out of memory for a %dx%d image", what, w, h);
    for (size_t p = 0; p < (size_t)w * h; p++) {
        const float *s = &buf[p * nch];
        float *d = data + p * c;
        if (nch == 2) {
            d[0] = d[1] = d[2] = s[0];
            d[3] = s[1];
        } else {
            for (int k = 0; k < c; k++) d[k] = s[k];
        }
    }
    out->w = w;
    out->h = h;
    out->c = c;
    out->data = data;
    return 0;
}

// Guesses the format of an image from its magic bytes, as a file name for OIIO.
const char *sniff_name(const unsigned char *p, size_t n) {
    if (n >= 8 && !memcmp(p, "\x89PNG\r\n\x1a\n", 8)) return "embedded.png";
    if (n >= 3 && p[0] == 0xFF && p[1] == 0xD8 && p[2] == 0xFF) return "embedded.jpg";
    if (n >= 4 && !memcmp(p, "\x76\x2f\x31\x01", 4)) return "embedded.exr";
    return nullptr;
}

uint32_t le32(const unsigned char *p) { return (uint32_t)p[3] << 24 | (uint32_t)p[2] << 16 | (uint32_t)p[1] << 8 | p[0]; }

// Scan lines per chunk of an EXR compression method (the offset table has one entry per chunk);
// 0 for a method this check does not know (OpenEXR then decides).
int exr_lines_per_chunk(int compression) {
    static const int lines[10] = {1, 1, 1, 16, 32, 16, 32, 32, 32, 256};
    return compression >= 0 && compression < 10 ? lines[compression] : 0;
}

// OpenEXR 3.1 reads an attribute value by its type, not by its declared size: a fixed-size
// type reads its own size, a channel list reads entries up to an empty name, a preview reads
// its declared pixels, whatever the size field says; a size it disagrees with desynchronises
// the rest of the header (and then some unknown "attribute" allocates gigabytes). So every
// value must have exactly the layout of its type. Unknown types and strings are read by size.
bool exr_value_ok(const char *type, const unsigned char *v, size_t size) {
    static const struct { const char *type; size_t size; } fixed[] = {
        {"box2i", 16}, {"box2f", 16}, {"chromaticities", 32}, {"compression", 1}, {"deepImageState", 1},
        {"double", 8}, {"envmap", 1}, {"float", 4}, {"int", 4}, {"keycode", 28}, {"lineOrder", 1},
        {"m33d", 72}, {"m33f", 36}, {"m44d", 128}, {"m44f", 64}, {"rational", 8}, {"tiledesc", 9},
        {"timecode", 8}, {"v2d", 16}, {"v2f", 8}, {"v2i", 8}, {"v3d", 24}, {"v3f", 12}, {"v3i", 12}};
    for (const auto &f : fixed)
        if (!strcmp(type, f.type)) return size == f.size;
    if (!strcmp(type, "chlist")) { // entries: name, 0, 16 bytes; then an empty name
        size_t at = 0;
        while (at < size && v[at]) {
            size_t len = strnlen((const char *)v + at, std::min<size_t>(size - at, 256));
            if (len >= 256 || at + len + 1 + 16 > size) return false;
            at += len + 1 + 16;
        }
        return at + 1 == size;
    }
    if (!strcmp(type, "preview")) { // width, height, then 4 bytes a pixel
        if (size < 8 || (size - 8) % 4) return false;
        size_t w = le32(v), h = le32(v + 4), pixels = (size - 8) / 4;
        return w && h ? pixels % w == 0 && pixels / w == h : pixels == 0;
    }
    if (!strcmp(type, "stringvector")) { // length-prefixed strings filling the size
        size_t at = 0;
        while (at < size) {
            if (size - at < 4 || le32(v + at) > size - at - 4) return false;
            at += 4 + le32(v + at);
        }
    }
    return true;
}

// Bytes of one pixel over all channels of a (checked) channel list: UINT 4, HALF 2, FLOAT 4.
unsigned long long exr_pixel_bytes(const unsigned char *v, size_t size) {
    unsigned long long bytes = 0;
    for (size_t at = 0; at < size && v[at];) {
        at += strlen((const char *)v + at) + 1;
        bytes += le32(v + at) == 1 ? 2 : 4;
        at += 16;
    }
    return bytes;
}

// The buffers OpenEXR sizes from the header before reading any pixel: the line or tile
// offset table (8 bytes an entry, read from the file: it must fit in what follows the header)
// and the decompression buffer of one chunk (a few hundred channels 16k wide at most).
int check_exr_layout(long long w, long long h, unsigned long long pixel_bytes, int compression, long long tile_w,
                     long long tile_h, size_t after_header, const char *what, mx_status *st) {
    long long lines = tile_w ? tile_h : exr_lines_per_chunk(compression);
    if (!lines) return 0; // a compression this check does not know: OpenEXR decides
    long long chunks = tile_w ? ((w + tile_w - 1) / tile_w) * ((h + tile_h - 1) / tile_h) : (h + lines - 1) / lines;
    if (tile_w > MX_IMAGE_MAX_SIDE || tile_h > MX_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "%s: unsupported EXR tile size %lldx%lld", what, tile_w, tile_h);
    if ((unsigned long long)(tile_w ? tile_w : w) * pixel_bytes * lines > (1ull << 28))
        return mx_fail(st, MX_EINPUT, "%s: unsupported EXR layout (%llu bytes a pixel, %lld lines a block)", what,
                       pixel_bytes, lines);
    if ((unsigned long long)chunks * 8 > after_header)
        return mx_fail(st, MX_EINPUT, "%s: truncated EXR (%lld %s blocks declared, the file is too short for them)", what,
                       chunks, tile_w ? "tile" : "scan-line");
    return 0;
}

// Walks the header(s) of an EXR held in memory: every attribute must fit in the file, and a
// single-part image's offset table and buffers be plausible (check_exr_layout). OpenEXR sizes a string attribute by its
// declared length before reading it (a 200-byte file declaring a 2 GB "capDate" allocates
// 2 GB), and its offset table by the data window's height.
int check_exr_header(const unsigned char *p, size_t n, const char *what, mx_status *st) {
    if (n < 8) return mx_fail(st, MX_EINPUT, "%s: truncated EXR header", what);
    uint32_t flags = le32(p + 4);
    int multipart = (flags & 0x1000) != 0, tiled = (flags & 0x200) != 0;
    size_t max_name = flags & 0x400 ? 256 : 32; // names and types of at most 31 (long names: 255) chars
    long long xmin = 0, xmax = -1, ymin = 0, ymax = -1;
    int compression = -1;
    long long tile_w = 0, tile_h = 0;
    unsigned long long pixel_bytes = 0;
    size_t pos = 8;
    for (;;) {
        if (pos >= n) return mx_fail(st, MX_EINPUT, "%s: truncated EXR header", what);
        if (!p[pos]) { // end of a header; the headers of a multi-part file end with an empty one
            pos++;
            if (!multipart) break;
            if (pos >= n) return mx_fail(st, MX_EINPUT, "%s: truncated EXR header", what);
            if (!p[pos]) {
                pos++;
                break;
            }
            continue;
        }
        const char *name = (const char *)p + pos;
        size_t left = n - pos, name_len = strnlen(name, std::min<size_t>(left, 256));
        size_t type_len = name_len + 1 < left ? strnlen(name + name_len + 1, std::min<size_t>(left - name_len - 1, 256)) : left;
        if (name_len >= max_name || type_len >= max_name || name_len + type_len + 2 > left)
            return mx_fail(st, MX_EINPUT, "%s: corrupt EXR header (attribute name at byte %zu)", what, pos);
        pos += name_len + type_len + 2;
        if (n - pos < 4) return mx_fail(st, MX_EINPUT, "%s: truncated EXR header", what);
        size_t size = le32(p + pos);
        pos += 4;
        if (size > n - pos)
            return mx_fail(st, MX_EINPUT, "%s: EXR attribute '%s' declares %zu bytes, more than the file holds", what,
                           name, size);
        if (!exr_value_ok(name + name_len + 1, p + pos, size))
            return mx_fail(st, MX_EINPUT, "%s: corrupt EXR attribute '%s' (%zu bytes do not hold a %s)", what, name,
                           size, name + name_len + 1);
        if (!strcmp(name, "dataWindow") && size == 16) {
            xmin = (int32_t)le32(p + pos), ymin = (int32_t)le32(p + pos + 4);
            xmax = (int32_t)le32(p + pos + 8), ymax = (int32_t)le32(p + pos + 12);
        }
        if (!strcmp(name, "compression") && size == 1) compression = p[pos];
        if (!strcmp(name, "tiles") && size == 9) tile_w = le32(p + pos), tile_h = le32(p + pos + 4);
        if (!strcmp(name, "channels") && !strcmp(name + name_len + 1, "chlist")) pixel_bytes = exr_pixel_bytes(p + pos, size);
        pos += size;
    }
    // before OpenEXR sizes its line buffers by the width (a 4M x 1 image: 512 MB for 234 bytes)
    if (xmax - xmin >= MX_IMAGE_MAX_SIDE || ymax - ymin >= MX_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "%s: unsupported image size %lldx%lld (at most %d a side)", what,
                       xmax - xmin + 1, ymax - ymin + 1, MX_IMAGE_MAX_SIDE);
    if (multipart || xmax < xmin || ymax < ymin || (tiled && (tile_w <= 0 || tile_h <= 0))) return 0; // OpenEXR checks
    return check_exr_layout(xmax - xmin + 1, ymax - ymin + 1, pixel_bytes, compression, tiled ? tile_w : 0, tile_h,
                            n - pos, what, st);
}

// Opens `name` (a file, or a name for the data of `proxy`) with the reader of `format` only:
// OIIO's own open() tries every reader it has (HEIF, RAW, ...) when the named one fails, and
// some of those allocate gigabytes for hostile data.
int open_as(const char *format, const char *name, OIIO::Filesystem::IOProxy *proxy, const char *what,
            std::unique_ptr<OIIO::ImageInput> &in, mx_status *st) {
    in = OIIO::ImageInput::create(format, false, nullptr, proxy);
    if (!in) {
        std::string err = OIIO::geterror();
        return mx_fail(st, MX_EINPUT, "%s: unsupported image format: %s", what, err.c_str());
    }
    OIIO::ImageSpec spec, config;
    config.attribute("oiio:UnassociatedAlpha", 1); // code values as stored: no premultiplied colour
    if ((proxy && !in->set_ioproxy(proxy)) || !in->open(name, spec, config)) {
        std::string err = in->geterror();
        in.reset();
        return mx_fail(st, MX_EINPUT, "%s: cannot decode image: %s", what, err.c_str());
    }
    return 0;
}

// Decodes a PNG/JPEG/EXR held in memory (its format already sniffed as `name`).
int decode_memory(const char *name, const unsigned char *data, size_t len, const char *what, mx_image *out,
                  mx_status *st) {
    if (!strcmp(name, "embedded.png") && mx_png_check(data, len, what, st)) return -1;
    OIIO::Filesystem::IOMemReader mem(data, len);
    std::unique_ptr<OIIO::ImageInput> in;
    if (open_as(name, name, &mem, what, in, st)) return -1;
    return read_opened(*in, what, out, st);
}

// Writes PNG through an already created output (file or memory proxy).
int write_png_to(OIIO::ImageOutput &out, const std::string &name, const mx_image *img, mx_status *st) {
    OIIO::ImageSpec spec(img->w, img->h, img->c, OIIO::TypeDesc::UINT8);
    spec.attribute("oiio:UnassociatedAlpha", 1); // the values are written as given, never divided by alpha
    unsigned char *px = mx_io_to_8bit(img);
    if (!px) return mx_fail(st, MX_ENOMEM, "%s: out of memory", name.c_str());
    bool ok = out.open(name, spec) && out.write_image(OIIO::TypeDesc::UINT8, px) && out.close();
    free(px);
    if (!ok) return mx_fail(st, MX_EIO, "%s: cannot write PNG: %s", name.c_str(), out.geterror().c_str());
    return 0;
}

} // namespace

extern "C" int mx_io_read_image(const char *path, mx_image *out, mx_status *st) {
    *out = mx_image{};
    struct stat sb;
    if (stat(path, &sb)) return mx_fail(st, MX_EINPUT, "%s: cannot open image: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: cannot open image: not a regular file", path);
    try {
        std::vector<unsigned char> head(8);
        FILE *f = fopen(path, "rb");
        head.resize(f ? fread(head.data(), 1, head.size(), f) : 0);
        const char *name = sniff_name(head.data(), head.size());
        int png = name && !strcmp(name, "embedded.png"), exr = name && !strcmp(name, "embedded.exr");
        if (f && (png || exr) && head.size() == 8) { // whole file: its structure is checked first
            head.resize((size_t)sb.st_size);
            head.resize(8 + fread(head.data() + 8, 1, head.size() - 8, f));
        }
        if (f) fclose(f);
        if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open image: %s", path, strerror(errno));
        if (png) return decode_memory(name, head.data(), head.size(), path, out, st);
        if (exr && check_exr_header(head.data(), head.size(), path, st)) return -1;
        std::unique_ptr<OIIO::ImageInput> in; // other formats by their magic, else by extension
        std::string format = name ? strrchr(name, '.') + 1 : strrchr(path, '.') ? strrchr(path, '.') + 1 : "";
        if (open_as(format.c_str(), path, nullptr, path, in, st)) return -1;
        return read_opened(*in, path, out, st);
    } catch (const std::exception &e) {
        return mx_fail(st, MX_EINPUT, "%s: cannot read image: %s", path, e.what());
    }
}

extern "C" int mx_io_decode_image(const void *data, size_t len, const char *what, mx_image *out,
                                  mx_status *st) {
    *out = mx_image{};
    const char *name = sniff_name((const unsigned char *)data, len);
    if (!name || !strcmp(name, "embedded.exr")) return mx_fail(st, MX_EINPUT, "%s: not a PNG or JPEG image", what);
    try {
        return decode_memory(name, (const unsigned char *)data, len, what, out, st);
    } catch (const std::exception &e) {
        return mx_fail(st, MX_EINPUT, "%s: cannot decode image: %s", what, e.what());
    }
}

extern "C" int mx_io_write_png(const char *path, const mx_image *img, mx_status *st) {
    if (mx_io_check_writable(img, path, st)) return -1;
    std::string tmp = std::string(path) + ".tmp";
    try {
        auto out = OIIO::ImageOutput::create("png");
        if (!out) return mx_fail(st, MX_EINTERNAL, "%s: OpenImageIO has no PNG writer", path);
        if (write_png_to(*out, tmp, img, st)) {
            std::remove(tmp.c_str());
            return mx_fail_prefix(st, "%s", path);
        }
    } catch (const std::exception &e) {
        std::remove(tmp.c_str());
        return mx_fail(st, MX_EIO, "%s: cannot write PNG: %s", path, e.what());
    }
    return mx_io_rename_into_place(tmp.c_str(), path, st);
}

extern "C" int mx_io_encode_png(const mx_image *img, unsigned char **data, size_t *len, mx_status *st) {
    *data = nullptr;
    *len = 0;
    if (mx_io_check_writable(img, "PNG encoder", st)) return -1;
    try {
        std::vector<unsigned char> bytes;
        OIIO::Filesystem::IOVecOutput vec(bytes);
        auto out = OIIO::ImageOutput::create("png");
        if (!out || !out->supports("ioproxy") || !out->set_ioproxy(&vec))
            return mx_fail(st, MX_EINTERNAL, "PNG encoder: OpenImageIO cannot write PNG to memory");
        if (write_png_to(*out, "memory.png", img, st)) return -1;
        out.reset();
        *data = (unsigned char *)malloc(bytes.size() ? bytes.size() : 1);
        if (!*data) return mx_fail(st, MX_ENOMEM, "PNG encoder: out of memory");
        memcpy(*data, bytes.data(), bytes.size());
        *len = bytes.size();
        return 0;
    } catch (const std::exception &e) {
        return mx_fail(st, MX_EIO, "PNG encoder: %s", e.what());
    }
}
