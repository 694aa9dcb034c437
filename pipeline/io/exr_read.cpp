// EXR input through OpenEXR (exr_read.h). Every attribute of the header is walked and checked
// before OpenEXR sees the file: OpenEXR sizes buffers from declared sizes (check_exr_header).
#include "exr_read.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfInputFile.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

namespace {

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

// The bytes of an EXR held in memory as an OpenEXR input stream.
class MemoryStream : public Imf::IStream {
  public:
    MemoryStream(const unsigned char *data, size_t len, const char *what) : Imf::IStream(what), p(data), n(len) {}
    bool read(char c[], int count) override {
        if (count < 0 || (size_t)count > n - at) throw std::runtime_error("unexpected end of file");
        memcpy(c, p + at, (size_t)count);
        at += (size_t)count;
        return at < n;
    }
    uint64_t tellg() override { return at; }
    void seekg(uint64_t pos) override {
        if (pos > n) throw std::runtime_error("seek past the end of the file");
        at = (size_t)pos;
    }

  private:
    const unsigned char *p;
    size_t n, at = 0;
};

// The channels matex keeps, in order: R G B (A), else Y (A), else the first (up to 4) by name.
std::vector<std::string> kept_channels(const Imf::ChannelList &list) {
    std::vector<std::string> all;
    for (auto it = list.begin(); it != list.end(); ++it) all.push_back(it.name());
    auto has = [&](const char *c) { return std::find(all.begin(), all.end(), c) != all.end(); };
    std::vector<std::string> kept;
    if (has("R") && has("G") && has("B")) kept = {"R", "G", "B"};
    else if (has("Y")) kept = {"Y"};
    if (!kept.empty() && has("A")) kept.push_back("A");
    if (kept.empty()) kept.assign(all.begin(), all.begin() + std::min<size_t>(all.size(), 4));
    return kept;
}

// Reads the pixels of an opened file into an mx_image (1, 3 or 4 channels; 2 widened to RGBA).
int read_exr_pixels(Imf::InputFile &file, const char *what, mx_image *out, mx_status *st) {
    const Imath::Box2i win = file.header().dataWindow();
    long long w = (long long)win.max.x - win.min.x + 1, h = (long long)win.max.y - win.min.y + 1;
    std::vector<std::string> names = kept_channels(file.header().channels());
    int nch = (int)names.size();
    if (w <= 0 || h <= 0 || nch == 0 || w > MX_IMAGE_MAX_SIDE || h > MX_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "%s: unsupported image size %lldx%lld with %d channels", what, w, h, nch);
    int c = nch == 2 ? 4 : nch;
    float *data = (float *)calloc((size_t)(w * h * c), sizeof(float));
    if (!data) return mx_fail(st, MX_ENOMEM, "%s: out of memory for a %lldx%lld image", what, w, h);
    // slices addressed from the data window's origin, as OpenEXR expects (in unsigned arithmetic:
    // a window far from (0, 0) puts that origin outside the buffer)
    uintptr_t shift = (uintptr_t)(((long long)win.min.y * w + win.min.x) * c) * sizeof(float);
    char *origin = (char *)((uintptr_t)data - shift);
    size_t xs = sizeof(float) * c, ys = xs * (size_t)w;
    Imf::FrameBuffer fb;
    for (int k = 0; k < nch; k++) fb.insert(names[k], Imf::Slice(Imf::FLOAT, origin + (nch == 2 && k ? 3 : k) * sizeof(float), xs, ys));
    try {
        file.setFrameBuffer(fb);
        file.readPixels(win.min.y, win.max.y);
    } catch (...) {
        free(data);
        throw;
    }
    if (nch == 2) // grey + alpha: the grey into R, G and B
        for (size_t p = 0; p < (size_t)(w * h); p++) data[p * 4 + 1] = data[p * 4 + 2] = data[p * 4];
    *out = mx_image{(int)w, (int)h, c, data};
    return 0;
}

} // namespace

extern "C" int mx_exr_decode(const void *data, size_t len, const char *what, mx_image *out, mx_status *st) {
    *out = mx_image{};
    const unsigned char *p = (const unsigned char *)data;
    if (check_exr_header(p, len, what, st)) return -1;
    try {
        MemoryStream stream(p, len, what);
        Imf::InputFile file(stream);
        return read_exr_pixels(file, what, out, st);
    } catch (const std::exception &e) {
        return mx_fail(st, MX_EINPUT, "%s: cannot decode EXR: %s", what, e.what());
    }
}
