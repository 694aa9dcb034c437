/* Single-file checkpoints (weights/single_file.c over torchzip.c, pickle.c, ldm_names.c): open
 * as a model and as a ControlNet, read every byte of every tensor found, print the summary.
 * Seeds: tiny torch.save-layout zips (tests/fuzz/seeds/ckpt, made by test_weights_single_file
 * with MX_WRITE_CKPT_SEEDS=DIR). */
#include <stdio.h>

#include "../../weights/single_file.h"
#include "fuzz.h"

static unsigned touch(const mx_single_file *sf) {
    unsigned sum = 0;
    for (size_t k = 0; k < sf->n_nets; k++)
        for (size_t i = 0; i < sf->nets[k].count; i++) {
            const unsigned char *p = sf->nets[k].tensors[i].data;
            for (size_t j = 0; j < sf->nets[k].tensors[i].nbytes; j++) sum += p[j];
        }
    return sum;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    fuzz_quiet();
    const char *path = fuzz_file("fuzz.ckpt", data, size);
    static FILE *sink;
    if (!sink) sink = fopen("/dev/null", "w");
    for (int flags = 0; flags <= MX_SF_CONTROLNET_ONLY; flags += MX_SF_CONTROLNET_ONLY) {
        mx_single_file sf;
        mx_status st;
        if (mx_sf_open(&sf, path, flags, &st)) continue;
        if (sink) fprintf(sink, "%u\n", touch(&sf));
        if (sink) mx_sf_print_info(&sf, sink);
        mx_sf_close(&sf);
    }
    return 0;
}
