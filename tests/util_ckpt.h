/* Writers of checkpoint files for the tests and the fuzz seeds (no Python here to make them):
 * safetensors of any dtype, and PyTorch zip checkpoints laid out as torch.save writes them
 * (ARCHIVE/data.pkl with protocol-2 pickle opcodes, ARCHIVE/data/KEY storages, byteorder,
 * version; STORED entries aligned to 64 bytes). Also raw zips and pickles for hostile files. */
#ifndef MX_UTIL_CKPT_H
#define MX_UTIL_CKPT_H

#include <stddef.h>
#include <stdint.h>

#include "../runtime/buf.h"
#include "../weights/safetensors.h"

typedef struct mx_test_zip_entry {
    const char *name;
    const void *data;
    size_t size;
    int method;            /* 0 STORED; anything else is written as if compressed (for refusals) */
    uint64_t declared_size; /* size written in the headers (0: the real size) */
} mx_test_zip_entry;

/* Writes a zip of the entries; 0 on success. */
int mx_test_write_zip(const char *path, const mx_test_zip_entry *e, size_t n);

/* The pickle of a state dict of tensors as torch.save writes it; storage i holds tensor i.
 * wrap: 1 puts it under {"state_dict": ..., "global_step": 7}; MX_TEST_NESTED writes a dict of
 * dicts by the names' first component, "a.b.c" as {"a": {"b.c": ...}} (the IP-Adapter .bin; the
 * tensors sorted by it). Caller frees b->p. */
#define MX_TEST_NESTED 2
void mx_test_pickle_state_dict(mx_buf *b, const mx_st_tensor *t, size_t n, int wrap);

/* A whole checkpoint: pickle + storages + byteorder + version. */
int mx_test_write_torchzip(const char *path, const mx_st_tensor *t, size_t n, int wrap);

/* A safetensors file of the tensors as they are (any dtype). */
int mx_test_write_safetensors(const char *path, const mx_st_tensor *t, size_t n);

#endif
