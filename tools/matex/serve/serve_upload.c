/* The mesh part a client sends: the mesh alone, or a zip of it with its side files (serve_upload.h). */
#include "serve_upload.h"

#include <errno.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "../../../pipeline/io/gltf.h"
#include "../../../runtime/fileio.h"
#include "../../../runtime/json.h"
#include "../../../runtime/zip.h"
#include "serve_zip.h"

#define GLTF_MAX_BYTES ((size_t)64 << 20) /* the JSON of a .gltf; its data is in the buffers */
#define GLB_MAGIC 0x46546C67u      /* "glTF" */
#define GLB_CHUNK_JSON 0x4E4F534Au /* "JSON" */
#define GLB_HEADER_BYTES 20        /* magic, version, length; the first chunk's length and type */

/* The mesh and the side files found so far, named as in the zip (names[0]: the mesh). */
typedef struct mesh_parts {
    const char *mesh;        /* the mesh's path as given */
    char dir[PATH_MAX];      /* its folder as the readers join names to it: "" or ending in '/' */
    char real_dir[PATH_MAX]; /* the same folder, resolved */
    char names[MX_SERVE_ZIP_MAX_ENTRIES][MX_SERVE_ZIP_NAME_MAX + 1];
    size_t n;
} mesh_parts;

/* The length of path's folder part with its final '/' (0 when path has none). */
static size_t dir_len(const char *path) {
    const char *slash = strrchr(path, '/');
    return slash ? (size_t)(slash - path) + 1 : 0;
}

/* rel without "" and "." components, each ".." taking the one before it away; -1 when a ".."
 * climbs out of the folder rel starts in, or out is too small. */
static int normalize(const char *rel, char *out, size_t cap) {
    size_t len = 0;
    for (const char *c = rel; *c;) {
        size_t n = strcspn(c, "/");
        if (n == 2 && c[0] == '.' && c[1] == '.') {
            if (len == 0) return -1;
            while (len > 0 && out[len - 1] != '/') len--;
            len -= len > 0; /* the '/' before the component taken away */
        } else if (n > 0 && !(n == 1 && c[0] == '.')) {
            if (len + (len > 0) + n >= cap) return -1;
            if (len > 0) out[len++] = '/';
            memcpy(out + len, c, n);
            len += n;
        }
        c += n + (c[n] == '/');
    }
    out[len] = 0;
    return len > 0 ? 0 : -1;
}

/* Whether the file the mesh's folder holds as name (normalized) resolves inside that folder. */
static int inside_folder(const mesh_parts *p, const char *name) {
    char path[2 * PATH_MAX], real[PATH_MAX];
    size_t root = strlen(p->real_dir);
    snprintf(path, sizeof path, "%s%s", p->dir, name);
    return realpath(path, real) && !strncmp(real, p->real_dir, root) && real[root] == '/';
}

/* Adds the file the reader opens for ref, named in the file named_by whose folder is ref_dir
 * (relative to the mesh's folder: "" or ending in '/'): 1 added (or there already), 0 not there
 * and not required (left out), -1 refused (st says why). */
static int add_part(mesh_parts *p, const char *ref_dir, const char *ref, int required, const char *named_by, mx_status *st) {
    char rel[2 * PATH_MAX], path[3 * PATH_MAX], name[PATH_MAX];
    struct stat sb;
    snprintf(rel, sizeof rel, "%s%s", ref_dir, ref);
    snprintf(path, sizeof path, "%s%s", p->dir, rel);
    if (stat(path, &sb) || !S_ISREG(sb.st_mode))
        return required ? mx_fail(st, MX_EINPUT, "%s: names '%s', which is not there", named_by, ref) : 0;
    if (ref[0] == '/' || normalize(rel, name, sizeof name) || !inside_folder(p, name))
        return mx_fail(st, MX_EINPUT, "%s: names '%s', outside the mesh's folder: a server is sent only the files in that "
                                      "folder (move the file into it)",
                       named_by, ref);
    if (!mx_serve_zip_name_valid(name))
        return mx_fail(st, MX_EINPUT, "%s: names '%s': not a name a server takes in a zip (a backslash, colon or control "
                                      "byte, or too long or deep)",
                       named_by, ref);
    for (size_t i = 0; i < p->n; i++)
        if (!strcmp(p->names[i], name)) return 1;
    if (p->n == MX_SERVE_ZIP_MAX_ENTRIES)
        return mx_fail(st, MX_EINPUT, "%s: more than %d files with its side files (a server takes at most that many)",
                       p->mesh, MX_SERVE_ZIP_MAX_ENTRIES);
    memcpy(p->names[p->n++], name, strlen(name) + 1);
    return 1;
}

