/* conv2d through cuDNN 9's backend (graph) API, OFF unless MATEX_CUDNN=1 (no GPU has run it yet:
 * docs/cuda-notes.md §8). One item of the batch per call, as the im2col path (cuda_conv.cu), so an
 * item computes the same bits alone or in a batch:
 *   x_b (fp32 NCHW) -> x16 (fp16 NHWC), w (fp16 KCRS, as in the weight file) -> w16 (fp16 KRSC),
 *   cuDNN: y16 = conv(x16, w16) [+ bias]  (fp16 in and out, fp32 accumulation),
 *   y16 (fp16 NHWC) -> y_b (fp32 NCHW) [+ bias where the graph could not fuse it].
 * The library is loaded at run time (dlopen libcudnn.so.9: the GPU machine's own cuDNN, from the
 * CUDA toolkit or PyTorch's nvidia/cudnn), so a binary runs, on today's path, where there is none.
 * Execution plans are built on the first call of a shape, among deterministic engines with fp32
 * accumulation only (numerical notes), and cached by mx_cudnn_conv_key (GPU, driver, cuDNN
 * version, shape, types, alignments); a shape no such engine runs is cached as "none" and goes
 * through im2col. Without cuDNN's headers (make CUDNN=0) only the decision is compiled. */
#include <stdio.h>
#include <string.h>

extern "C" {
#include "../../runtime/log.h" /* a C header without its own extern "C" */
}
#include "cuda_common.cuh"
#include "cudnn_plan.h"

#ifdef MX_WITH_CUDNN
#include <dlfcn.h>

#include <cudnn_graph.h>

#define PLAN_SLOTS 512        /* shapes per context: SD1.5's three networks use ~60 */
#define PLAN_DESCS 16         /* descriptors one plan keeps alive */
#define MAX_ENGINE_CFGS 32    /* heuristic results tried per mode */
#define MAX_WORKSPACE ((int64_t)256 << 20)

/* The backend-API entry points, looked up in the library found at run time. */
typedef struct cudnn_api {
    void *lib;
    decltype(&cudnnGetVersion) GetVersion;
    decltype(&cudnnGetErrorString) GetErrorString;
    decltype(&cudnnCreate) Create;
    decltype(&cudnnDestroy) Destroy;
    decltype(&cudnnSetStream) SetStream;
    decltype(&cudnnBackendCreateDescriptor) CreateDescriptor;
    decltype(&cudnnBackendDestroyDescriptor) DestroyDescriptor;
    decltype(&cudnnBackendFinalize) Finalize;
    decltype(&cudnnBackendSetAttribute) SetAttribute;
    decltype(&cudnnBackendGetAttribute) GetAttribute;
    decltype(&cudnnBackendExecute) Execute;
} cudnn_api;

/* One cached shape: its plan (ok) or "no deterministic engine runs it" (!ok: im2col). */
typedef struct cudnn_plan {
    mx_cudnn_conv_key key;
    int used, ok, fused_bias;
    int64_t workspace;
    cudnnBackendDescriptor_t plan;
    cudnnBackendDescriptor_t keep[PLAN_DESCS]; /* everything the plan was built from */
    int nkeep;
} cudnn_plan;

struct mx_cuda_cudnn {
    cudnn_api api;
    cudnnHandle_t handle;
    mx_cudnn_conv_key base; /* the GPU, driver and library fields of every key */
    cudnn_plan *plans;      /* PLAN_SLOTS, open addressing */
    void *buf;              /* x16, w16, y16 and the workspace of one call, grown on demand */
    size_t buf_bytes;
};

/* CUDNN_ATTR_OPERATIONGRAPH_HANDLE and CUDNN_ATTR_EXECUTION_PLAN_HANDLE: deprecated by cuDNN 9.19's
 * headers (the handle is given at execution) but required by earlier 9.x, which the GPU machine
 * may carry: set by value, so that the deprecation does not fail the build, and their failure is
 * ignored. */
static const cudnnBackendAttributeName_t ATTR_GRAPH_HANDLE = (cudnnBackendAttributeName_t)800;
static const cudnnBackendAttributeName_t ATTR_PLAN_HANDLE = (cudnnBackendAttributeName_t)400;

