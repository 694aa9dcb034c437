/* safetensors files (weights/safetensors.c): open, then every tensor found, converted to fp32. */
#include <stdlib.h>

#include "../../weights/safetensors.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    mx_status st;
    mx_safetensors f;
    if (mx_st_open(&f, fuzz_file("fuzz.safetensors", data, size), &st)) return 0;
    for (size_t i = 0; i < f.count; i++) {
        const mx_st_tensor *t = &f.tensors[i];
        if (mx_st_find(&f, t->name) == NULL) abort(); /* an opened file finds its own names */
        free(mx_st_to_f32(&f, t, &st));
    }
    mx_st_close(&f);
    return 0;
}
