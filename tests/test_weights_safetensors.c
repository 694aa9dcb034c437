/* safetensors: write/read round trip, reading the shared golden files (fp32 and fp16 agree),
 * and hostile files (truncations, bad header lengths, dtypes, shapes, offsets, duplicates,
 * flipped header bytes) failing with a message that names the file. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../weights/safetensors.h"
#include "corrupt_file.h"
#include "util_test.h"

static char tmpdir[256];

static void path_in_tmp(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", tmpdir, name); }

/* A safetensors file from a header text and a data area of `data_len` bytes (value i%251). */
static void make_file(const char *path, const char *header, size_t data_len) {
    size_t hl = strlen(header);
    unsigned char *buf = malloc(8 + hl + data_len + 1);
    for (int i = 0; i < 8; i++) buf[i] = (unsigned char)((uint64_t)hl >> (8 * i));
    memcpy(buf + 8, header, hl);
    for (size_t i = 0; i < data_len; i++) buf[8 + hl + i] = (unsigned char)(i % 251);
    write_bytes(path, buf, 8 + hl + data_len);
    free(buf);
}

static void expect_open_error(const char *path, const char *fragment) {
    mx_safetensors f;
    mx_status st;
    mx_status_clear(&st);
    int rc = mx_st_open(&f, path, &st);
    CHECK(rc == -1);
    if (rc == 0) {
        mx_st_close(&f);
        return;
    }
    CHECK(strstr(st.msg, path) != NULL);
    if (fragment && !strstr(st.msg, fragment)) {
        fprintf(stderr, "message '%s' lacks '%s'\n", st.msg, fragment);
        mx_test_failures++;
    }
}

static void test_roundtrip(void) {
    char path[512];
    path_in_tmp(path, sizeof path, "rt.safetensors");
    float a[6] = {1, -2, 3.5f, 0, 1e-8f, -7};
    int64_t ids[3] = {981, 37, -1};
    float s = 42;
    mx_st_out outs[3] = {
        {"x.weight", MX_ST_F32, 2, {2, 3}, a},
        {"timestep", MX_ST_I64, 1, {3}, ids},
        {"scalar \"q\"", MX_ST_F32, 0, {0}, &s},
    };
    mx_status st;
    CHECK(mx_st_write(path, outs, 3, &st) == 0);
    mx_safetensors f;
    CHECK(mx_st_open(&f, path, &st) == 0);
    CHECK(f.count == 3);
    const mx_st_tensor *t = mx_st_find(&f, "x.weight");
    CHECK(t && t->dtype == MX_ST_F32 && t->ndim == 2 && t->shape[0] == 2 && t->shape[1] == 3 && t->nbytes == 24);
    float *x = t ? mx_st_to_f32(&f, t, &st) : NULL;
    CHECK(x && !memcmp(x, a, sizeof a));
    free(x);
    t = mx_st_find(&f, "timestep");
    CHECK(t && t->dtype == MX_ST_I64 && !memcmp(t->data, ids, sizeof ids));
    x = t ? mx_st_to_f32(&f, t, &st) : NULL;
    CHECK(x && x[0] == 981 && x[1] == 37 && x[2] == -1);
    free(x);
    t = mx_st_find(&f, "scalar \"q\"");
    CHECK(t && t->ndim == 0 && t->nbytes == 4);
    CHECK(mx_st_find(&f, "nope") == NULL);
    CHECK(f.metadata_json == NULL);
    mx_st_close(&f);
    /* no temp file left behind */
    char tmpname[600];
    snprintf(tmpname, sizeof tmpname, "ls %s | grep -c tmp > /dev/null", tmpdir);
    CHECK(system(tmpname) != 0);
}

