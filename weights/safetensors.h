/* Reader of the safetensors format (8-byte LE header length N, N bytes of JSON, raw data).
 * Every offset is checked against the file length; dtypes F32, F16, BF16, F64, I64, I32 and U8
 * (8-bit images) are read.
 * The file is mmapped; tensor data pointers point into the mapping (possibly unaligned:
 * copy before SIMD use). */
#ifndef MX_SAFETENSORS_H
#define MX_SAFETENSORS_H

#include <stddef.h>
#include <stdint.h>

#include "../runtime/status.h"
#include "../runtime/tensor.h"

typedef enum { MX_ST_F32, MX_ST_F16, MX_ST_BF16, MX_ST_I64, MX_ST_I32, MX_ST_F64, MX_ST_U8 } mx_st_dtype;

typedef struct mx_st_tensor {
    char *name;
    mx_st_dtype dtype;
    int ndim;
    int64_t shape[8];
    const void *data;
    size_t nbytes;
} mx_st_tensor;

typedef struct mx_safetensors {
    char *path;
    void *map;
    size_t map_len;
    size_t count;
    mx_st_tensor *tensors;
    char *metadata_json; /* the __metadata__ object as JSON text, or NULL */
} mx_safetensors;

int mx_st_open(mx_safetensors *f, const char *path, mx_status *st);
/* Maps the whole of PATH read-only into f->map / f->map_len (closed by mx_st_close); a file shorter
 * than min_len is "not a KIND (N bytes, TOO_SHORT)". */
int mx_st_map_file(mx_safetensors *f, const char *path, long long min_len, const char *kind, const char *too_short,
                   mx_status *st);
void mx_st_close(mx_safetensors *f);
const mx_st_tensor *mx_st_find(const mx_safetensors *f, const char *name);
/* Sorts the tensors by name again (after a caller renamed them), as mx_st_find needs. */
void mx_st_sort(mx_safetensors *f);
/* Copies a floating tensor (F32/F16/BF16/F64) into a new malloc'ed fp32 array; I64/I32/U8 are
 * converted to float too. Returns NULL with an error naming file and tensor. */
float *mx_st_to_f32(const mx_safetensors *f, const mx_st_tensor *t, mx_status *st);

/* Writer for outputs of `matex run-net` and tests: fp32 tensors only (plus I64 for ids). */
typedef struct mx_st_out {
    const char *name;
    mx_st_dtype dtype; /* MX_ST_F32 or MX_ST_I64 */
    int ndim;
    int64_t shape[8];
    const void *data;
} mx_st_out;
/* Writes atomically (temp + rename). */
int mx_st_write(const char *path, const mx_st_out *tensors, size_t n, mx_status *st);

#endif
