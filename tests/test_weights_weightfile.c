/* Weight file: write/read round trip with dtype conversion (checked against an independent
 * rounding), alignment, metadata, mx_wf_require messages, and hostile files: every
 * truncation, flipped bytes in the header and tables, huge counts. Run under ASan by
 * `make asan`. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../weights/weights.h"
#include "../weights/wfinfo.h"
#include "corrupt_file.h"
#include "util_test.h"

static char tmpdir[256];

static void tmp_path(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", tmpdir, name); }

/* fp16 by an independent method: nearest representable value found by search over the
 * candidates around the value (ties to the even mantissa). */
static float fp16_round_reference(float x) {
    if (x == 0) return x;
    double a = fabs((double)x);
    int e;
    frexp(a, &e); /* a in [2^(e-1), 2^e) */
    int exp = e - 1 < -14 ? -14 : e - 1;
    double ulp = ldexp(1.0, exp - 10);
    double q = floor(a / ulp), lo = q * ulp, hi = lo + ulp, r;
    if (a - lo < hi - a) r = lo;
    else if (a - lo > hi - a) r = hi;
    else r = fmod(q, 2) == 0 ? lo : hi;
    if (r >= 65520.0) r = INFINITY;
    return (float)(x < 0 ? -r : r);
}

static float bf16_round_reference(float x) {
    double a = fabs((double)x);
    if (a == 0) return x;
    int e;
    frexp(a, &e);
    double ulp = ldexp(1.0, e - 1 - 7);
    double q = floor(a / ulp), lo = q * ulp, hi = lo + ulp, r;
    if (a - lo < hi - a) r = lo;
    else if (a - lo > hi - a) r = hi;
    else r = fmod(q, 2) == 0 ? lo : hi;
    return (float)(x < 0 ? -r : r);
}

static float half_bits_to_float(uint16_t h) {
    int exp = (h >> 10) & 31, man = h & 1023;
    double v = exp == 0 ? ldexp(man, -24) : exp == 31 ? INFINITY : ldexp(1024 + man, exp - 25);
    return (float)(h & 0x8000 ? -v : v);
}

static float bf16_bits_to_float(uint16_t h) {
    uint32_t u = (uint32_t)h << 16;
    float f;
    memcpy(&f, &u, 4);
    return f;
}

#define N_VALUES 4099

static void make_values(float *v) {
    mx_fill_random(v, N_VALUES, 7, -3, 3);
    v[0] = 0;
    v[1] = 65504;
    v[2] = 1e-7f;   /* fp16 subnormal */
    v[3] = -6e-8f;  /* near the smallest fp16 subnormal */
    v[4] = 1.0f + 1.0f / 2048; /* fp16 tie: rounds to even (1.0) */
    v[5] = 65519.f;
    v[6] = 1e-30f;
    v[7] = 3.0e-8f;
    for (int i = 8; i < 64; i++) v[i] *= powf(10.f, (float)(i % 9) - 5);
}

