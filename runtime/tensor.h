/* Tensors: a dtype, up to 5 dimensions, contiguous row-major (C order) data.
 * A tensor does not own its data: it points into an arena, an mmapped weight file
 * or a caller's buffer. */
#ifndef MX_TENSOR_H
#define MX_TENSOR_H

#include <stddef.h>
#include <stdint.h>

#include "status.h"

#define MX_MAX_DIMS 5

typedef enum { MX_F32 = 0, MX_F16 = 1, MX_BF16 = 2, MX_I32 = 3 } mx_dtype;

typedef struct mx_tensor {
    mx_dtype dtype;
    int ndim;
    int64_t shape[MX_MAX_DIMS];
    void *data;
} mx_tensor;

size_t mx_dtype_size(mx_dtype dt);
const char *mx_dtype_name(mx_dtype dt);

/* Builds a tensor header; fails (bad shape: ndim outside 1..5, a negative dim,
 * or an element count that overflows) with a message naming `what`. */
int mx_tensor_init(mx_tensor *t, mx_dtype dt, int ndim, const int64_t *shape, void *data,
                   const char *what, mx_status *st);
int64_t mx_tensor_numel(const mx_tensor *t);
size_t mx_tensor_nbytes(const mx_tensor *t);
/* 1 when both have the same ndim and dims. */
int mx_tensor_same_shape(const mx_tensor *a, const mx_tensor *b);
/* Formats "[2, 4, 64, 64]" into buf. */
const char *mx_shape_str(int ndim, const int64_t *shape, char *buf, size_t cap);

/* Element count with overflow check: returns -1 on overflow or negative dims. */
int64_t mx_shape_numel(int ndim, const int64_t *shape);

#endif