/* The golden fp32 and fp16 weights of clip_tiny hold the same values up to fp16 rounding. */
static void test_golden_files(void) {
    char p32[512], p16[512];
    mx_test_path(p32, sizeof p32, "golden/clip_tiny/model.safetensors");
    mx_test_path(p16, sizeof p16, "golden/clip_tiny/model.fp16.safetensors");
    mx_safetensors a, b;
    mx_status st;
    if (mx_st_open(&a, p32, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        mx_test_failures++;
        return;
    }
    CHECK(mx_st_open(&b, p16, &st) == 0);
    CHECK(a.count == b.count && a.count > 10);
    CHECK(a.metadata_json && strstr(a.metadata_json, "\"format\":\"pt\""));
    const mx_st_tensor *t = mx_st_find(&a, "text_model.embeddings.token_embedding.weight");
    CHECK(t && t->ndim == 2 && t->shape[0] == 1000 && t->shape[1] == 32);
    for (size_t i = 0; i < a.count && i < b.count; i++) {
        const mx_st_tensor *ta = &a.tensors[i], *tb = mx_st_find(&b, ta->name);
        CHECK(tb != NULL);
        if (!tb || ta->dtype != MX_ST_F32) continue;
        CHECK(tb->dtype == MX_ST_F16);
        float *xa = mx_st_to_f32(&a, ta, &st), *xb = mx_st_to_f32(&b, tb, &st);
        size_t n = ta->nbytes / 4;
        double worst = 0;
        for (size_t k = 0; k < n; k++) {
            double d = (double)xa[k] - xb[k], rel = d < 0 ? -d : d;
            double m = xa[k] < 0 ? -xa[k] : xa[k];
            if (m > 1e-4) rel /= m;
            if (rel > worst) worst = rel;
        }
        if (worst > 1.0 / 2048) {
            fprintf(stderr, "%s: fp16 differs from fp32 by %g\n", ta->name, worst);
            mx_test_failures++;
        }
        free(xa);
        free(xb);
    }
    mx_st_close(&a);
    mx_st_close(&b);
}

static void test_hostile_headers(void) {
    char path[512];
    path_in_tmp(path, sizeof path, "bad.safetensors");
    struct {
        const char *header;
        size_t data;
        const char *fragment;
    } cases[] = {
        {"[1,2]", 0, "not a JSON object"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}", 8, "invalid JSON"},
        {"{\"a\":{\"dtype\":\"Q4\",\"shape\":[2],\"data_offsets\":[0,8]}}", 8, "unsupported dtype 'Q4'"},
        {"{\"a\":{\"shape\":[2],\"data_offsets\":[0,8]}}", 8, "dtype"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[3],\"data_offsets\":[0,8]}}", 8, "does not match"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}", 4, "outside the data area"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[8,0]}}", 8, "outside"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[-2],\"data_offsets\":[0,8]}}", 8, "non-negative"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[2.5],\"data_offsets\":[0,8]}}", 8, "non-negative"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[1,1,1,1,1,1,1,1,2],\"data_offsets\":[0,8]}}", 8, "dimensions"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[4294967296,4294967296,4294967296],\"data_offsets\":[0,8]}}", 8,
         "does not match"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0]}}", 8, "data_offsets"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,1e300]}}", 8, "data_offsets"},
        {"{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]},"
         "\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}",
         8, "duplicate"},
        {"{\"a\":5}", 0, "not an object"},
        {"{\"__metadata__\":{\"k\":1}}", 0, "not a string"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        make_file(path, cases[i].header, cases[i].data);
        expect_open_error(path, cases[i].fragment);
    }
    /* header length beyond the file, short file, empty file, missing file, a directory */
    unsigned char big[16] = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f, '{', '}'};
    write_bytes(path, big, 10);
    expect_open_error(path, "exceeds the file size");
    write_bytes(path, big, 5);
    expect_open_error(path, "header length needs 8");
    write_bytes(path, big, 0);
    expect_open_error(path, NULL);
    path_in_tmp(path, sizeof path, "missing.safetensors");
    expect_open_error(path, "cannot open");
    expect_open_error(tmpdir, "regular file");
}

/* A truncated file: an error naming it. */
static int st_refused(const char *path) {
    mx_safetensors f;
    mx_status st;
    mx_status_clear(&st);
    if (mx_st_open(&f, path, &st) == 0) {
        mx_st_close(&f);
        return 0;
    }
    return strstr(st.msg, path) != NULL;
}

/* A corrupted file: an error naming it, or a file whose every tensor converts. */
static int st_refused_or_readable(const char *path) {
    mx_safetensors f;
    mx_status st;
    mx_status_clear(&st);
    if (mx_st_open(&f, path, &st)) return strstr(st.msg, path) != NULL;
    int ok = 1;
    for (size_t i = 0; i < f.count; i++) {
        float *x = mx_st_to_f32(&f, &f.tensors[i], &st);
        ok &= x != NULL;
        free(x);
    }
    mx_st_close(&f);
    return ok;
}

/* Every truncation and many single-byte corruptions of a valid file: an error or a valid
 * parse, never a crash (this test is run under ASan by `make asan`). */
static void test_truncation_and_flips(void) {
    char good[512], bad[512];
    path_in_tmp(good, sizeof good, "good.safetensors");
    path_in_tmp(bad, sizeof bad, "cut.safetensors");
    float a[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    int64_t id = 5;
    mx_st_out outs[2] = {{"w", MX_ST_F32, 2, {2, 4}, a}, {"id", MX_ST_I64, 1, {1}, &id}};
    mx_status st;
    CHECK(mx_st_write(good, outs, 2, &st) == 0);
    size_t n;
    unsigned char *buf = read_bytes(good, &n);
    CHECK(buf != NULL);
    if (!buf) return;
    CHECK(each_truncation(bad, buf, n, st_refused) == 0);
    static const unsigned char vals[3] = {0x00, 0xff, '9'};
    CHECK(each_byte_set(bad, buf, n, vals, 3, st_refused_or_readable) == 0);
    free(buf);
}

int main(void) {
    /* thousands of small files are written: memory-backed /dev/shm when there is one */
    snprintf(tmpdir, sizeof tmpdir, "%s/mx_test_st_XXXXXX", access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp");
    if (!mkdtemp(tmpdir)) return 1;
    test_roundtrip();
    test_golden_files();
    test_hostile_headers();
    test_truncation_and_flips();
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return mx_test_finish("test_weights_safetensors");
}