static void test_roundtrip(void) {
    char path[512];
    tmp_path(path, sizeof path, "rt.mxw");
    static float v[N_VALUES];
    make_values(v);
    int32_t ids[77];
    for (int i = 0; i < 77; i++) ids[i] = i;
    int64_t s_v[2] = {N_VALUES, 1}, s_id[1] = {77}, s_small[3] = {1, 1, 3}, s_empty[1] = {0};
    mx_status st;
    mx_wf_writer *w = mx_wf_writer_create(&st);
    CHECK(mx_wf_writer_add(w, "unet.b.f16", MX_F16, 2, s_v, v, MX_F32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "unet.a.f32", MX_F32, 2, s_v, v, MX_F32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "vae.c.bf16", MX_BF16, 2, s_v, v, MX_F32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "text_encoder.position_ids", MX_I32, 1, s_id, ids, MX_I32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "vae.small", MX_F32, 3, s_small, v, MX_F32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "vae.empty", MX_F32, 1, s_empty, v, MX_F32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "bad", MX_I32, 1, s_id, v, MX_F32, &st) == -1);
    CHECK(mx_wf_writer_meta(w, "unet.config", "{\"a\": 1}", &st) == 0);
    CHECK(mx_wf_writer_meta(w, "provenance", "caf\xC3\xA9", &st) == 0);
    CHECK(mx_wf_writer_finish(w, path, &st) == 0);
    mx_wf_writer_free(w);

    CHECK(mx_wf_is_weightfile(path) == 1);
    mx_weightfile *wf;
    if (mx_wf_open(&wf, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        mx_test_failures++;
        return;
    }
    CHECK(mx_wf_count(wf) == 6);
    for (size_t i = 0; i < mx_wf_count(wf); i++) CHECK(((uintptr_t)mx_wf_tensor(wf, i)->data & 63) == 0);
    CHECK(!strcmp(mx_wf_tensor(wf, 0)->name, "text_encoder.position_ids"));
    const mx_wtensor *t = mx_wf_find(wf, "unet.a.f32");
    CHECK(t && t->dtype == MX_F32 && t->nbytes == 4 * N_VALUES && !memcmp(t->data, v, sizeof v));
    t = mx_wf_find(wf, "unet.b.f16");
    CHECK(t && t->dtype == MX_F16 && t->nbytes == 2 * N_VALUES);
    int bad16 = 0, bad_bf = 0;
    for (int i = 0; t && i < N_VALUES; i++) {
        uint16_t h;
        memcpy(&h, (const uint8_t *)t->data + 2 * i, 2);
        float got = half_bits_to_float(h), want = fp16_round_reference(v[i]);
        if (got != want && bad16++ < 5) fprintf(stderr, "f16 of %.9g: got %.9g want %.9g\n", v[i], got, want);
    }
    t = mx_wf_find(wf, "vae.c.bf16");
    for (int i = 0; t && i < N_VALUES; i++) {
        uint16_t h;
        memcpy(&h, (const uint8_t *)t->data + 2 * i, 2);
        if (bf16_bits_to_float(h) != bf16_round_reference(v[i]) && bad_bf++ < 5) fprintf(stderr, "bf16 of %.9g\n", v[i]);
    }
    CHECK(bad16 == 0 && bad_bf == 0);
    t = mx_wf_find(wf, "text_encoder.position_ids");
    CHECK(t && t->dtype == MX_I32 && !memcmp(t->data, ids, sizeof ids));
    t = mx_wf_find(wf, "vae.empty");
    CHECK(t && t->nbytes == 0);
    CHECK(mx_wf_find(wf, "unet.zzz") == NULL);
    CHECK(!strcmp(mx_wf_meta(wf, "unet.config"), "{\"a\": 1}"));
    CHECK(!strcmp(mx_wf_meta(wf, "provenance"), "caf\xC3\xA9"));
    CHECK(mx_wf_meta(wf, "nope") == NULL);
    CHECK(mx_wf_meta_count(wf) == 2 && !strcmp(mx_wf_meta_key(wf, 0), "provenance"));

    int64_t want_ok[3] = {1, -1, 3}, want_bad[3] = {1, 2, 3};
    CHECK(mx_wf_require(wf, "vae.small", 3, want_ok, &st) != NULL);
    CHECK(mx_wf_require(wf, "vae.small", 3, want_bad, &st) == NULL);
    CHECK(strstr(st.msg, "vae.small") && strstr(st.msg, "[1, 1, 3]") && strstr(st.msg, "[1, 2, 3]"));
    CHECK(mx_wf_require(wf, "vae.missing", 3, want_ok, &st) == NULL && strstr(st.msg, "not found"));
    mx_wf_close(wf);

    FILE *devnull = fopen("/dev/null", "w");
    CHECK(mx_wf_print_info(path, devnull, &st) == 0);
    fclose(devnull);
}

static void test_writer_errors(void) {
    char path[512];
    tmp_path(path, sizeof path, "dup.mxw");
    float x = 1;
    int64_t s1[1] = {1};
    mx_status st;
    mx_wf_writer *w = mx_wf_writer_create(&st);
    CHECK(mx_wf_writer_add(w, "a", MX_F32, 1, s1, &x, MX_F32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "a", MX_F16, 1, s1, &x, MX_F32, &st) == 0);
    CHECK(mx_wf_writer_add(w, "b", MX_F32, 0, s1, &x, MX_F32, &st) == -1);
    CHECK(mx_wf_writer_finish(w, path, &st) == -1 && strstr(st.msg, "twice"));
    mx_wf_writer_free(w);
    CHECK(access(path, F_OK) != 0); /* no output on failure */
    char nodir[600];
    snprintf(nodir, sizeof nodir, "%s/no/such/dir.mxw", tmpdir);
    w = mx_wf_writer_create(&st);
    CHECK(mx_wf_writer_finish(w, nodir, &st) == -1 && strstr(st.msg, nodir));
    mx_wf_writer_free(w);
}

static volatile unsigned read_sink;

static int opens(const char *path, mx_status *st) {
    mx_weightfile *wf;
    if (mx_wf_open(&wf, path, st)) return 0;
    /* a file that opens must be fully usable */
    for (size_t i = 0; i < mx_wf_count(wf); i++) {
        const mx_wtensor *t = mx_wf_tensor(wf, i);
        unsigned sum = (unsigned)strlen(t->name);
        for (size_t k = 0; k < t->nbytes; k++) sum += ((const uint8_t *)t->data)[k];
        read_sink += sum; /* touches every byte so ASan sees any read outside the mapping */
    }
    for (size_t i = 0; i < mx_wf_meta_count(wf); i++) (void)strlen(mx_wf_meta(wf, mx_wf_meta_key(wf, i)));
    mx_wf_close(wf);
    return 1;
}

static int wf_refused(const char *path) {
    mx_status st;
    return !opens(path, &st) && strstr(st.msg, path) != NULL;
}

static int wf_refused_or_readable(const char *path) {
    mx_status st;
    return opens(path, &st) || strstr(st.msg, path) != NULL;
}

static void put64(unsigned char *p, uint64_t v) {
    for (int i = 0; i < 8; i++) p[i] = (unsigned char)(v >> (8 * i));
}

/* A small file with every dtype and two metadata keys: the subject of the corruption tests. */
static int write_small_file(const char *path) {
    float f[12] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
    int32_t ids[2] = {7, 9};
    int64_t s_a[2] = {4, 3}, s_b[1] = {5}, s_c[1] = {2};
    mx_status st;
    mx_wf_writer *w = mx_wf_writer_create(&st);
    int rc = mx_wf_writer_add(w, "unet.a", MX_F16, 2, s_a, f, MX_F32, &st) ||
             mx_wf_writer_add(w, "unet.b", MX_F32, 1, s_b, f, MX_F32, &st) ||
             mx_wf_writer_add(w, "vae.c", MX_I32, 1, s_c, ids, MX_I32, &st) ||
             mx_wf_writer_add(w, "vae.d", MX_BF16, 2, s_a, f, MX_F32, &st) ||
             mx_wf_writer_meta(w, "unet.config", "{}", &st) || mx_wf_writer_meta(w, "provenance", "test", &st) ||
             mx_wf_writer_finish(w, path, &st);
    mx_wf_writer_free(w);
    return rc;
}

static void test_hostile(void) {
    char good[512], bad[512];
    tmp_path(good, sizeof good, "small.mxw");
    tmp_path(bad, sizeof bad, "bad.mxw");
    CHECK(write_small_file(good) == 0);
    size_t n;
    unsigned char *buf = read_bytes(good, &n);
    CHECK(buf != NULL);
    if (!buf) return;
    mx_status st;
    /* every truncation fails with a message naming the file */
    CHECK(each_truncation(bad, buf, n, wf_refused) == 0);
    /* every byte set to several values: a clean error or a valid, fully readable file */
    static const unsigned char vals[4] = {0x00, 0xff, 0x80, 0x41};
    CHECK(each_byte_set(bad, buf, n, vals, 4, wf_refused_or_readable) == 0);
    /* huge counts and offsets */
    static const size_t fields[] = {24, 32, 40, 48, 56, 64, 72, 80};
    static const uint64_t hostile[] = {UINT64_MAX, UINT64_MAX / 80 + 1, (uint64_t)1 << 62, 0x7fffffffffffffffULL};
    for (size_t f = 0; f < sizeof fields / sizeof fields[0]; f++)
        for (size_t h = 0; h < sizeof hostile / sizeof hostile[0]; h++) {
            unsigned char saved[8];
            memcpy(saved, buf + fields[f], 8);
            put64(buf + fields[f], hostile[h]);
            write_bytes(bad, buf, n);
            CHECK(!opens(bad, &st) && strstr(st.msg, bad));
            memcpy(buf + fields[f], saved, 8);
        }
    /* not a weight file at all */
    write_bytes(bad, "{\"a\": 1}", 8);
    CHECK(!opens(bad, &st) && strstr(st.msg, bad));
    CHECK(mx_wf_is_weightfile(bad) == 0);
    free(buf);
}

int main(void) {
    /* thousands of small files are written: memory-backed /dev/shm when there is one */
    snprintf(tmpdir, sizeof tmpdir, "%s/mx_test_wf_XXXXXX", access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp");
    if (!mkdtemp(tmpdir)) return 1;
    test_roundtrip();
    test_writer_errors();
    test_hostile();
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return mx_test_finish("test_weights_weightfile");
}
