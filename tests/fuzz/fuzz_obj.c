/* OBJ + MTL (pipeline/io/meshio.cpp): the input is "OBJ text FUZZ_SEP MTL text", written as
 * fuzz.obj and fuzz.mtl (the seeds say `mtllib fuzz.mtl`), loaded as the product loads any
 * mesh, then its textures (missing files are warnings). */
#include "../../pipeline/geom/image.h"
#include "../../pipeline/io/mesh_load.h"
#include "fuzz.h"
#include "mesh_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    fuzz_quiet();
    size_t obj_len, mtl_len;
    const uint8_t *mtl;
    fuzz_split(data, size, FUZZ_SEP, &obj_len, &mtl, &mtl_len);
    fuzz_file("fuzz.mtl", mtl, mtl_len);
    mx_status st;
    mx_mesh m;
    if (mx_mesh_load(fuzz_file("fuzz.obj", data, obj_len), &m, &st)) return 0;
    fuzz_use_mesh(&m);
    mx_image tex[64];
    if (m.nmat <= 64 && !mx_mesh_load_textures(&m, tex, &st))
        for (int i = 0; i < m.nmat; i++) mx_image_free(&tex[i]);
    mx_mesh_free(&m);
    return 0;
}
