/* PLY, OFF and STL through OpenMesh (pipeline/io/meshio.cpp): the first byte picks the
 * extension, the rest is the file. */
#include "../../pipeline/io/mesh_load.h"
#include "fuzz.h"
#include "mesh_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[3] = {"fuzz.ply", "fuzz.off", "fuzz.stl"};
    if (!size) return 0;
    fuzz_quiet();
    mx_status st;
    mx_mesh m;
    if (mx_mesh_load(fuzz_file(names[data[0] % 3], data + 1, size - 1), &m, &st)) return 0;
    fuzz_use_mesh(&m);
    mx_mesh_free(&m);
    return 0;
}
