/* Loading a mesh and its textures by extension (pipeline/io/mesh_load.h). */
#include "mesh_load.h"

#include <ctype.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../geom/mesh.h"
#include "filekind.h"
#include "gltf.h"
#include "io.h"

/* 1 when path's last component ends in "." ext, case-insensitive (ext in lower case). */
static int has_ext(const char *path, const char *ext) {
    const char *dot = strrchr(path, '.');
    if (!dot || strchr(dot, '/')) return 0;
    for (dot++; *dot && *ext; dot++, ext++)
        if (tolower((unsigned char)*dot) != *ext) return 0;
    return !*dot && !*ext;
}

int mx_mesh_load(const char *path, mx_mesh *m, mx_status *st) {
    memset(m, 0, sizeof *m);
    if (mx_mesh_check_file(path, st)) return -1;
    int rc = has_ext(path, "gltf") || has_ext(path, "glb") ? mx_gltf_load(path, m, st) : mx_io_read_mesh(path, m, st);
    if (rc) return -1;
    if (mx_mesh_validate(m, st)) {
        mx_mesh_free(m);
        return -1;
    }
    return 0;
}

/* "<file>#image<N>" names an image inside a glTF file: returns N and the file part. */
static int embedded_image_ref(const char *tex_path, char *file, size_t cap) {
    const char *hash = strrchr(tex_path, '#');
    if (!hash || strncmp(hash, "#image", 6) || !isdigit((unsigned char)hash[6])) return -1;
    char *end;
    long n = strtol(hash + 6, &end, 10);
    if (*end || n < 0 || n > 1000000 || (size_t)(hash - tex_path) >= cap) return -1;
    memcpy(file, tex_path, (size_t)(hash - tex_path));
    file[hash - tex_path] = 0;
    return (int)n;
}

int mx_mesh_load_textures(const mx_mesh *m, mx_image *tex, mx_status *st) {
    for (int i = 0; i < m->nmat; i++) memset(&tex[i], 0, sizeof tex[i]);
    for (int i = 0; i < m->nmat; i++) {
        const char *tp = m->mats[i].texture_path;
        if (!tp[0]) continue;
        char file[sizeof m->mats[i].texture_path];
        int index = embedded_image_ref(tp, file, sizeof file);
        mx_status err;
        int rc = index >= 0 ? mx_gltf_read_image(file, index, &tex[i], &err) : mx_io_read_image(tp, &tex[i], &err);
        if (rc == 0) continue;
        if (err.code == MX_ENOMEM) {
            for (int k = 0; k < i; k++) mx_image_free(&tex[k]);
            return mx_fail(st, MX_ENOMEM, "%s", err.msg);
        }
        mx_warn("%s: material '%s': %s; no texture", m->source_path, m->mats[i].name, err.msg);
    }
    return 0;
}
