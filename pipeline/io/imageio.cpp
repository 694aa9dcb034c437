// The OpenImageIO adapter, built alone into libmatex_oiio.so and opened on first use
// (oiio_adapter.h): the image formats that matex does not read itself. No colour conversion:
// 8-bit code values map to [0,1] as is. Only the two entry points are exported.
#include "io.h"
#include "oiio_adapter.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

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

} // namespace

extern "C" __attribute__((visibility("default"))) int mx_oiio_read(const char *path, const char *format, mx_image *out,
                                                                   mx_status *st) {
    *out = mx_image{};
    try {
        std::unique_ptr<OIIO::ImageInput> in;
        if (open_as(format, path, nullptr, path, in, st)) return -1;
        return read_opened(*in, path, out, st);
    } catch (const std::exception &e) {
        return mx_fail(st, MX_EINPUT, "%s: cannot read image: %s", path, e.what());
    }
}

extern "C" __attribute__((visibility("default"))) int mx_oiio_decode(const void *data, size_t len, const char *format,
                                                                     const char *what, mx_image *out, mx_status *st) {
    *out = mx_image{};
    try {
        OIIO::Filesystem::IOMemReader mem((void *)data, len);
        std::unique_ptr<OIIO::ImageInput> in;
        std::string name = std::string("memory.") + format; // OIIO picks the reader by the name too
        if (open_as(format, name.c_str(), &mem, what, in, st)) return -1;
        return read_opened(*in, what, out, st);
    } catch (const std::exception &e) {
        return mx_fail(st, MX_EINPUT, "%s: cannot decode image: %s", what, e.what());
    }
}
