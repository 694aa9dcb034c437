/* The image files of the file adapter (io.h): the formats matex reads itself first, OpenImageIO
 * for the rest, loaded only then. 8-bit PNG through zlib (png_zlib.c), EXR through OpenEXR
 * (exr_read.cpp); JPEG, TIFF, palette/16-bit/interlaced PNG and every other format through
 * libmatex_oiio.so (oiio_adapter.h), opened with dlopen() on the first file that needs it, so
 * `matex --help`, option errors and a PNG/EXR-only job never map OpenImageIO's ~250 libraries.
 * PNG output is always png_zlib.c's. */
#include "io.h"

#include <dlfcn.h>
#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "exr_read.h"
#include "io_write.h"
#include "oiio_adapter.h"
#include "png_zlib.h"

enum { MAX_FILE = 1 << 30 }; /* a PNG of 16384² RGBA, stored uncompressed, is 1 GiB */

typedef enum { KIND_OTHER, KIND_PNG, KIND_JPEG, KIND_EXR } image_kind;

/* The format of an image from its magic bytes. */
static image_kind sniff(const unsigned char *p, size_t n) {
    if (n >= 8 && !memcmp(p, "\x89PNG\r\n\x1a\n", 8)) return KIND_PNG;
    if (n >= 3 && p[0] == 0xFF && p[1] == 0xD8 && p[2] == 0xFF) return KIND_JPEG;
    if (n >= 4 && !memcmp(p, "\x76\x2f\x31\x01", 4)) return KIND_EXR;
    return KIND_OTHER;
}

/* ---- the OpenImageIO adapter, opened once per process ---- */

/* The adapter's entry points, or the reason it could not be loaded. Process-wide by nature (a
 * dlopen'ed library is), set once under pthread_once and read-only after. */
static struct {
    pthread_once_t once;
    mx_oiio_read_fn *read;
    mx_oiio_decode_fn *decode;
    char error[512];
} oiio = {PTHREAD_ONCE_INIT, NULL, NULL, ""};

/* dlopen of the adapter in the folder of the running program (matex: build/, or PREFIX/bin's
 * ../lib once installed), then by the loader's own search (LD_LIBRARY_PATH, the RUNPATH of the
 * program: PREFIX/lib for a program linked through matex.pc, the build folder for the tests).
 * The program's folder comes first so that build/matex never picks up an older installed copy;
 * it is looked up here rather than through an $ORIGIN RUNPATH because under AddressSanitizer
 * dlopen is called from its interceptor, and the program's RUNPATH is then not searched. */
static void *open_oiio_library(void) {
    char exe[4096], path[4096 + 64];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    char *slash = n > 0 ? (exe[n] = 0, strrchr(exe, '/')) : NULL;
    if (slash) *slash = 0; /* exe: the program's folder */
    static const char *const beside[2] = {"", "/../lib"};
    for (int i = 0; slash && i < 2; i++) {
        snprintf(path, sizeof path, "%s%s/" MX_OIIO_LIBRARY, exe, beside[i]);
        if (access(path, F_OK) == 0) return dlopen(path, RTLD_NOW | RTLD_LOCAL); /* its error is the one to report */
    }
    return dlopen(MX_OIIO_LIBRARY, RTLD_NOW | RTLD_LOCAL);
}

static void load_oiio(void) {
    /* RTLD_LOCAL: OpenImageIO's symbols stay out of the program's namespace. Never closed: its
     * libraries register atexit handlers and thread-local state. */
    void *lib = open_oiio_library();
    if (lib) {
        oiio.read = (mx_oiio_read_fn *)dlsym(lib, MX_OIIO_READ);
        oiio.decode = (mx_oiio_decode_fn *)dlsym(lib, MX_OIIO_DECODE);
    }
    if (!oiio.read || !oiio.decode) {
        const char *why = dlerror();
        snprintf(oiio.error, sizeof oiio.error, "%s", why ? why : MX_OIIO_LIBRARY ": entry points missing");
        oiio.read = NULL;
        oiio.decode = NULL;
    }
}

/* 0 when the adapter is loaded; else an error naming what needed it and why it is missing. */
static int need_oiio(const char *what, const char *format, mx_status *st) {
    pthread_once(&oiio.once, load_oiio);
    if (oiio.read) return 0;
    return mx_fail(st, MX_EINPUT,
                   "%s: reading this %s image needs the OpenImageIO adapter " MX_OIIO_LIBRARY
                   ", which cannot be loaded (%s); matex reads 8-bit PNG and EXR without it",
                   what, format, oiio.error);
}

