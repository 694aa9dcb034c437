/* Images through the adapter (pipeline/io/imageio.cpp). First byte: 0 decodes the rest from
 * memory (as an image embedded in a GLB); 1, 2, 3 write it as fuzz.png, fuzz.jpg, fuzz.exr
 * and read that file (as a texture referenced by an OBJ/glTF). */
#include <stdlib.h>

#include "../../pipeline/geom/image.h"
#include "../../pipeline/io/io.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[3] = {"fuzz.png", "fuzz.jpg", "fuzz.exr"};
    if (!size) return 0;
    mx_status st;
    mx_image img;
    int rc = data[0] % 4 == 0 ? mx_io_decode_image(data + 1, size - 1, "fuzz", &img, &st)
                              : mx_io_read_image(fuzz_file(names[data[0] % 4 - 1], data + 1, size - 1), &img, &st);
    if (rc) return 0;
    size_t n = (size_t)img.w * img.h * img.c;
    if (img.w <= 0 || img.h <= 0 || img.c < 1 || img.c > 4 || img.data[0] + img.data[n - 1] != img.data[n - 1] + img.data[0])
        abort();
    mx_image_free(&img);
    return 0;
}
