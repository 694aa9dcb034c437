/* The backends: names and what is compiled in; every CPU kernel table compiled in (each level,
 * whether or not this CPU runs it; test_cuda_ops checks CUDA's) has every op of ops/op_list.h wired
 * to a kernel of that op and of that level or one below it on its ladder (told by the kernel's
 * symbol, mx_<op>_ref or mx_<op>_<level>: this test is linked with -rdynamic), and a table that
 * lacks one is refused with the op's name; cpu-strict memory really is out of reach
 * outside the op layer (a direct read or write kills a child process with SIGSEGV) while ops and
 * the host copies work on it; a measuring context computes nothing; the small layout, vector and
 * embedding ops (pad, copy, fill, axpy, lincomb, clamp, affine, embed_tokens) on known values, on
 * the strict backend. */
#include <dlfcn.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../ops/ops.h"
#include "util_test.h"

static void test_names(void) {
    mx_backend_kind k;
    mx_status st = {0};
    CHECK(mx_backend_parse("cpu-strict", &k, &st) == 0 && k == MX_BACKEND_CPU_STRICT);
    CHECK(mx_backend_parse("gpu", &k, &st) != 0 && strstr(st.msg, "cpu, cpu-strict or cuda"));
    CHECK(strcmp(mx_backend_name(MX_BACKEND_CUDA), "cuda") == 0);
    CHECK(strstr(mx_backends_compiled(), "cpu-strict") != NULL);
    if (!mx_backend_compiled(MX_BACKEND_CUDA)) {
        mx_ctx c;
        CHECK(mx_ctx_create_on(&c, MX_BACKEND_CUDA, 1, MX_ISA_SCALAR, 1 << 16, &st) != 0);
        CHECK(strstr(st.msg, "without the cuda backend") != NULL);
    }
}

/* The symbol of the function at fn ("" when dladdr cannot name it). */
static const char *kernel_symbol(void (*fn)(void)) {
    void *p;
    memcpy(&p, &fn, sizeof p); /* a function's address as an object pointer, for dladdr */
    Dl_info info;
    return dladdr(p, &info) && info.dli_sname ? info.dli_sname : "";
}

/* Whether sym names a kernel of op `op` that a table of level isa may hold: the scalar reference
 * mx_<op>_ref, or mx_<op>_<level> of a level compiled in at or below isa on isa's ladder. */
static int kernel_fits(const char *sym, const char *op, mx_isa isa) {
    size_t n = strlen(op);
    if (strncmp(sym, "mx_", 3) != 0 || strncmp(sym + 3, op, n) != 0 || sym[3 + n] != '_') return 0;
    const char *level = sym + 3 + n + 1;
    if (strcmp(level, "ref") == 0) return 1;
    for (mx_isa l = MX_ISA_SCALAR + 1; l < MX_ISA_COUNT; l++)
        if (strcmp(level, mx_isa_name(l)) == 0) return mx_kernels_compiled(l) && mx_isa_min(l, isa) == l;
    return 0;
}

/* One table: every op of the list present and wired to a kernel of its own op at a level the
 * table may use (a failure names the table, the op and the kernel it holds). */
