/* glTF and GLB (pipeline/io/gltf.c): the first byte picks .gltf (even) or .glb (odd), the
 * rest is the file; buffers and images come from data: URIs or the GLB's binary chunk. The
 * mesh is loaded as the product loads it, then every embedded image is decoded. */
#include "../../pipeline/geom/image.h"
#include "../../pipeline/io/gltf.h"
#include "../../pipeline/io/mesh_load.h"
#include "fuzz.h"
#include "mesh_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (!size) return 0;
    fuzz_quiet();
    mx_status st;
    mx_mesh m;
    const char *path = fuzz_file(data[0] & 1 ? "fuzz.glb" : "fuzz.gltf", data + 1, size - 1);
    if (mx_mesh_load(path, &m, &st)) return 0;
    fuzz_use_mesh(&m);
    mx_image tex[64];
    if (m.nmat <= 64 && !mx_mesh_load_textures(&m, tex, &st))
        for (int i = 0; i < m.nmat; i++) mx_image_free(&tex[i]);
    mx_mesh_free(&m);
    mx_image img;
    if (!mx_gltf_read_image(path, 0, &img, &st)) mx_image_free(&img);
    return 0;
}
