#include "filekind.h"

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

typedef struct magic {
    const char *bytes;
    size_t len;
    const char *kind;
} magic;

#define MAGIC(s, kind) {s, sizeof s - 1, kind}

/* Files people mistake for meshes, and the binary mesh formats. */
static const magic magics[] = {
    MAGIC("\x89PNG\r\n\x1a\n", "a PNG image"),
    MAGIC("\xff\xd8\xff", "a JPEG image"),
    MAGIC("GIF8", "a GIF image"),
    MAGIC("\x76\x2f\x31\x01", "an OpenEXR image"),
    MAGIC("II*\0", "a TIFF image"),
    MAGIC("MM\0*", "a TIFF image"),
    MAGIC("BM", "a BMP image"),
    MAGIC("PK\x03\x04", "a zip archive"),
    MAGIC("\x1f\x8b", "a gzip file"),
    MAGIC("%PDF", "a PDF document"),
    MAGIC("\x7f" "ELF", "a program (ELF)"),
    MAGIC("MATEXWF\0", "a matex weight file"),
    MAGIC("glTF", "a binary glTF (GLB) mesh"),
    MAGIC("ply\n", "a PLY mesh"),
    MAGIC("ply\r\n", "a PLY mesh"),
};

/* The first word ends in OFF (OFF, COFF, NOFF, STOFF, 4OFF, ...: OpenMesh's header words). */
static int is_off_header(const unsigned char *h, size_t n) {
    size_t i = 0;
    while (i < n && i < 12 && isalnum(h[i])) i++;
    return i >= 3 && i < n && isspace(h[i]) && !memcmp(h + i - 3, "OFF", 3);
}

/* A binary STL: 80-byte header, triangle count, 50 bytes per triangle, and nothing else. */
static int is_binary_stl(const unsigned char *h, size_t n, uint64_t size) {
    if (n < 84 || size < 84) return 0;
    uint32_t count = (uint32_t)h[80] | (uint32_t)h[81] << 8 | (uint32_t)h[82] << 16 | (uint32_t)h[83] << 24;
    return 84 + 50 * (uint64_t)count == size;
}

const char *mx_file_kind(const unsigned char *head, size_t n, uint64_t file_size, int *definite) {
    *definite = 1;
    for (size_t i = 0; i < sizeof magics / sizeof magics[0]; i++)
        if (n >= magics[i].len && !memcmp(head, magics[i].bytes, magics[i].len)) return magics[i].kind;
    if (is_binary_stl(head, n, file_size) || (n >= 6 && !memcmp(head, "solid", 5) && isspace(head[5])))
        return "an STL mesh";
    if (is_off_header(head, n)) return "an OFF mesh";
    *definite = 0;
    if (memchr(head, 0, n)) return "binary data";
    size_t i = 0;
    while (i < n && isspace(head[i])) i++;
    return i < n && head[i] == '{' ? "JSON text" : "text";
}

/* The mesh formats matex reads: extension, what a file of it is, whether it is text. */
typedef struct mesh_format {
    const char *ext, *kind;
    int text;
} mesh_format;

static const mesh_format formats[] = {
    {"obj", "an OBJ mesh", 1},          {"ply", "a PLY mesh", 0},  {"off", "an OFF mesh", 1},
    {"stl", "an STL mesh", 0},          {"gltf", "a glTF mesh", 1}, {"glb", "a glTF mesh", 0},
};
#define NFORMATS (sizeof formats / sizeof formats[0])
#define FORMAT_LIST ".obj .ply .off .stl .gltf .glb"

static const mesh_format *format_of_ext(const char *ext) {
    for (size_t i = 0; i < NFORMATS; i++)
        if (!strcasecmp(ext, formats[i].ext)) return &formats[i];
    return NULL;
}

/* The extension a file of this kind wants ("ply"), or NULL when it is not a mesh. */
static const char *ext_of_kind(const char *kind) {
    if (!strcmp(kind, "a binary glTF (GLB) mesh")) return "glb";
    for (size_t i = 0; i < NFORMATS; i++)
        if (!strcmp(kind, formats[i].kind)) return formats[i].ext;
    return NULL;
}

/* The content fits the format: the same kind, glTF as GLB or JSON, or a guess that cannot
 * tell (a text format's file is text; a binary format's reader judges "binary data"). */
static int content_fits(const mesh_format *f, const char *kind, int definite) {
    if (!strcmp(kind, f->kind)) return 1;
    if (!strcmp(f->kind, "a glTF mesh")) return !strcmp(kind, "a binary glTF (GLB) mesh") || !definite;
    if (!definite) return f->text ? strcmp(kind, "binary data") != 0 : 1;
    return 0;
}

int mx_file_kind_of(const char *path, const char *what, const char **kind, int *definite, mx_status *st) {
    struct stat sb;
    if (stat(path, &sb) != 0) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
    if (S_ISDIR(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: is a directory, not %s", path, what);
    FILE *fp = fopen(path, "rb");
    if (!fp) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
    unsigned char head[512];
    size_t n = fread(head, 1, sizeof head, fp);
    int bad = ferror(fp);
    fclose(fp);
    if (bad) return mx_fail(st, MX_EINPUT, "%s: read error: %s", path, strerror(errno));
    *kind = mx_file_kind(head, n, (uint64_t)sb.st_size, definite);
    return 0;
}

int mx_mesh_check_file(const char *path, mx_status *st) {
    const char *kind;
    int definite;
    if (mx_file_kind_of(path, "a mesh file", &kind, &definite, st)) return -1;
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    const char *ext_want = ext_of_kind(kind);
    if (!dot || (slash && dot < slash) || !dot[1]) {
        if (ext_want)
            return mx_fail(st, MX_EINPUT, "%s: no file extension (its content is %s: name it .%s)", path, kind, ext_want);
        return mx_fail(st, MX_EINPUT, "%s: no file extension (its content is %s; expected " FORMAT_LIST ")", path, kind);
    }
    const mesh_format *f = format_of_ext(dot + 1);
    if (!f)
        return mx_fail(st, MX_EINPUT, "%s: unknown mesh format '%s' (expected " FORMAT_LIST "; its content is %s)", path,
                       dot, kind);
    if (content_fits(f, kind, definite)) return 0;
    if (ext_want)
        return mx_fail(st, MX_EINPUT, "%s: the file is %s, not %s (name it .%s)", path, kind, f->kind, ext_want);
    return mx_fail(st, MX_EINPUT, "%s: the file is %s, not %s", path, kind, f->kind);
}