static void check_table_full(const mx_kernels *k, const char *table) {
    int present = 0, wired = 0;
#define CHECK_ENTRY_(name, guard, params, args, cost)                                                       \
    if (k->name) {                                                                                           \
        present++;                                                                                           \
        const char *sym_ = kernel_symbol((void (*)(void))k->name);                                           \
        if (kernel_fits(sym_, #name, k->isa)) wired++;                                                       \
        else printf("FAIL: table %s: op %s is wired to %s\n", table, #name, sym_[0] ? sym_ : "an unnamed function"); \
    }
    MX_OPS(CHECK_ENTRY_)
#undef CHECK_ENTRY_
    const char *missing = mx_kernels_missing(k);
    if (missing) printf("FAIL: table %s has no kernel for op %s\n", table, missing);
    CHECK(missing == NULL && present == MX_OP_COUNT && wired == MX_OP_COUNT);
}

static void test_tables_full(void) {
    int tables = 0;
    for (mx_isa isa = MX_ISA_SCALAR; strcmp(mx_isa_name(isa), "?") != 0; isa++) { /* every named level */
        const mx_kernels *k = mx_kernels_compiled(isa);
        if (!k) continue; /* a level of another architecture */
        CHECK(k->isa == isa);
        check_table_full(k, mx_isa_name(isa));
        tables++;
    }
#ifndef MX_NO_X86_SIMD
    CHECK(tables == MX_ISA_AMX + 1);
#endif
    printf("kernel tables full and wired: %d tables x %d ops\n", tables, MX_OP_COUNT);
    /* a table with a hole: refused with the op's name, never called */
    mx_kernels holed = *mx_kernels_scalar();
    holed.embed_tokens = NULL;
    mx_status st = {0};
    CHECK(mx_kernels_missing(&holed) != NULL && strcmp(mx_kernels_missing(&holed), "embed_tokens") == 0);
    CHECK(mx_kernels_check(&holed, "test", &st) != 0);
    CHECK(strcmp(st.msg, "op embed_tokens is not available on backend test") == 0);
    CHECK(mx_kernels_check(mx_kernels_scalar(), "test", &st) == 0);
}

/* Runs fn(p) in a child; returns the signal that ended it (0: it exited). */
static int child_signal(void (*fn)(volatile float *), volatile float *p) {
    fflush(stdout);
    fflush(stderr);
    pid_t pid = fork();
    if (pid == 0) {
        signal(SIGSEGV, SIG_DFL); /* no sanitizer report: just die */
        fn(p);
        _exit(0);
    }
    int status = 0;
    if (pid < 0 || waitpid(pid, &status, 0) != pid) return -1;
    return WIFSIGNALED(status) ? WTERMSIG(status) : 0;
}

static void read_one(volatile float *p) {
    float v = p[3];
    (void)v;
}
static void write_one(volatile float *p) { p[3] = 1.0f; }

static void test_strict_guard(void) {
    mx_ctx c;
    mx_status st = {0};
    CHECK(mx_ctx_create_on(&c, MX_BACKEND_CPU_STRICT, 2, mx_cpu_best_isa(), 1 << 20, &st) == 0);
    float host[100], back[100], want[100];
    for (int i = 0; i < 100; i++) host[i] = (float)i, want[i] = 2.0f * (float)i;
    float *d = mx_dev_from_host(&c, host, 100, &st);
    CHECK(d != NULL);
    if (!d) return;
    mx_scale(&c, d, d, 2.0f, 100);
    CHECK(mx_download(&c, back, d, 100, &st) == 0);
    mx_check_close("cpu-strict: scale through the op layer", back, want, 100, 0);
    CHECK(child_signal(read_one, d) == SIGSEGV);
    CHECK(child_signal(write_one, d) == SIGSEGV);
    /* an arena on the backend is guarded too */
    mx_arena a;
    CHECK(mx_arena_create_on(&a, c.be, 4096, &st) == 0);
    float *x = mx_act_alloc(&a, 16, &st);
    CHECK(x != NULL && child_signal(read_one, x) == SIGSEGV);
    mx_arena_destroy(&a);
    /* host memory is still fine for the host (the guard is only on backend memory) */
    CHECK(child_signal(write_one, host) == 0);
    mx_dev_free(&c, d);
    mx_ctx_destroy(&c);
}

/* cpu-strict is a device context: a weight must be a device copy (mx_dev_weight, what
 * mx_binder_device binds); a host pointer is refused, the op does not run, and the next download
 * fails with a message naming the op, the argument and its shape. The weight copy itself is
 * read-only for the host. */
static void test_strict_weights(void) {
    mx_ctx c;
    mx_status st = {0};
    CHECK(mx_ctx_create_on(&c, MX_BACKEND_CPU_STRICT, 2, mx_cpu_best_isa(), 1 << 20, &st) == 0);
    const float x[3] = {1, 2, 3}, w[6] = {1, 0, 0, 0, 1, 1}, want[2] = {1, 5};
    float got[2] = {0, 0};
    float *dx = mx_dev_from_host(&c, x, 3, &st), *dy = mx_dev_alloc(&c, 2, &st);
    void *dw = mx_dev_weight(&c, w, sizeof w, &st);
    CHECK(dx && dy && dw);
    if (!dx || !dy || !dw) return;
    mx_linear(&c, dy, dx, mx_w_f32(dw), mx_w_none(), 1, 2, 3);
    CHECK(mx_download(&c, got, dy, 2, &st) == 0);
    mx_check_close("cpu-strict: linear with a device weight", got, want, 2, 0);
    CHECK(child_signal(read_one, dw) == 0 && child_signal(write_one, dw) == SIGSEGV);
    mx_fill(&c, dy, 7.0f, 2);
    mx_linear(&c, dy, dx, mx_w_f32(w), mx_w_none(), 1, 2, 3); /* a host weight: refused */
    CHECK(mx_download(&c, got, dy, 2, &st) != 0);
    printf("refused: %s\n", st.msg);
    CHECK(strstr(st.msg, "op linear: weight w [2, 3] (f32)") && strstr(st.msg, "not device memory") &&
          strstr(st.msg, "mx_binder_device"));
    /* sticky, like a CUDA fault: later downloads fail too */
    CHECK(mx_download(&c, got, dx, 2, &st) != 0 && strstr(st.msg, "op linear"));
    mx_dev_free(&c, dw);
    mx_dev_free(&c, dx);
    mx_dev_free(&c, dy);
    mx_ctx_destroy(&c);
}

/* A whole weight file on a device context (mx_dev_weight_file, as CUDA does it; cpu-strict streams
 * it too): the file's bytes land in one read-only copy that the observer saw in order; a weight
 * inside the mapping is its place in that copy (same bytes, usable by an op), one outside is its
 * own copy; freeing a place does nothing; a second call for the same file does nothing; a file
 * that is not the length said fails naming it. The CPU backend streams nothing. */
static void seen_sum(void *arg, const void *buf, size_t n, uint64_t off) {
    uint64_t *sum = arg; /* position-weighted, so order and offsets count */
    for (size_t i = 0; i < n; i++) *sum += ((const unsigned char *)buf)[i] * (off + i + 1);
}

static void test_weight_file(void) {
    enum { N = (3 << 20) / 4 + 5 }; /* 3 MiB + 20 bytes: several chunks, the last one short */
    float *data = malloc(N * sizeof *data);
    char dir[] = "/tmp/matex_test_wfile.XXXXXX", path[64];
    CHECK(data && mkdtemp(dir) != NULL);
    if (!data) return;
    snprintf(path, sizeof path, "%s/w.bin", dir);
    uint64_t want_sum = 0, sum = 0;
    for (int i = 0; i < N; i++) data[i] = (float)(i % 1000) * 0.25f;
    for (size_t i = 0; i < N * sizeof *data; i++) want_sum += ((unsigned char *)data)[i] * (i + 1);
    FILE *f = fopen(path, "wb");
    CHECK(f && fwrite(data, sizeof *data, N, f) == N);
    if (f) fclose(f);
    int fd = open(path, O_RDONLY);
    mx_ctx c, cpu;
    mx_status st = {0};
    CHECK(mx_ctx_create_on(&c, MX_BACKEND_CPU_STRICT, 2, mx_cpu_best_isa(), 1 << 20, &st) == 0);
    CHECK(mx_ctx_create_on(&cpu, MX_BACKEND_CPU, 1, mx_cpu_best_isa(), 1 << 20, &st) == 0);
    mx_stream_observer obs = {seen_sum, &sum};
    /* data stands in for the file's mapping: weights are found by their place in it */
    CHECK(mx_dev_weight_file(&cpu, fd, data, N * sizeof *data, path, &obs, &st) == 0 && sum == 0);
    CHECK(mx_dev_weight_file(&c, fd, data, N * sizeof *data, path, &obs, &st) == 1 && sum == want_sum);
    CHECK(mx_dev_weight_file(&c, fd, data, N * sizeof *data, path, NULL, &st) == 0);
    const float x[3] = {1, 2, 3}, w_out[6] = {4, 0, 0, 0, 1, 1};
    float got[2] = {0, 0}, want[2];
    float *w_in = mx_dev_weight(&c, data + 1000, 6 * sizeof(float), &st); /* data[1000..1005] = 0, .25, ... */
    float *w_own = mx_dev_weight(&c, w_out, sizeof w_out, &st);
    float *w_tail = mx_dev_weight(&c, data + N - 6, 6 * sizeof(float), &st);
    float *dx = mx_dev_from_host(&c, x, 3, &st), *dy = mx_dev_alloc(&c, 2, &st);
    CHECK(w_in && w_own && w_tail && dx && dy && w_in != data + 1000 && w_own != w_out);
    if (w_in && w_own && w_tail && dx && dy) {
        CHECK(memcmp(w_in, data + 1000, 6 * sizeof(float)) == 0 && memcmp(w_tail, data + N - 6, 6 * sizeof(float)) == 0);
        CHECK(child_signal(write_one, w_in) == SIGSEGV);
        mx_dev_free(&c, w_in); /* a place in the file's copy: nothing is freed */
        mx_linear(&c, dy, dx, mx_w_f32(w_in), mx_w_none(), 1, 2, 3);
        want[0] = data[1000] * 1 + data[1001] * 2 + data[1002] * 3;
        want[1] = data[1003] * 1 + data[1004] * 2 + data[1005] * 3;
        CHECK(mx_download(&c, got, dy, 2, &st) == 0);
        mx_check_close("cpu-strict: linear on a weight inside the file's copy", got, want, 2, 0);
    }
    mx_dev_free(&c, w_own);
    mx_dev_free(&c, dx);
    mx_dev_free(&c, dy);
    mx_dev_weight_file_drop(&c, data);
    float other[4];
    CHECK(mx_dev_weight_file(&c, fd, other, N * sizeof *data - 4, path, NULL, &st) == -1 &&
          strstr(st.msg, path) && strstr(st.msg, "expected"));
    close(fd);
    unlink(path);
    rmdir(dir);
    mx_ctx_destroy(&cpu);
    mx_ctx_destroy(&c);
    free(data);
}

static void test_measuring(void) {
    const mx_ctx *m = mx_ctx_measuring();
    mx_arena a;
    mx_arena_measure(&a);
    float *p = mx_act_alloc(&a, 1000, NULL), *q = mx_act_alloc(&a, 10, NULL);
    CHECK(p && q && a.peak >= 1010 * sizeof(float));
    mx_copy(m, NULL, NULL, 1000); /* returns at once: would crash otherwise */
    mx_conv2d(m, NULL, NULL, 1, 3, 8, 8, mx_w_none(), mx_w_none(), 4, 3, 3, 1, 1);
    CHECK(mx_run_ctx(NULL, &a) == m);
}

static void test_small_ops(const mx_ctx *c) {
    mx_status st = {0};
    /* pad a 2x3 plane by (top 1, bottom 0, left 0, right 2) */
    const float x[6] = {1, 2, 3, 4, 5, 6};
    const float pad_want[15] = {0, 0, 0, 0, 0, 1, 2, 3, 0, 0, 4, 5, 6, 0, 0};
    float got[16];
    float *dx = mx_dev_from_host(c, x, 6, &st), *dy = mx_dev_alloc(c, 16, &st);
    CHECK(dx && dy);
    if (!dx || !dy) return;
    mx_pad2d(c, dy, dx, 1, 2, 3, 1, 0, 0, 2);
    CHECK(mx_download(c, got, dy, 15, &st) == 0);
    mx_check_close("pad2d (1, 0, 0, 2)", got, pad_want, 15, 0);
    /* fill, copy, axpy, lincomb, clamp, affine */
    mx_fill(c, dy, 0.5f, 6);
    mx_axpy(c, dy, dx, 2.0f, 6); /* 0.5 + 2x */
    const float axpy_want[6] = {2.5f, 4.5f, 6.5f, 8.5f, 10.5f, 12.5f};
    CHECK(mx_download(c, got, dy, 6, &st) == 0);
    mx_check_close("fill + axpy", got, axpy_want, 6, 0);
    const float coef[3] = {1.0f, -2.0f, 0.5f};
    const float *const terms[3] = {dy, dx, dx};
    mx_lincomb(c, dy, 3, coef, terms, 6); /* 0.5 + 2x - 2x + 0.5x */
    const float lc_want[6] = {1.0f, 1.5f, 2.0f, 2.5f, 3.0f, 3.5f};
    CHECK(mx_download(c, got, dy, 6, &st) == 0);
    mx_check_close("lincomb of 3", got, lc_want, 6, 0);
    mx_clamp(c, dy, dy, 1.5f, 3.0f, 6);
    mx_affine(c, dy, dy, 2.0f, -1.0f, 6);
    const float ca_want[6] = {2.0f, 2.0f, 3.0f, 4.0f, 5.0f, 5.0f};
    CHECK(mx_download(c, got, dy, 6, &st) == 0);
    mx_check_close("clamp + affine", got, ca_want, 6, 0);
    mx_copy(c, dy + 1, dx, 3);
    const float cp_want[4] = {2.0f, 1.0f, 2.0f, 3.0f};
    CHECK(mx_download(c, got, dy, 4, &st) == 0);
    mx_check_close("copy at an offset", got, cp_want, 4, 0);
    /* token + position embedding: vocabulary of 3, C = 2, T = 2 */
    const float tok[6] = {0, 1, 10, 11, 20, 21}, pos[4] = {100, 200, 300, 400};
    const int32_t ids[4] = {2, 0, 1, 1};
    const float emb_want[8] = {120, 221, 300, 401, 110, 211, 310, 411};
    void *dtok = mx_dev_weight(c, tok, sizeof tok, &st), *dpos = mx_dev_weight(c, pos, sizeof pos, &st);
    CHECK(dtok && dpos);
    mx_embed_tokens(c, dy, ids, 2, 2, 2, mx_w_f32(dtok), mx_w_f32(dpos));
    CHECK(mx_download(c, got, dy, 8, &st) == 0);
    mx_check_close("embed_tokens", got, emb_want, 8, 0);
    const int32_t no_token[4] = {1, -1, -1, 0}; /* a negative id: the position row alone */
    const float pos_want[8] = {110, 211, 300, 400, 100, 200, 300, 401};
    mx_embed_tokens(c, dy, no_token, 2, 2, 2, mx_w_f32(dtok), mx_w_f32(dpos));
    CHECK(mx_download(c, got, dy, 8, &st) == 0);
    mx_check_close("embed_tokens, negative ids", got, pos_want, 8, 0);
    mx_dev_free(c, dtok);
    mx_dev_free(c, dpos);
    mx_dev_free(c, dx);
    mx_dev_free(c, dy);
}

/* The cpu backend's kept host blocks (ops/backend.c): a released block of 8 MiB or more serves
 * the next request of n to 1.25 n bytes as it is (contents included), and is usable to its end;
 * the backend's end frees what it kept (the leak checker of make asan sees any left). */
static void test_kept_blocks(void) {
    mx_ctx c;
    mx_status st = {0};
    CHECK(mx_ctx_create(&c, 1, mx_cpu_best_isa(), 1 << 20, &st) == 0);
    size_t mb = (size_t)1 << 20 >> 2; /* floats in 1 MiB */
    float *a = mx_dev_alloc(&c, 16 * mb, &st);
    CHECK(a != NULL);
    if (!a) return;
    a[0] = 12345.0f;
    a[16 * mb - 1] = 1.0f;
    mx_dev_free(&c, a);
    float *b = mx_dev_alloc(&c, 14 * mb, &st); /* 16 MiB ≤ 1.25 × 14 MiB: the kept one */
    CHECK(b == a && b[0] == 12345.0f);
    float *d = mx_dev_alloc(&c, 14 * mb, &st); /* the kept one is in use: a block of its own */
    CHECK(d != NULL);
    if (d) d[14 * mb - 1] = 2.0f;
    mx_dev_free(&c, b);
    mx_dev_free(&c, d);
    mx_ctx_destroy(&c);
}

int main(void) {
    test_names();
    test_kept_blocks();
    test_tables_full();
    test_strict_guard();
    test_strict_weights();
    test_weight_file();
    test_measuring();
    mx_ctx c;
    mx_status st = {0};
    if (mx_ctx_create_on(&c, MX_BACKEND_CPU_STRICT, 2, mx_cpu_best_isa(), 1 << 20, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return 1;
    }
    test_small_ops(&c);
    mx_ctx_destroy(&c);
    return mx_test_finish("test_ops_backend");
}
