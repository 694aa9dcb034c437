/* JSON reader: values, escapes (incl. surrogate pairs), numbers, errors with byte offsets,
 * depth limit, and every truncation of a document failing cleanly. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../runtime/buf.h"
#include "../runtime/json.h"
#include "util_test.h"

static mx_json *parse(const char *s, mx_status *st) { return mx_json_parse(s, strlen(s), "test.json", st); }

static void expect_error(const char *text, const char *fragment) {
    mx_status st;
    mx_status_clear(&st);
    mx_json *j = parse(text, &st);
    CHECK(j == NULL);
    CHECK(st.code == MX_EINPUT);
    CHECK(strstr(st.msg, "test.json") != NULL);
    if (fragment && !strstr(st.msg, fragment)) {
        fprintf(stderr, "error for %s: '%s' lacks '%s'\n", text, st.msg, fragment);
        mx_test_failures++;
    }
    mx_json_free(j);
}

static void test_values(void) {
    mx_status st;
    const char *doc = " {\"a\": 1.5e2, \"b\": [true, false, null, -0.25, 0, 12345678901234],"
                      " \"s\": \"x\\\"\\\\\\/\\b\\f\\n\\r\\t\", \"o\": {}, \"e\": [], \"n\": -3E-2} ";
    mx_json *j = parse(doc, &st);
    CHECK(j != NULL);
    if (!j) return;
    CHECK(mx_json_kind(j) == MX_JSON_OBJ);
    CHECK(mx_json_len(j) == 6);
    CHECK(mx_json_get_num(j, "a", 0) == 150.0);
    CHECK(mx_json_get_num(j, "n", 0) == -0.03);
    CHECK(mx_json_get_num(j, "missing", 7) == 7);
    CHECK(mx_json_get_num(j, "s", 7) == 7); /* wrong type gives the default */
    const mx_json *b = mx_json_get(j, "b");
    CHECK(mx_json_kind(b) == MX_JSON_ARR && mx_json_len(b) == 6);
    CHECK(mx_json_bool(mx_json_at(b, 0)) == 1 && mx_json_bool(mx_json_at(b, 1)) == 0);
    CHECK(mx_json_kind(mx_json_at(b, 2)) == MX_JSON_NULL);
    CHECK(mx_json_num(mx_json_at(b, 3)) == -0.25);
    CHECK(mx_json_num(mx_json_at(b, 5)) == 12345678901234.0);
    CHECK(mx_json_at(b, 6) == NULL);
    CHECK(!strcmp(mx_json_get_str(j, "s", ""), "x\"\\/\b\f\n\r\t"));
    CHECK(mx_json_str_len(mx_json_get(j, "s")) == 9);
    CHECK(mx_json_len(mx_json_get(j, "o")) == 0 && mx_json_kind(mx_json_get(j, "o")) == MX_JSON_OBJ);
    CHECK(mx_json_len(mx_json_get(j, "e")) == 0 && mx_json_kind(mx_json_get(j, "e")) == MX_JSON_ARR);
    CHECK(!strcmp(mx_json_key(j, 2), "s"));
    CHECK(mx_json_get_bool(j, "a", 5) == 5);
    mx_json_free(j);

    j = parse("\"\\u00e9\\u20ac\\ud83d\\ude00\\u0041\"", &st);
    CHECK(j != NULL);
    if (j) {
        CHECK(!strcmp(mx_json_str(j), "\xC3\xA9\xE2\x82\xAC\xF0\x9F\x98\x80" "A"));
        CHECK(mx_json_str_len(j) == 10);
    }
    mx_json_free(j);

    j = parse("\"\\u0000x\"", &st); /* embedded NUL keeps its length */
    CHECK(j && mx_json_str_len(j) == 2);
    mx_json_free(j);

    j = parse("\"gr\xC3\xBC\xC3\x9F\"", &st); /* raw UTF-8 passes through */
    CHECK(j && !strcmp(mx_json_str(j), "gr\xC3\xBC\xC3\x9F"));
    mx_json_free(j);

    /* Python's json writes these (diffusers scheduler configs hold -Infinity) */
    j = parse("[NaN, Infinity, -Infinity]", &st);
    CHECK(j && isnan(mx_json_num(mx_json_at(j, 0))) && isinf(mx_json_num(mx_json_at(j, 1))) &&
          mx_json_num(mx_json_at(j, 2)) < 0 && isinf(mx_json_num(mx_json_at(j, 2))));
    mx_json_free(j);

    j = parse("\xEF\xBB\xBF[1]", &st); /* byte order mark */
    CHECK(j && mx_json_len(j) == 1);
    mx_json_free(j);
}