/* ---- reading ---- */

/* A PNG: 8-bit through zlib, the variants png_zlib.c does not read through the adapter. */
static int decode_png(const unsigned char *data, size_t len, const char *what, mx_image *out, mx_status *st) {
    if (mx_png_check(data, len, what, st)) return -1;
    if (mx_png_zlib_reads(data)) return mx_png_decode(data, len, what, out, st);
    if (need_oiio(what, "PNG", st)) return -1;
    return oiio.decode(data, len, "png", what, out, st);
}

/* The whole regular file at path in a malloc'ed buffer. */
static int read_whole_file(const char *path, unsigned char **data, size_t *len, mx_status *st) {
    struct stat sb;
    *data = NULL;
    if (stat(path, &sb)) return mx_fail(st, MX_EINPUT, "%s: cannot open image: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: cannot open image: not a regular file", path);
    if (sb.st_size > MAX_FILE) return mx_fail(st, MX_EINPUT, "%s: image file larger than 1 GiB", path);
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open image: %s", path, strerror(errno));
    *len = (size_t)sb.st_size;
    *data = malloc(*len ? *len : 1);
    int ok = *data && fread(*data, 1, *len, f) == *len;
    fclose(f);
    if (!ok) {
        free(*data);
        *data = NULL;
        return mx_fail(st, MX_EINPUT, "%s: cannot read the image file", path);
    }
    return 0;
}

/* The reader OpenImageIO should use for a file of unknown magic: its extension. */
static const char *extension_of(const char *path) {
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    return dot && (!slash || dot > slash) ? dot + 1 : "";
}

int mx_io_read_image(const char *path, mx_image *out, mx_status *st) {
    unsigned char *data;
    size_t len = 0;
    memset(out, 0, sizeof *out);
    if (read_whole_file(path, &data, &len, st)) return -1;
    image_kind kind = sniff(data, len);
    const char *ext = extension_of(path);
    int rc;
    if (kind == KIND_PNG) rc = decode_png(data, len, path, out, st);
    else if (kind == KIND_EXR) rc = mx_exr_decode(data, len, path, out, st);
    else if (!strcasecmp(ext, "png") || !strcasecmp(ext, "exr"))
        rc = mx_fail(st, MX_EINPUT, "%s: not a%s file (its first bytes are not a %s signature)", path,
                     strcasecmp(ext, "png") ? "n EXR" : " PNG", strcasecmp(ext, "png") ? "EXR" : "PNG");
    else if (need_oiio(path, kind == KIND_JPEG ? "JPEG" : ext, st)) rc = -1;
    else rc = oiio.read(path, kind == KIND_JPEG ? "jpg" : ext, out, st);
    free(data);
    return rc;
}

int mx_io_decode_image(const void *data, size_t len, const char *what, mx_image *out, mx_status *st) {
    memset(out, 0, sizeof *out);
    image_kind kind = sniff(data, len);
    if (kind == KIND_PNG) return decode_png(data, len, what, out, st);
    if (kind != KIND_JPEG) return mx_fail(st, MX_EINPUT, "%s: not a PNG or JPEG image", what);
    if (need_oiio(what, "JPEG", st)) return -1;
    return oiio.decode(data, len, "jpg", what, out, st);
}

/* ---- writing: PNG through zlib ---- */

int mx_io_encode_png(const mx_image *img, unsigned char **data, size_t *len, mx_status *st) {
    return mx_png_encode(img, data, len, st);
}

int mx_io_write_png(const char *path, const mx_image *img, mx_status *st) {
    unsigned char *png;
    size_t len;
    if (mx_png_encode(img, &png, &len, st)) return mx_fail_prefix(st, "%s", path);
    char tmp[4096];
    if (snprintf(tmp, sizeof tmp, "%s.tmp", path) >= (int)sizeof tmp) {
        free(png);
        return mx_fail(st, MX_EINPUT, "%s: path too long", path);
    }
    FILE *f = fopen(tmp, "wb");
    int ok = f && fwrite(png, 1, len, f) == len;
    if (f && fclose(f)) ok = 0;
    free(png);
    if (!ok) {
        remove(tmp);
        return mx_fail(st, MX_EIO, "%s: cannot write PNG: %s", path, strerror(errno));
    }
    return mx_io_rename_into_place(tmp, path, st);
}
