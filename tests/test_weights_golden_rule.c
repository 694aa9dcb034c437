/* golden-v1 rule: the README's worked example, then the checksums of
 * golden/sd15_{clip,vae,unet,controlnet}/weights_checksums.json (streamed per tensor
 * in chunks). This program checks every CLIP and VAE tensor, every 1-D tensor and a
 * deterministic sample of the large UNet/ControlNet tensors; test_weights_golden_rule_full (the
 * same source with GOLDEN_FULL) checks every tensor when MATEX_FULL=1. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../runtime/json.h"
#include "../runtime/fileio.h"
#include "../weights/golden_rule.h"
#include "util_test.h"

#ifndef GOLDEN_FULL
#define GOLDEN_FULL 0
#endif

enum { CHUNK = 1 << 20 };

static void test_worked_example(void) {
    int64_t shape[4] = {320, 4, 3, 3};
    float v[320 * 4 * 9];
    mx_golden_v1_fill("conv_in.weight", 4, shape, 1, v);
    const uint32_t want[4] = {0xbba6ead5u, 0x3d2c5440u, 0x3b833455u, 0xbd336615u};
    for (int i = 0; i < 4; i++) {
        uint32_t bits;
        memcpy(&bits, &v[i], 4);
        if (bits != want[i]) {
            fprintf(stderr, "conv_in.weight[%d] = 0x%08x, want 0x%08x\n", i, bits, want[i]);
            mx_test_failures++;
        }
    }
    /* a range equals the same slice of the whole tensor */
    float part[100];
    mx_golden_v1_fill_range("conv_in.weight", 4, shape, 1, 5000, 100, part);
    CHECK(!memcmp(part, v + 5000, sizeof part));
    /* 1-D cases: "weight" near 1, others near 0 */
    int64_t s1[1] = {64};
    float w[64], b[64];
    mx_golden_v1_fill("norm.weight", 1, s1, 1, w);
    mx_golden_v1_fill("norm.bias", 1, s1, 1, b);
    for (int i = 0; i < 64; i++) CHECK(fabsf(w[i] - 1) <= 0.1f && fabsf(b[i]) <= 0.05f);
}


static uint64_t hex_of(const mx_json *arr, size_t i) {
    const char *s = mx_json_str(mx_json_at(arr, i));
    return s ? strtoull(s, NULL, 16) : 0xFFFFFFFFFFFFFFFFull;
}

/* u32_wsum is up to 2^64: exact only when read from the digits, not through a double.
 * Finds `"<tensor>": {` in the text and then `"<field>": <digits>` inside that entry. */
static int exact_u64_of(const char *text, size_t len, const char *tensor, const char *field, uint64_t *out) {
    char pat[600];
    snprintf(pat, sizeof pat, "\"%s\": {", tensor);
    const char *p = memmem(text, len, pat, strlen(pat));
    if (!p) return -1;
    const char *end = memchr(p, '}', len - (size_t)(p - text));
    snprintf(pat, sizeof pat, "\"%s\": ", field);
    const char *q = end ? memmem(p, (size_t)(end - p), pat, strlen(pat)) : NULL;
    if (!q) return -1;
    *out = strtoull(q + strlen(pat), NULL, 10);
    return 0;
}

typedef struct {
    const char *text;
    size_t len;
} source;