static int load_api(cudnn_api *a, char *err, size_t err_size) {
    memset(a, 0, sizeof *a);
    a->lib = dlopen("libcudnn.so.9", RTLD_NOW | RTLD_LOCAL);
    if (!a->lib) {
        snprintf(err, err_size, "%s", dlerror());
        return -1;
    }
#define LOAD_(field, sym)                                                                 \
    if (!(*(void **)&a->field = dlsym(a->lib, #sym))) {                                   \
        snprintf(err, err_size, "libcudnn.so.9 has no %s", #sym);                         \
        dlclose(a->lib);                                                                  \
        a->lib = NULL;                                                                    \
        return -1;                                                                        \
    }
    LOAD_(GetVersion, cudnnGetVersion)
    LOAD_(GetErrorString, cudnnGetErrorString)
    LOAD_(Create, cudnnCreate)
    LOAD_(Destroy, cudnnDestroy)
    LOAD_(SetStream, cudnnSetStream)
    LOAD_(CreateDescriptor, cudnnBackendCreateDescriptor)
    LOAD_(DestroyDescriptor, cudnnBackendDestroyDescriptor)
    LOAD_(Finalize, cudnnBackendFinalize)
    LOAD_(SetAttribute, cudnnBackendSetAttribute)
    LOAD_(GetAttribute, cudnnBackendGetAttribute)
    LOAD_(Execute, cudnnBackendExecute)
#undef LOAD_
    return 0;
}

/* The GPU, driver and library fields of the keys. */
static void base_key(mx_cuda_cudnn *n) {
    cudaDeviceProp p;
    int dev = 0, drv = 0;
    memset(&p, 0, sizeof p);
    (void)cudaGetDevice(&dev);
    (void)cudaGetDeviceProperties(&p, dev);
    (void)cudaDriverGetVersion(&drv);
    mx_cudnn_key_init(&n->base, p.name, p.major * 10 + p.minor, drv, (long)n->api.GetVersion());
}

void mx_cuda_cudnn_open(mx_cuda_ctx *c) {
    const char *env = getenv("MATEX_CUDNN");
    char why[320], err[256] = "";
    cudnn_api api;
    size_t version = 0;
    if (env && strcmp(env, "1") == 0 && load_api(&api, err, sizeof err) == 0) version = api.GetVersion();
    int use = mx_cudnn_decide(env, 1, version, err, why, sizeof why);
    mx_cuda_cudnn *n = NULL;
    if (use) {
        n = (mx_cuda_cudnn *)calloc(1, sizeof *n);
        cudnn_plan *plans = (cudnn_plan *)calloc(PLAN_SLOTS, sizeof *plans);
        cudnnStatus_t s = CUDNN_STATUS_ALLOC_FAILED;
        if (n && plans && (s = api.Create(&n->handle)) == CUDNN_STATUS_SUCCESS &&
            (s = api.SetStream(n->handle, c->stream)) == CUDNN_STATUS_SUCCESS) {
            n->api = api;
            n->plans = plans;
            base_key(n);
        } else {
            snprintf(why, sizeof why, "convolution through im2col + cuBLASLt: MATEX_CUDNN=1, but cuDNN %zu could not "
                     "start (cudnnCreate: %s)", version, api.GetErrorString(s));
            if (n && n->handle) api.Destroy(n->handle);
            free(plans);
            free(n);
            n = NULL;
        }
    }
    if (!n && version) dlclose(api.lib);
    c->cudnn = n;
    /* One line only where it was asked for: today's path is the default and says nothing. */
    if (env && strcmp(env, "1") == 0) {
        if (n) mx_info("cuda: %s", why);
        else mx_warn("cuda: %s", why);
    }
}

static void plan_free(const cudnn_api *a, cudnn_plan *p) {
    for (int i = p->nkeep - 1; i >= 0; i--) a->DestroyDescriptor(p->keep[i]);
    memset(p, 0, sizeof *p);
}

void mx_cuda_cudnn_close(mx_cuda_ctx *c) {
    mx_cuda_cudnn *n = c->cudnn;
    if (!n) return;
    for (int i = 0; i < PLAN_SLOTS; i++)
        if (n->plans[i].used) plan_free(&n->api, &n->plans[i]);
    free(n->plans);
    if (n->buf) cudaFree(n->buf);
    n->api.Destroy(n->handle);
    dlclose(n->api.lib);
    free(n);
    c->cudnn = NULL;
}

/* ---- building a plan: descriptors made through `build`, which keeps them and the first failure ---- */

typedef struct build {
    const cudnn_api *a;
    cudnn_plan *p;
    cudnnStatus_t s;
    const char *where; /* the call that failed first */
} build;

static cudnnBackendDescriptor_t make(build *b, cudnnBackendDescriptorType_t type) {
    cudnnBackendDescriptor_t d = NULL;
    if (b->s != CUDNN_STATUS_SUCCESS) return NULL;
    if (b->p->nkeep == PLAN_DESCS) {
        b->s = CUDNN_STATUS_INTERNAL_ERROR;
        b->where = "too many descriptors";
        return NULL;
    }
    if ((b->s = b->a->CreateDescriptor(type, &d)) != CUDNN_STATUS_SUCCESS) {
        b->where = "cudnnBackendCreateDescriptor";
        return NULL;
    }
    b->p->keep[b->p->nkeep++] = d;
    return d;
}

static void set(build *b, cudnnBackendDescriptor_t d, cudnnBackendAttributeName_t name, cudnnBackendAttributeType_t type,
                int64_t count, const void *value) {
    if (b->s != CUDNN_STATUS_SUCCESS) return;
    if ((b->s = b->a->SetAttribute(d, name, type, count, value)) != CUDNN_STATUS_SUCCESS)
        b->where = "cudnnBackendSetAttribute";
}

static void finalize(build *b, cudnnBackendDescriptor_t d) {
    if (b->s != CUDNN_STATUS_SUCCESS) return;
    if ((b->s = b->a->Finalize(d)) != CUDNN_STATUS_SUCCESS) b->where = "cudnnBackendFinalize";
}

static cudnnDataType_t cudnn_type(int dtype) {
    return dtype == MX_F16 ? CUDNN_DATA_HALF : dtype == MX_BF16 ? CUDNN_DATA_BFLOAT16 : CUDNN_DATA_FLOAT;
}

/* A 4-d tensor [n, c, h, w] stored NHWC (strides h*w*c, 1, w*c, c). */
static cudnnBackendDescriptor_t tensor(build *b, int64_t uid, cudnnDataType_t type, int64_t n, int64_t ch, int64_t h,
                                       int64_t w, int64_t align, bool is_virtual) {
    const int64_t dims[4] = {n, ch, h, w}, strides[4] = {h * w * ch, 1, w * ch, ch};
    cudnnBackendDescriptor_t d = make(b, CUDNN_BACKEND_TENSOR_DESCRIPTOR);
    set(b, d, CUDNN_ATTR_TENSOR_DATA_TYPE, CUDNN_TYPE_DATA_TYPE, 1, &type);
    set(b, d, CUDNN_ATTR_TENSOR_DIMENSIONS, CUDNN_TYPE_INT64, 4, dims);
    set(b, d, CUDNN_ATTR_TENSOR_STRIDES, CUDNN_TYPE_INT64, 4, strides);
    set(b, d, CUDNN_ATTR_TENSOR_UNIQUE_ID, CUDNN_TYPE_INT64, 1, &uid);
    set(b, d, CUDNN_ATTR_TENSOR_BYTE_ALIGNMENT, CUDNN_TYPE_INT64, 1, &align);
    set(b, d, CUDNN_ATTR_TENSOR_IS_VIRTUAL, CUDNN_TYPE_BOOLEAN, 1, &is_virtual);
    finalize(b, d);
    return d;
}

enum { UID_X = 1, UID_W, UID_Y, UID_BIAS, UID_CONV_OUT };

/* The operation graph: y = conv(x, w) (+ bias when fuse_bias), fp16 tensors, fp32 math. */
static cudnnBackendDescriptor_t conv_graph(build *b, cudnnHandle_t handle, const mx_cudnn_conv_key *k, int fuse_bias) {
    int64_t ho = (k->h + 2 * k->pad - k->kh) / k->stride + 1, wo = (k->w + 2 * k->pad - k->kw) / k->stride + 1;
    cudnnBackendDescriptor_t x = tensor(b, UID_X, CUDNN_DATA_HALF, k->n, k->cin, k->h, k->w, k->align_x, false);
    cudnnBackendDescriptor_t w = tensor(b, UID_W, CUDNN_DATA_HALF, k->cout, k->cin, k->kh, k->kw, k->align_w, false);
    cudnnBackendDescriptor_t y = tensor(b, UID_Y, CUDNN_DATA_HALF, k->n, k->cout, ho, wo, k->align_y, false);
    cudnnBackendDescriptor_t conv_out =
        fuse_bias ? tensor(b, UID_CONV_OUT, CUDNN_DATA_FLOAT, k->n, k->cout, ho, wo, 16, true) : y;

    cudnnDataType_t fp32 = CUDNN_DATA_FLOAT;
    cudnnConvolutionMode_t mode = CUDNN_CROSS_CORRELATION;
    const int64_t dims = 2, dil[2] = {1, 1}, strides[2] = {k->stride, k->stride}, pads[2] = {k->pad, k->pad};
    cudnnBackendDescriptor_t cd = make(b, CUDNN_BACKEND_CONVOLUTION_DESCRIPTOR);
    set(b, cd, CUDNN_ATTR_CONVOLUTION_COMP_TYPE, CUDNN_TYPE_DATA_TYPE, 1, &fp32);
    set(b, cd, CUDNN_ATTR_CONVOLUTION_CONV_MODE, CUDNN_TYPE_CONVOLUTION_MODE, 1, &mode);
    set(b, cd, CUDNN_ATTR_CONVOLUTION_SPATIAL_DIMS, CUDNN_TYPE_INT64, 1, &dims);
    set(b, cd, CUDNN_ATTR_CONVOLUTION_DILATIONS, CUDNN_TYPE_INT64, 2, dil);
    set(b, cd, CUDNN_ATTR_CONVOLUTION_FILTER_STRIDES, CUDNN_TYPE_INT64, 2, strides);
    set(b, cd, CUDNN_ATTR_CONVOLUTION_PRE_PADDINGS, CUDNN_TYPE_INT64, 2, pads);
    set(b, cd, CUDNN_ATTR_CONVOLUTION_POST_PADDINGS, CUDNN_TYPE_INT64, 2, pads);
    finalize(b, cd);

    float one = 1.0f, zero = 0.0f;
    cudnnBackendDescriptor_t ops[2];
    ops[0] = make(b, CUDNN_BACKEND_OPERATION_CONVOLUTION_FORWARD_DESCRIPTOR);
    set(b, ops[0], CUDNN_ATTR_OPERATION_CONVOLUTION_FORWARD_X, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &x);
    set(b, ops[0], CUDNN_ATTR_OPERATION_CONVOLUTION_FORWARD_W, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &w);
    set(b, ops[0], CUDNN_ATTR_OPERATION_CONVOLUTION_FORWARD_Y, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &conv_out);
    set(b, ops[0], CUDNN_ATTR_OPERATION_CONVOLUTION_FORWARD_CONV_DESC, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &cd);
    set(b, ops[0], CUDNN_ATTR_OPERATION_CONVOLUTION_FORWARD_ALPHA, CUDNN_TYPE_FLOAT, 1, &one);
    set(b, ops[0], CUDNN_ATTR_OPERATION_CONVOLUTION_FORWARD_BETA, CUDNN_TYPE_FLOAT, 1, &zero);
    finalize(b, ops[0]);
    if (fuse_bias) {
        cudnnPointwiseMode_t add = CUDNN_POINTWISE_ADD;
        cudnnBackendDescriptor_t bias =
            tensor(b, UID_BIAS, cudnn_type(k->bdtype), 1, k->cout, 1, 1, k->align_b, false);
        cudnnBackendDescriptor_t pw = make(b, CUDNN_BACKEND_POINTWISE_DESCRIPTOR);
        set(b, pw, CUDNN_ATTR_POINTWISE_MODE, CUDNN_TYPE_POINTWISE_MODE, 1, &add);
        set(b, pw, CUDNN_ATTR_POINTWISE_MATH_PREC, CUDNN_TYPE_DATA_TYPE, 1, &fp32);
        finalize(b, pw);
        ops[1] = make(b, CUDNN_BACKEND_OPERATION_POINTWISE_DESCRIPTOR);
        set(b, ops[1], CUDNN_ATTR_OPERATION_POINTWISE_PW_DESCRIPTOR, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &pw);
        set(b, ops[1], CUDNN_ATTR_OPERATION_POINTWISE_XDESC, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &conv_out);
        set(b, ops[1], CUDNN_ATTR_OPERATION_POINTWISE_BDESC, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &bias);
        set(b, ops[1], CUDNN_ATTR_OPERATION_POINTWISE_YDESC, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &y);
        finalize(b, ops[1]);
    }
    cudnnBackendDescriptor_t g = make(b, CUDNN_BACKEND_OPERATIONGRAPH_DESCRIPTOR);
    set(b, g, CUDNN_ATTR_OPERATIONGRAPH_OPS, CUDNN_TYPE_BACKEND_DESCRIPTOR, fuse_bias ? 2 : 1, ops);
    if (b->s == CUDNN_STATUS_SUCCESS) (void)b->a->SetAttribute(g, ATTR_GRAPH_HANDLE, CUDNN_TYPE_HANDLE, 1, &handle);
    finalize(b, g);
    return g;
}

/* An engine is acceptable when it is deterministic and accumulates in fp32 (same seed, same
 * bytes; the accuracy of today's path). */
static int engine_acceptable(const cudnn_api *a, cudnnBackendDescriptor_t cfg) {
    cudnnBackendDescriptor_t e = NULL;
    int64_t n = 0;
    int ok = 0;
    if (a->CreateDescriptor(CUDNN_BACKEND_ENGINE_DESCRIPTOR, &e) != CUDNN_STATUS_SUCCESS) return 0;
    cudnnBackendNumericalNote_t notes[CUDNN_NUMERICAL_NOTE_TYPE_COUNT];
    if (a->GetAttribute(cfg, CUDNN_ATTR_ENGINECFG_ENGINE, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &n, &e) ==
            CUDNN_STATUS_SUCCESS &&
        a->GetAttribute(e, CUDNN_ATTR_ENGINE_NUMERICAL_NOTE, CUDNN_TYPE_NUMERICAL_NOTE,
                        CUDNN_NUMERICAL_NOTE_TYPE_COUNT, &n, notes) == CUDNN_STATUS_SUCCESS) {
        ok = 1;
        for (int64_t i = 0; i < n && i < CUDNN_NUMERICAL_NOTE_TYPE_COUNT; i++)
            if (notes[i] == CUDNN_NUMERICAL_NOTE_NONDETERMINISTIC ||
                notes[i] == CUDNN_NUMERICAL_NOTE_REDUCED_PRECISION_REDUCTION ||
                notes[i] == CUDNN_NUMERICAL_NOTE_DOWN_CONVERT_INPUTS)
                ok = 0;
    }
    a->DestroyDescriptor(e);
    return ok;
}

/* The first acceptable engine configuration of the heuristic `mode` whose plan finalises within
 * MAX_WORKSPACE: kept in p (plan, workspace). 0 when found. */
static int choose_plan(build *b, cudnnHandle_t handle, cudnnBackendDescriptor_t graph, cudnnBackendHeurMode_t mode) {
    const cudnn_api *a = b->a;
    cudnnBackendDescriptor_t heur = NULL, cfgs[MAX_ENGINE_CFGS];
    int64_t count = 0;
    int found = -1;
    if (a->CreateDescriptor(CUDNN_BACKEND_ENGINEHEUR_DESCRIPTOR, &heur) != CUDNN_STATUS_SUCCESS) return -1;
    int ncfg = 0;
    if (a->SetAttribute(heur, CUDNN_ATTR_ENGINEHEUR_OPERATION_GRAPH, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1, &graph) ==
            CUDNN_STATUS_SUCCESS &&
        a->SetAttribute(heur, CUDNN_ATTR_ENGINEHEUR_MODE, CUDNN_TYPE_HEUR_MODE, 1, &mode) == CUDNN_STATUS_SUCCESS &&
        a->Finalize(heur) == CUDNN_STATUS_SUCCESS &&
        a->GetAttribute(heur, CUDNN_ATTR_ENGINEHEUR_RESULTS, CUDNN_TYPE_BACKEND_DESCRIPTOR, 0, &count, NULL) ==
            CUDNN_STATUS_SUCCESS) {
        for (; ncfg < count && ncfg < MAX_ENGINE_CFGS; ncfg++)
            if (a->CreateDescriptor(CUDNN_BACKEND_ENGINECFG_DESCRIPTOR, &cfgs[ncfg]) != CUDNN_STATUS_SUCCESS) break;
        if (a->GetAttribute(heur, CUDNN_ATTR_ENGINEHEUR_RESULTS, CUDNN_TYPE_BACKEND_DESCRIPTOR, ncfg, &count, cfgs) !=
            CUDNN_STATUS_SUCCESS)
            count = 0;
    }
    for (int i = 0; i < ncfg && i < count && found < 0; i++) {
        if (!engine_acceptable(a, cfgs[i])) continue;
        cudnnBackendDescriptor_t plan = NULL;
        int64_t ws = 0, n = 0;
        if (a->CreateDescriptor(CUDNN_BACKEND_EXECUTION_PLAN_DESCRIPTOR, &plan) != CUDNN_STATUS_SUCCESS) continue;
        (void)a->SetAttribute(plan, ATTR_PLAN_HANDLE, CUDNN_TYPE_HANDLE, 1, &handle);
        if (a->SetAttribute(plan, CUDNN_ATTR_EXECUTION_PLAN_ENGINE_CONFIG, CUDNN_TYPE_BACKEND_DESCRIPTOR, 1,
                            &cfgs[i]) == CUDNN_STATUS_SUCCESS &&
            a->Finalize(plan) == CUDNN_STATUS_SUCCESS &&
            a->GetAttribute(plan, CUDNN_ATTR_EXECUTION_PLAN_WORKSPACE_SIZE, CUDNN_TYPE_INT64, 1, &n, &ws) ==
                CUDNN_STATUS_SUCCESS &&
            ws >= 0 && ws <= MAX_WORKSPACE && b->p->nkeep + 2 <= PLAN_DESCS) {
            found = i;
            b->p->keep[b->p->nkeep++] = cfgs[i];
            b->p->keep[b->p->nkeep++] = plan;
            b->p->plan = plan;
            b->p->workspace = ws;
        } else {
            a->DestroyDescriptor(plan);
        }
    }
    for (int i = 0; i < ncfg; i++)
        if (i != found) a->DestroyDescriptor(cfgs[i]);
    a->DestroyDescriptor(heur);
    return found >= 0 ? 0 : -1;
}

/* Builds p's plan for p->key: the bias fused into the graph if the key has one and an engine runs
 * that graph, else the convolution alone (the bias then added by the unpacking kernel). Marks p
 * !ok when neither works (that shape then goes through im2col: not an error). */
static void plan_build(mx_cuda_cudnn *n, cudnn_plan *p) {
    static const cudnnBackendHeurMode_t modes[2] = {CUDNN_HEUR_MODE_A, CUDNN_HEUR_MODE_FALLBACK};
    for (int fuse = p->key.bdtype >= 0; fuse >= 0; fuse--) {
        for (int m = 0; m < 2; m++) {
            build b = {&n->api, p, CUDNN_STATUS_SUCCESS, NULL};
            cudnnBackendDescriptor_t g = conv_graph(&b, n->handle, &p->key, fuse);
            if (b.s == CUDNN_STATUS_SUCCESS && choose_plan(&b, n->handle, g, modes[m]) == 0) {
                p->ok = 1;
                p->fused_bias = fuse;
                return;
            }
            if (b.s != CUDNN_STATUS_SUCCESS)
                mx_debug("cuda: cuDNN conv graph %dx%dx%dx%d k%d s%d: %s: %s", p->key.cin, p->key.h, p->key.w,
                         p->key.cout, p->key.kh, p->key.stride, b.where, n->api.GetErrorString(b.s));
            mx_cudnn_conv_key key = p->key;
            plan_free(&n->api, p); /* and try the next variant on clean descriptors */
            p->key = key;
            p->used = 1;
        }
    }
    mx_info("cuda: no deterministic cuDNN engine runs conv %d->%d %dx%d k%dx%d s%d p%d: im2col + cuBLASLt",
            p->key.cin, p->key.cout, p->key.h, p->key.w, p->key.kh, p->key.kw, p->key.stride, p->key.pad);
}

/* The cached plan of key, built on its first use (when `build`: never while a CUDA graph is
 * captured). NULL when the table is full (then: im2col), or when it is not there and not built. */
static cudnn_plan *plan_for(mx_cuda_cudnn *n, const mx_cudnn_conv_key *key, int build) {
    uint64_t h = mx_cudnn_key_hash(key);
    for (int probe = 0; probe < PLAN_SLOTS; probe++) {
        cudnn_plan *p = &n->plans[(h + (uint64_t)probe) % PLAN_SLOTS];
        if (p->used && mx_cudnn_key_equal(&p->key, key)) return p;
        if (!p->used) {
            if (!build) return NULL;
            p->used = 1;
            p->key = *key;
            plan_build(n, p);
            return p;
        }
    }
    return NULL;
}

/* ---- layouts: one tiled transposing kernel for x (fp32 NCHW -> fp16 NHWC), the filter (KCRS ->
 * KRSC, per output channel) and y (fp16 NHWC -> fp32 NCHW, + bias) ---- */

__device__ __forceinline__ float as_float(float v) { return v; }
__device__ __forceinline__ float as_float(__half v) { return __half2float(v); }

/* Per blockIdx.z (plane), dst[q*rows + r] = src[r*cols + q] (+ bias[q]), through a 32x33 tile. */
template <typename Tin, typename Tout>
__global__ void transpose_kernel(Tout *dst, const Tin *src, unsigned rows, unsigned cols, const void *bias,
                                 int bias_dtype) {
    __shared__ float tile[32][33];
    size_t plane = (size_t)rows * cols;
    src += blockIdx.z * plane;
    dst += blockIdx.z * plane;
    unsigned r0 = blockIdx.y * 32, q0 = blockIdx.x * 32;
    for (unsigned i = threadIdx.y; i < 32; i += 8) {
        unsigned r = r0 + i, q = q0 + threadIdx.x;
        if (r < rows && q < cols) tile[i][threadIdx.x] = as_float(src[(size_t)r * cols + q]);
    }
    __syncthreads();
    for (unsigned i = threadIdx.y; i < 32; i += 8) {
        unsigned q = q0 + i, r = r0 + threadIdx.x;
        if (r < rows && q < cols) {
            float v = tile[threadIdx.x][i];
            if (bias) v += mx_cuda_wload(bias, bias_dtype, q);
            dst[mx_transpose_dst_offset(r, q, rows)] = mx_cuda_store<Tout>(v);
        }
    }
}

template <typename Tin, typename Tout>
static int transpose(mx_cuda_ctx *c, Tout *dst, const Tin *src, unsigned rows, unsigned cols, unsigned planes,
                     mx_wptr bias, const char *what, mx_status *st) {
    dim3 grid((cols + 31) / 32, (rows + 31) / 32, planes);
    if (grid.y > 65535 || grid.z > 65535) return mx_fail(st, MX_EINPUT, "%s: %u x %u x %u too large", what, planes, rows, cols);
    transpose_kernel<Tin, Tout><<<grid, dim3(32, 8), 0, c->stream>>>(dst, src, rows, cols, bias.data, (int)bias.dtype);
    return mx_cuda_launched(what, st);
}

/* The call's device buffer of at least `bytes` (freeing the old one waits for the device: only
 * while the first calls of the largest shapes grow it). */
static void *call_buffer(mx_cuda_cudnn *n, size_t bytes, mx_status *st) {
    if (bytes <= n->buf_bytes) return n->buf;
    if (n->buf) cudaFree(n->buf); /* cudaMalloc/cudaFree here: cuda_memory.cu opens this file's state */
    n->buf = NULL;
    n->buf_bytes = 0;
    if (mx_cuda_ok(cudaMalloc(&n->buf, bytes), "cuda conv2d (cuDNN) buffers", st)) {
        n->buf = NULL;
        return NULL;
    }
    n->buf_bytes = bytes;
    return n->buf;
}

static size_t round256(size_t b) { return (b + 255) & ~(size_t)255; }

static int cudnn_failed(const mx_cuda_cudnn *n, cudnnStatus_t s, const char *call, mx_status *st) {
    return mx_fail(st, MX_EINTERNAL, "cuda conv2d (cuDNN): %s: %s", call, n->api.GetErrorString(s));
}

/* Runs p's plan on one item's buffers. */
static int execute(mx_cuda_cudnn *n, const cudnn_plan *p, void *x16, void *w16, void *y16, const void *bias, void *ws,
                   mx_status *st) {
    const cudnn_api *a = &n->api;
    int64_t uids[4] = {UID_X, UID_W, UID_Y, UID_BIAS};
    void *ptrs[4] = {x16, w16, y16, (void *)bias};
    int64_t count = p->fused_bias ? 4 : 3;
    cudnnBackendDescriptor_t vp = NULL;
    cudnnStatus_t s = a->CreateDescriptor(CUDNN_BACKEND_VARIANT_PACK_DESCRIPTOR, &vp);
    if (s != CUDNN_STATUS_SUCCESS) return cudnn_failed(n, s, "variant pack", st);
    if ((s = a->SetAttribute(vp, CUDNN_ATTR_VARIANT_PACK_UNIQUE_IDS, CUDNN_TYPE_INT64, count, uids)) ||
        (s = a->SetAttribute(vp, CUDNN_ATTR_VARIANT_PACK_DATA_POINTERS, CUDNN_TYPE_VOID_PTR, count, ptrs)) ||
        (s = a->SetAttribute(vp, CUDNN_ATTR_VARIANT_PACK_WORKSPACE, CUDNN_TYPE_VOID_PTR, 1, &ws)) ||
        (s = a->Finalize(vp)) || (s = a->Execute(n->handle, p->plan, vp))) {
        a->DestroyDescriptor(vp);
        return cudnn_failed(n, s, "cudnnBackendExecute", st);
    }
    a->DestroyDescriptor(vp);
    return 0;
}

int mx_cuda_cudnn_conv2d(mx_cuda_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                         mx_wptr bias, int Cout, int kh, int kw, int stride, int pad, int Ho, int Wo, mx_status *st) {
    mx_cuda_cudnn *n = c->cudnn;
    if (!n || w.dtype != MX_F16 || Cout > 65535) return 1;
    mx_cudnn_conv_key key = n->base;
    key.n = 1, key.cin = Cin, key.h = H, key.w = W, key.cout = Cout, key.kh = kh, key.kw = kw, key.stride = stride;
    key.pad = pad, key.wdtype = (int)w.dtype, key.bdtype = bias.data ? (int)bias.dtype : -1;
    key.align_x = key.align_w = key.align_y = 16; /* the call buffer's pieces are 256-byte aligned */
    key.align_b = bias.data ? mx_cudnn_align((uintptr_t)bias.data) : 16;
    cudnn_plan *p = plan_for(n, &key, !c->capturing);
    if (!p && c->capturing) return mx_cuda_not_capturing(c, "cuda conv2d (cuDNN): a plan for a new shape", st);
    if (!p || !p->ok) return 1;

    size_t xb = round256((size_t)Cin * H * W * 2), wb = round256((size_t)Cout * Cin * kh * kw * 2);
    size_t yb = round256((size_t)Cout * Ho * Wo * 2);
    if (xb + wb + yb + (size_t)p->workspace > n->buf_bytes &&
        mx_cuda_not_capturing(c, "cuda conv2d (cuDNN): growing its buffer", st))
        return -1;
    unsigned char *buf = (unsigned char *)call_buffer(n, xb + wb + yb + (size_t)p->workspace, st);
    if (!buf) return -1;
    __half *x16 = (__half *)buf, *w16 = (__half *)(buf + xb), *y16 = (__half *)(buf + xb + wb);
    void *ws = p->workspace ? buf + xb + wb + yb : NULL;
    mx_wptr none = {NULL, MX_F32};
    /* The filter per call (~0.02 ms for SD's largest): a copy kept per weight would go stale when
     * a weight buffer is freed and its address reused. */
    if (transpose<__half, __half>(c, w16, (const __half *)w.data, (unsigned)Cin, (unsigned)(kh * kw), (unsigned)Cout,
                                  none, "cuda conv2d (cuDNN) filter to KRSC", st))
        return -1;
    long long in_plane = (long long)Cin * H * W, out_plane = (long long)Cout * Ho * Wo;
    for (int b = 0; b < B; b++) {
        if (transpose<float, __half>(c, x16, x + b * in_plane, (unsigned)Cin, (unsigned)(H * W), 1, none,
                                     "cuda conv2d (cuDNN) x to NHWC", st) ||
            execute(n, p, x16, w16, y16, bias.data, ws, st) ||
            transpose<__half, float>(c, y + b * out_plane, y16, (unsigned)(Ho * Wo), (unsigned)Cout, 1,
                                     p->fused_bias ? none : bias, "cuda conv2d (cuDNN) y to NCHW", st))
            return -1;
    }
    c->half_products++;
    c->cudnn_convs++;
    return 0;
}

#else /* built without cuDNN's headers: the decision only */

void mx_cuda_cudnn_open(mx_cuda_ctx *c) {
    const char *env = getenv("MATEX_CUDNN");
    char why[320];
    c->cudnn = NULL;
    if (!mx_cudnn_decide(env, 0, 0, NULL, why, sizeof why) && env && strcmp(env, "1") == 0) mx_warn("cuda: %s", why);
}

void mx_cuda_cudnn_close(mx_cuda_ctx *c) { (void)c; }

int mx_cuda_cudnn_conv2d(mx_cuda_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                         mx_wptr bias, int Cout, int kh, int kw, int stride, int pad, int Ho, int Wo, mx_status *st) {
    (void)c, (void)y, (void)x, (void)B, (void)Cin, (void)H, (void)W, (void)w, (void)bias, (void)Cout, (void)kh;
    (void)kw, (void)stride, (void)pad, (void)Ho, (void)Wo, (void)st;
    return 1;
}

#endif