/* The value of a line "KEYWORD value" (leading and trailing blanks and the line end cut), or NULL. */
static char *keyword_value(char *line, const char *keyword) {
    size_t k = strlen(keyword);
    line += strspn(line, " \t");
    if (strncmp(line, keyword, k) || (line[k] != ' ' && line[k] != '\t')) return NULL;
    char *v = line + k + strspn(line + k, " \t"), *end = v + strlen(v);
    while (end > v && strchr(" \t\r\n", end[-1])) *--end = 0;
    return *v ? v : NULL;
}

/* The last blank-separated word of a line (the texture of "map_Kd -s 1 1 1 wood.png"), cut in place. */
static char *last_word(char *v) {
    char *end = v + strlen(v);
    while (end > v && !strchr(" \t", end[-1])) end--;
    return end;
}

/* Each line of the file at path (relative to the mesh's folder: rel) through fn. */
static int for_each_line(mesh_parts *p, const char *path, const char *rel,
                         int (*fn)(mesh_parts *, const char *, char *, mx_status *), mx_status *st) {
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
    char *line = NULL;
    size_t cap = 0;
    int rc = 0;
    while (!rc && getline(&line, &cap, f) >= 0) rc = fn(p, rel, line, st);
    free(line);
    fclose(f);
    return rc;
}

/* A .mtl's line: its map_Kd texture, relative to the .mtl (mtl: its path from the mesh's folder). */
static int mtl_line(mesh_parts *p, const char *mtl, char *line, mx_status *st) {
    char *v = keyword_value(line, "map_Kd"), dir[PATH_MAX], named_by[2 * PATH_MAX];
    if (!v) return 0;
    snprintf(dir, sizeof dir, "%.*s", (int)dir_len(mtl), mtl);
    snprintf(named_by, sizeof named_by, "%s%s", p->dir, mtl);
    return add_part(p, dir, last_word(v), 0, named_by, st) < 0 ? -1 : 0;
}

/* An OBJ's line: its mtllib file and that file's textures. */
static int obj_line(mesh_parts *p, const char *obj, char *line, mx_status *st) {
    char *lib = keyword_value(line, "mtllib"), path[2 * PATH_MAX];
    (void)obj;
    int rc = lib ? add_part(p, "", lib, 0, p->mesh, st) : 0;
    if (rc <= 0) return rc;
    snprintf(path, sizeof path, "%s%s", p->dir, lib);
    return for_each_line(p, path, lib, mtl_line, st);
}

/* A glTF's URIs of one list (buffers or images) that name files, as the reader names them. */
static int uri_parts(mesh_parts *p, const mx_json *list, int required, mx_status *st) {
    for (size_t i = 0; i < mx_json_len(list); i++) {
        const char *uri = mx_json_get_str(mx_json_at(list, i), "uri", NULL);
        char ref[PATH_MAX];
        if (!uri || !strncmp(uri, "data:", 5) || strstr(uri, "://")) continue;
        if (mx_gltf_uri_name(uri, ref, sizeof ref)) return mx_fail(st, MX_EINPUT, "%s: uri too long: %s", p->mesh, uri);
        if (add_part(p, "", ref, required, p->mesh, st) < 0) return -1;
    }
    return 0;
}

static uint32_t le32(const uint8_t *b) { return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24; }

/* The glTF JSON of a .gltf or .glb (the reader tells them by the magic, not the name): the file's
 * text, or a GLB's first chunk, its length checked against the file's (malloc'ed, *len bytes). */
