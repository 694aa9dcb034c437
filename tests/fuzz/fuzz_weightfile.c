/* matex weight files (.mxw, weights/weightfile.c): open, touch the first and last byte of
 * every tensor, read every metadata entry, build the tokenizer it carries, print its table of
 * contents. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../pipeline/nn/tokenizer.h"
#include "../../weights/weights.h"
#include "../../weights/wfinfo.h"
#include "fuzz.h"

static unsigned touch(const mx_weightfile *wf) {
    unsigned sum = 0;
    for (size_t i = 0; i < mx_wf_count(wf); i++) {
        const mx_wtensor *t = mx_wf_tensor(wf, i);
        if (t->nbytes) sum += ((const uint8_t *)t->data)[0] + ((const uint8_t *)t->data)[t->nbytes - 1];
        if (mx_wf_find(wf, t->name) == NULL) abort(); /* an opened file finds its own names */
    }
    for (size_t i = 0; i < mx_wf_meta_count(wf); i++) sum += (unsigned)strlen(mx_wf_meta(wf, mx_wf_meta_key(wf, i)));
    return sum;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    mx_status st;
    mx_weightfile *wf;
    const char *path = fuzz_file("fuzz.mxw", data, size);
    if (mx_wf_open(&wf, path, &st)) return 0;
    touch(wf);
    mx_tokenizer *tok;
    if (!mx_tok_load_weights(&tok, wf, &st)) mx_tok_free(tok);
    mx_wf_close(wf);
    FILE *null = fopen("/dev/null", "w");
    if (null) {
        mx_wf_print_info(path, null, &st);
        fclose(null);
    }
    return 0;
}