static int check_tensor(const source *src, const char *name, const mx_json *e, uint64_t seed, float *buf) {
    const mx_json *js = mx_json_get(e, "shape");
    int ndim = (int)mx_json_len(js);
    int64_t shape[8];
    uint64_t n = 1;
    if (ndim > 8) return -1;
    for (int d = 0; d < ndim; d++) n *= (uint64_t)(shape[d] = (int64_t)mx_json_num(mx_json_at(js, (size_t)d)));
    mx_golden_checksum c;
    mx_golden_checksum_init(&c);
    for (uint64_t k = 0; k < n; k += CHUNK) {
        size_t m = n - k < CHUNK ? (size_t)(n - k) : CHUNK;
        mx_golden_v1_fill_range(name, ndim, shape, seed, k, m, buf);
        mx_golden_checksum_add(&c, buf, m);
    }
    int bad = 0;
    uint64_t u32_sum, u32_wsum, f16_sum;
    if (exact_u64_of(src->text, src->len, name, "u32_sum", &u32_sum) ||
        exact_u64_of(src->text, src->len, name, "u32_wsum", &u32_wsum) ||
        exact_u64_of(src->text, src->len, name, "f16_u16_sum", &f16_sum)) {
        fprintf(stderr, "%s: checksum fields not found\n", name);
        return -1;
    }
    bad |= c.u32_sum != u32_sum || c.u32_wsum != u32_wsum || c.f16_u16_sum != f16_sum;
    const mx_json *f4 = mx_json_get(e, "first4_hex"), *h4 = mx_json_get(e, "f16_first4_hex");
    for (size_t i = 0; i < 4 && i < n; i++) bad |= c.first4[i] != hex_of(f4, i) || c.f16_first4[i] != hex_of(h4, i);
    double sum = mx_golden_checksum_sum(&c), sumsq = mx_golden_checksum_sumsq(&c);
    double want_sum = mx_json_get_num(e, "sum", NAN), want_sumsq = mx_json_get_num(e, "sumsq", NAN);
    /* the reference's pairwise sums are within ~n_log * 1e-16 of exact; allow 1e-12 of the scale */
    bad |= !(fabs(sum - want_sum) <= 1e-12 * (c.sum_abs + fabs(want_sum)));
    bad |= !(fabs(sumsq - want_sumsq) <= 1e-12 * fabs(want_sumsq));
    if (bad)
        fprintf(stderr, "%s: checksums differ (u32_wsum %llu vs %llu, sum %.17g vs %.17g)\n", name,
                (unsigned long long)c.u32_wsum, (unsigned long long)u32_wsum, sum, want_sum);
    return bad ? -1 : 0;
}

/* In the sampled mode: every tensor of small networks, every 1-D tensor, and every 16th
 * tensor (by position in the file) of the big ones. */
static int selected(int full, int small_net, size_t index, const mx_json *e) {
    return full || small_net || mx_json_len(mx_json_get(e, "shape")) == 1 || index % 16 == 0;
}

static void check_network(const char *folder, int small_net, int full, float *buf) {
    char path[1024];
    if (!mx_test_need(path, sizeof path, "golden/%s/weights_checksums.json", folder)) return;
    source src;
    char *text = mx_read_file(path, (size_t)1 << 30, &src.len, NULL);
    src.text = text;
    mx_status st;
    mx_json *root = text ? mx_json_parse(text, src.len, path, &st) : NULL;
    if (!root) {
        fprintf(stderr, "%s: %s\n", path, text ? st.msg : "cannot read");
        mx_test_failures++;
        free(text);
        return;
    }
    uint64_t seed = (uint64_t)mx_json_get_num(root, "seed", -1);
    const mx_json *tensors = mx_json_get(root, "tensors");
    size_t checked = 0, failed = 0;
    uint64_t elements = 0;
    for (size_t i = 0; i < mx_json_len(tensors); i++) {
        const mx_json *e = mx_json_at(tensors, i);
        if (!selected(full, small_net, i, e)) continue;
        checked++;
        if (check_tensor(&src, mx_json_key(tensors, i), e, seed, buf)) failed++;
        const mx_json *js = mx_json_get(e, "shape");
        uint64_t n = 1;
        for (size_t d = 0; d < mx_json_len(js); d++) n *= (uint64_t)mx_json_num(mx_json_at(js, d));
        elements += n;
    }
    printf("%-16s %zu of %zu tensors checked (%llu elements), %zu differ\n", folder, checked, mx_json_len(tensors),
           (unsigned long long)elements, failed);
    CHECK(checked > 0 && failed == 0);
    mx_json_free(root);
    free(text);
}

int main(void) {
    int full = GOLDEN_FULL;
    if (full && !(getenv("MATEX_FULL") && !strcmp(getenv("MATEX_FULL"), "1"))) {
        printf("test_weights_golden_rule_full: the complete check runs with MATEX_FULL=1 (make test-full)\n");
        return MX_TEST_SKIP;
    }
    float *buf = malloc(CHUNK * sizeof *buf);
    test_worked_example();
    check_network("sd15_clip", 1, full, buf);
    check_network("sd15_vae", 1, full, buf);
    check_network("sd15_unet", 0, full, buf);
    check_network("sd15_controlnet", 0, full, buf);
    free(buf);
    return mx_test_finish(full ? "test_weights_golden_rule_full" : "test_weights_golden_rule");
}
