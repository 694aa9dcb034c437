/* CUDA graphs (issue 39 item 4, docs/cuda-notes.md §11): work queued on a context's stream captured
 * once into a graph and replayed with one launch. The backend's recorded regions (ops/record.h,
 * cuda_backend.cu) and bench_cuda's launch count use it. While capturing, the context refuses what
 * a replay could not redo (mx_cuda_not_capturing: host copies, waits, new plans, grown buffers), and
 * the thread-local capture mode makes CUDA refuse allocations and frees. */
#include "cuda_common.cuh"

int mx_cuda_graph_capture(mx_cuda_ctx *c, int (*queue)(void *arg, mx_status *st), void *arg, cudaGraph_t *graph,
                          mx_status *st) {
    *graph = NULL;
    if (mx_cuda_ok(cudaStreamBeginCapture(c->stream, cudaStreamCaptureModeThreadLocal), "cuda graph: begin capture", st))
        return -1;
    c->capturing = 1;
    int rc = queue(arg, st);
    c->capturing = 0;
    c->scratch_used = 0; /* an op that failed inside may have left its scratch taken; none is running now */
    cudaGraph_t g = NULL;
    cudaError_t e = cudaStreamEndCapture(c->stream, &g); /* ends it even when an unsafe call invalidated it */
    if (rc == 0 && mx_cuda_ok(e, "cuda graph: the queued work cannot be captured", st)) rc = -1;
    if (rc) {
        if (g) cudaGraphDestroy(g);
        (void)cudaGetLastError(); /* a capture's error is not a later op's */
        return -1;
    }
    *graph = g;
    return 0;
}

int mx_cuda_graph_instantiate(cudaGraph_t graph, cudaGraphExec_t *exec, size_t *nodes, mx_status *st) {
    *exec = NULL;
    *nodes = 0;
    if (mx_cuda_ok(cudaGraphGetNodes(graph, NULL, nodes), "cuda graph: its nodes", st) ||
        mx_cuda_ok(cudaGraphInstantiate(exec, graph, 0), "cuda graph: instantiate", st)) {
        *exec = NULL;
        (void)cudaGetLastError();
        return -1;
    }
    return 0;
}

int mx_cuda_graph_launch(mx_cuda_ctx *c, cudaGraphExec_t exec, mx_status *st) {
    return mx_cuda_ok(cudaGraphLaunch(exec, c->stream), "cuda graph: launch", st);
}

void mx_cuda_graph_free(cudaGraphExec_t exec) {
    if (exec) cudaGraphExecDestroy(exec);
}
