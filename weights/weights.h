/* The matex weight file (format in weights/FORMAT.md): one mmapped file holding every
 * tensor of a model set (names are "<net>.<state-dict name>", e.g. "unet.conv_in.weight",
 * "controlnet_depth.controlnet_mid_block.bias", "vae.decoder.conv_in.weight",
 * "text_encoder.text_model.final_layer_norm.weight") and a metadata block of key -> text
 * (e.g. "unet.config" = config.json text, "tokenizer.vocab", "tokenizer.merges",
 * "scheduler.config", "provenance"). Every count, offset and size is validated on open. */
#ifndef MX_WEIGHTS_H
#define MX_WEIGHTS_H

#include <stddef.h>
#include <stdint.h>

#include "../runtime/status.h"
#include "../runtime/tensor.h"

typedef struct mx_wtensor {
    const char *name;
    mx_dtype dtype; /* MX_F32, MX_F16, MX_BF16 or MX_I32 */
    int ndim;
    int64_t shape[MX_MAX_DIMS];
    const void *data; /* inside the mapping, 64-byte aligned */
    size_t nbytes;
} mx_wtensor;

typedef struct mx_weightfile mx_weightfile;

int mx_wf_open(mx_weightfile **out, const char *path, mx_status *st);
void mx_wf_close(mx_weightfile *wf);
const char *mx_wf_path(const mx_weightfile *wf);
/* The open file and its whole mapping (len bytes): what mx_dev_weight_file streams to a device
 * (the fd is the file mapped, open until mx_wf_close; tensors' data point into the mapping). */
int mx_wf_fd(const mx_weightfile *wf);
const void *mx_wf_map(const mx_weightfile *wf, size_t *len);

size_t mx_wf_count(const mx_weightfile *wf);
const mx_wtensor *mx_wf_tensor(const mx_weightfile *wf, size_t i);
/* NULL when absent. */
const mx_wtensor *mx_wf_find(const mx_weightfile *wf, const char *name);
/* Finds `name` and checks its shape (ndim dims; a -1 dim matches anything); on failure the
 * message names the file, the tensor and the expected vs found shape. */
const mx_wtensor *mx_wf_require(const mx_weightfile *wf, const char *name, int ndim, const int64_t *shape,
                                mx_status *st);
/* Metadata value (NUL-terminated) or NULL. */
const char *mx_wf_meta(const mx_weightfile *wf, const char *key);
size_t mx_wf_meta_count(const mx_weightfile *wf);
const char *mx_wf_meta_key(const mx_weightfile *wf, size_t i);

/* Writer: collect tensors and metadata, then write atomically (temp file + rename). */
typedef struct mx_wf_writer mx_wf_writer;
mx_wf_writer *mx_wf_writer_create(mx_status *st);
/* Copies nothing: data must stay valid until mx_wf_writer_finish. The data's dtype is src_dtype;
 * it is converted to dtype when written (f32/f16/bf16 among themselves; i32 only as is). */
int mx_wf_writer_add(mx_wf_writer *w, const char *name, mx_dtype dtype, int ndim, const int64_t *shape,
                     const void *data, mx_dtype src_dtype, mx_status *st);
int mx_wf_writer_meta(mx_wf_writer *w, const char *key, const char *value, mx_status *st);
int mx_wf_writer_finish(mx_wf_writer *w, const char *path, mx_status *st);
void mx_wf_writer_free(mx_wf_writer *w);

#endif