static char *gltf_json(const char *path, size_t *len, mx_status *st) {
    uint8_t h[GLB_HEADER_BYTES];
    struct stat sb = {0};
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno)), NULL;
    size_t got = fread(h, 1, sizeof h, f);
    if (got < 4 || le32(h) != GLB_MAGIC) {
        fclose(f);
        return mx_read_file(path, GLTF_MAX_BYTES, len, st);
    }
    /* a GLB: the first chunk is its JSON; a length the file cannot hold is damage */
    uint64_t n = got == sizeof h && le32(h + 16) == GLB_CHUNK_JSON && !fstat(fileno(f), &sb) ? le32(h + 12) : UINT64_MAX;
    char *text = n <= GLTF_MAX_BYTES && n <= (uint64_t)sb.st_size - sizeof h ? malloc(n + 1) : NULL;
    if (text && fread(text, 1, n, f) == n) {
        text[n] = 0;
        *len = n;
    } else {
        free(text);
        text = NULL;
        mx_fail(st, MX_EINPUT, "%s: a GLB whose JSON chunk is damaged or too large", path);
    }
    fclose(f);
    return text;
}

static int gltf_parts(mesh_parts *p, mx_status *st) {
    size_t len;
    char *text = gltf_json(p->mesh, &len, st);
    mx_json *doc = text ? mx_json_parse(text, len, p->mesh, st) : NULL;
    free(text);
    int rc = !doc || uri_parts(p, mx_json_get(doc, "buffers"), 1, st) || uri_parts(p, mx_json_get(doc, "images"), 0, st);
    mx_json_free(doc);
    return rc ? -1 : 0;
}

static int has_extension(const char *path, const char *ext) {
    const char *dot = strrchr(path + dir_len(path), '.');
    return dot && !strcasecmp(dot + 1, ext);
}

/* The zip of the parts into a new temporary file. */
static int write_zip(const mesh_parts *p, FILE **zip, mx_status *st) {
    mx_zip_source *src = calloc(p->n, sizeof *src);
    char(*paths)[2 * PATH_MAX] = calloc(p->n, sizeof *paths), what[PATH_MAX + 32];
    FILE *f = src && paths ? tmpfile() : NULL;
    int rc = f ? 0 : mx_fail(st, MX_EIO, "%s: cannot make the zip to send: out of memory or temporary space", p->mesh);
    for (size_t i = 0; !rc && i < p->n; i++) {
        snprintf(paths[i], sizeof paths[i], "%s%s", p->dir, p->names[i]);
        src[i] = (mx_zip_source){.name = p->names[i], .path = paths[i]};
    }
    snprintf(what, sizeof what, "the zip of %s", p->mesh);
    if (!rc) rc = mx_zip_write(f, src, p->n, what, st);
    if (!rc && fseek(f, 0, SEEK_SET)) rc = mx_fail(st, MX_EIO, "%s: cannot read back", what);
    if (rc && f) fclose(f);
    else *zip = f;
    free(src);
    free(paths);
    return rc;
}

int mx_serve_upload_zip(const char *mesh_path, FILE **zip, mx_status *st) {
    int gltf = has_extension(mesh_path, "gltf"), glb = has_extension(mesh_path, "glb");
    *zip = NULL;
    if (!gltf && !glb && !has_extension(mesh_path, "obj")) return 0; /* PLY, STL, OFF: one file */
    mesh_parts *p = calloc(1, sizeof *p);
    if (!p) return mx_fail(st, MX_ENOMEM, "%s: out of memory", mesh_path);
    size_t d = dir_len(mesh_path);
    p->mesh = mesh_path;
    snprintf(p->dir, sizeof p->dir, "%.*s", (int)d, mesh_path);
    snprintf(p->names[p->n++], sizeof p->names[0], "%s", mesh_path + d);
    int rc = realpath(d ? p->dir : ".", p->real_dir) ? 0 : mx_fail(st, MX_EINPUT, "%s: cannot resolve its folder", mesh_path);
    if (!rc) rc = gltf || glb ? gltf_parts(p, st) : for_each_line(p, mesh_path, p->names[0], obj_line, st);
    int zipped = !rc && (gltf || p->n > 1);
    if (zipped && !mx_serve_zip_name_valid(mesh_path + d))
        rc = mx_fail(st, MX_EINPUT, "%s: not a file name a server takes in a zip (a backslash, colon or control byte, or too long)",
                     mesh_path);
    if (zipped && !rc) rc = write_zip(p, zip, st);
    free(p);
    return rc;
}
