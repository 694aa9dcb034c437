// EXR output through OpenEXR (io.h: mx_io_write_exr), in both builds with a file adapter: the
// full one (with OpenImageIO) and the one without (png_zlib.c for PNG).
#include "io.h"
#include "io_write.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfThreading.h>

#include <cstdio>
#include <exception>
#include <string>

extern "C" int mx_io_write_exr(const char *path, const mx_image *img, int threads, mx_status *st) {
    if (mx_io_check_writable(img, path, st)) return -1;
    /* OpenEXR runs a file's threads on its global pool: without threads there, the blocks are
     * compressed one after the other whatever the file asks (a 1024² RGB texture: ~0.25 s) */
    if (threads > 1 && Imf::globalThreadCount() < threads) Imf::setGlobalThreadCount(threads);
    static const char *const names[4][4] = {{"Y"}, {}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
    std::string tmp = std::string(path) + ".tmp";
    try {
        Imf::Header header(img->w, img->h);
        header.compression() = Imf::ZIP_COMPRESSION;
        Imf::FrameBuffer fb;
        size_t xs = sizeof(float) * img->c, ys = xs * img->w;
        for (int k = 0; k < img->c; k++) {
            header.channels().insert(names[img->c - 1][k], Imf::Channel(Imf::FLOAT));
            fb.insert(names[img->c - 1][k], Imf::Slice(Imf::FLOAT, (char *)(img->data + k), xs, ys));
        }
        {
            Imf::OutputFile file(tmp.c_str(), header, threads > 1 ? threads : 0);
            file.setFrameBuffer(fb);
            file.writePixels(img->h);
        }
    } catch (const std::exception &e) {
        std::remove(tmp.c_str());
        return mx_fail(st, MX_EIO, "%s: cannot write EXR: %s", path, e.what());
    }
    return mx_io_rename_into_place(tmp.c_str(), path, st);
}
