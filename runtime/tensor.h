/* Element types and shapes (up to 5 dimensions, row-major) of the tensors of weight files,
 * safetensors files and the ops. Activations are `float *` handles (ops/ops.h); weights are
 * mx_wptr (data + dtype). */
#ifndef MX_TENSOR_H
#define MX_TENSOR_H

#include <stddef.h>
#include <stdint.h>

#include "status.h"

#define MX_MAX_DIMS 5

typedef enum { MX_F32 = 0, MX_F16 = 1, MX_BF16 = 2, MX_I32 = 3 } mx_dtype;

size_t mx_dtype_size(mx_dtype dt);
const char *mx_dtype_name(mx_dtype dt);
/* Formats "[2, 4, 64, 64]" into buf. */
const char *mx_shape_str(int ndim, const int64_t *shape, char *buf, size_t cap);

/* Element count with overflow check: returns -1 on overflow or negative dims. */
int64_t mx_shape_numel(int ndim, const int64_t *shape);

#endif