static void test_errors(void) {
    expect_error("", "byte 0");
    expect_error("{\"a\":1,}", "byte 7");
    expect_error("[1,2", "byte 4");
    expect_error("[1 2]", "byte 3");
    expect_error("{\"a\" 1}", "':'");
    expect_error("{1:2}", "key");
    expect_error("01", "trailing");
    expect_error("1.", "'.'");
    expect_error("1e", "exponent");
    expect_error("-", NULL);
    expect_error("+1", NULL);
    expect_error("nan", NULL);
    expect_error("-Inf", NULL);
    expect_error("1e999", "range");
    expect_error("tru", NULL);
    expect_error("\"abc", "unterminated");
    expect_error("\"a\nb\"", "control");
    expect_error("\"\\x\"", "escape");
    expect_error("\"\\u12G4\"", "hex");
    expect_error("\"\\ud83d\"", "surrogate");
    expect_error("\"\\ud83d\\u0041\"", "surrogate");
    expect_error("\"\\ude00\"", "surrogate");
    expect_error("\"\xC3\"", "UTF-8");
    expect_error("\"\xC0\xAF\"", "UTF-8");     /* overlong */
    expect_error("\"\xED\xA0\x80\"", "UTF-8"); /* encoded surrogate */
    expect_error("[1] x", "trailing");
    expect_error("// c\n1", NULL);
}

static void test_depth(void) {
    size_t n = 300;
    char *s = malloc(2 * n + 1);
    for (size_t i = 0; i < n; i++) s[i] = '[', s[2 * n - 1 - i] = ']';
    s[2 * n] = 0;
    expect_error(s, "deep");
    /* 200 levels are fine */
    mx_status st;
    mx_json *j = mx_json_parse(s + 100, 400, "test.json", &st);
    CHECK(j != NULL);
    mx_json_free(j);
    free(s);
}

/* Every proper prefix of a valid document is an error, never a crash. */
static void test_truncations(void) {
    const char *doc = "{\"k\": [1, -2.5e3, \"\\u00e9\\ud83d\\ude00\", {\"x\": null}], \"t\": true}";
    size_t n = strlen(doc);
    for (size_t cut = 0; cut < n; cut++) {
        mx_status st;
        char *copy = malloc(cut ? cut : 1); /* exact size: ASan catches reads past the end */
        memcpy(copy, doc, cut);
        mx_json *j = mx_json_parse(copy, cut, "test.json", &st);
        CHECK(j == NULL);
        mx_json_free(j);
        free(copy);
    }
}

/* Every byte of a document set to several values: parsed or refused, never a crash (ASan). */
static void test_mutations(void) {
    const char *doc = "{\"a\": [1, 2.5e-3, \"x\\u00e9\\n\"], \"b\": {\"c\": null, \"d\": -Infinity}, \"e\": true}";
    size_t n = strlen(doc);
    static const char vals[] = {0, '"', '\\', '[', '{', ']', '}', ',', ':', '-', '0', 'u', 'e', (char)0xC3, (char)0xFF};
    int parsed = 0, refused = 0;
    for (size_t pos = 0; pos < n; pos++)
        for (size_t v = 0; v < sizeof vals; v++) {
            char *copy = malloc(n);
            memcpy(copy, doc, n);
            copy[pos] = vals[v];
            mx_status st;
            mx_json *j = mx_json_parse(copy, n, "test.json", &st);
            if (j) {
                parsed++;
            } else {
                refused++;
                CHECK(strstr(st.msg, "test.json") != NULL);
            }
            mx_json_free(j);
            free(copy);
        }
    CHECK(parsed > 0 && refused > 0);
}

static void test_large_object(void) {
    /* a vocab.json-like object: many keys, parsed and looked up */
    size_t n = 20000, cap = n * 24 + 16, off = 0;
    char *s = malloc(cap);
    off += (size_t)snprintf(s + off, cap - off, "{");
    for (size_t i = 0; i < n; i++) off += (size_t)snprintf(s + off, cap - off, "%s\"w%zu\":%zu", i ? "," : "", i, i);
    off += (size_t)snprintf(s + off, cap - off, "}");
    mx_status st;
    mx_json *j = mx_json_parse(s, off, "vocab.json", &st);
    CHECK(j != NULL);
    if (j) {
        CHECK(mx_json_len(j) == n);
        CHECK(mx_json_get_num(j, "w12345", -1) == 12345);
        CHECK(mx_json_num(mx_json_at(j, n - 1)) == (double)(n - 1));
    }
    mx_json_free(j);
    free(s);
}

/* The JSON writer keeps valid UTF-8 and writes each byte that is not UTF-8 as \ufffd (a prompt
 * of raw 0xFF 0xFE bytes made report.json invalid JSON); the result parses back. */
static void test_writer_utf8(void) {
    mx_buf b = {0};
    mx_buf_json_str(&b, "\xff\xfe caf\xc3\xa9 \xe2\x82 \"q\"\x01");
    printf("written: %s\n", b.p);
    CHECK(b.p && !strcmp(b.p, "\"\\ufffd\\ufffd caf\xc3\xa9 \\ufffd\\ufffd \\\"q\\\"\\u0001\""));
    mx_status st = {0};
    mx_json *j = b.p ? mx_json_parse(b.p, b.len, "written", &st) : NULL;
    CHECK(j && mx_json_kind(j) == MX_JSON_STR && !strncmp(mx_json_str(j), "\xef\xbf\xbd\xef\xbf\xbd caf\xc3\xa9", 11));
    mx_json_free(j);
    mx_buf_free(&b);
}

int main(void) {
    test_writer_utf8();
    test_values();
    test_errors();
    test_depth();
    test_truncations();
    test_mutations();
    test_large_object();
    return mx_test_finish("test_runtime_json");
}
