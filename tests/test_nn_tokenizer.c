/* CLIP tokenizer against transformers' CLIPTokenizer without ftfy: the 77 ids of every prompt
 * of golden/tokenizer/tokenizer_golden.json must be exactly equal; truncation is reported. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/nn/tokenizer.h"
#include "../runtime/fileio.h"
#include "../runtime/json.h"
#include "util_test.h"


/* Compares the ids of one record; prints the first difference. */
static void check_record(const mx_tokenizer *tok, const mx_json *rec) {
    const char *prompt = mx_json_get_str(rec, "prompt", NULL);
    const mx_json *want = mx_json_get(mx_json_get(rec, "hf_slow_noftfy"), "ids_sd_pipeline");
    const mx_json *full = mx_json_get(mx_json_get(rec, "hf_slow_noftfy"), "ids_full");
    CHECK(prompt != NULL && mx_json_len(want) == MX_CLIP_CONTEXT);
    if (!prompt || mx_json_len(want) != MX_CLIP_CONTEXT) return;
    mx_tok_result r;
    mx_status st = {0};
    CHECK(mx_tok_encode(tok, prompt, &r, &st) == 0);
    int first_diff = -1;
    for (int i = 0; i < MX_CLIP_CONTEXT && first_diff < 0; i++)
        if (r.ids[i] != (int32_t)mx_json_num(mx_json_at(want, (size_t)i))) first_diff = i;
    /* ids_full has BOS + every token + EOS: what was dropped is its excess over 77 */
    int dropped = (int)mx_json_len(full) > MX_CLIP_CONTEXT ? (int)mx_json_len(full) - MX_CLIP_CONTEXT : 0;
    char shown[48];
    size_t k = 0;
    for (; prompt[k] && k + 1 < sizeof shown; k++) shown[k] = (unsigned char)prompt[k] < 0x20 ? ' ' : prompt[k];
    shown[k] = 0;
    printf("%-48s %s\n", shown, first_diff < 0 ? "ids equal" : "ids DIFFER");
    if (first_diff >= 0)
        printf("    first difference at %d: got %d want %d\n", first_diff, r.ids[first_diff],
               (int)mx_json_num(mx_json_at(want, (size_t)first_diff)));
    CHECK(first_diff < 0);
    CHECK(r.n_dropped == dropped);
    CHECK(dropped > 0 || r.n_tokens == (int)mx_json_len(full));
}

static void test_golden(const mx_tokenizer *tok) {
    char path[1024];
    mx_test_path(path, sizeof path, "golden/tokenizer/tokenizer_golden.json");
    size_t len;
    char *text = mx_read_file(path, (size_t)1 << 30, &len, NULL);
    CHECK(text != NULL);
    if (!text) return;
    mx_status st = {0};
    mx_json *root = mx_json_parse(text, len, path, &st);
    CHECK(root != NULL);
    const mx_json *records = mx_json_get(root, "records");
    CHECK(mx_json_len(records) == 24);
    for (size_t i = 0; i < mx_json_len(records); i++) check_record(tok, mx_json_at(records, i));
    mx_json_free(root);
    free(text);
}

/* A hostile byte string never fails and yields a well-framed result. */
static void test_bad_utf8(const mx_tokenizer *tok) {
    const char bad[] = {'a', (char)0xff, (char)0xc3, 'b', (char)0xe2, (char)0x82, ' ', (char)0xf0, 'c', 0};
    mx_tok_result r;
    mx_status st = {0};
    CHECK(mx_tok_encode(tok, bad, &r, &st) == 0);
    CHECK(r.ids[0] == MX_CLIP_BOS_ID && r.ids[r.n_tokens - 1] == MX_CLIP_EOS_ID && r.n_dropped == 0);
}

/* The tokenizer of a matex weight file: metadata tokenizer.vocab / tokenizer.merges. */
static void test_weight_file(const char *vocab_path, const char *merges_path) {
    size_t vl, ml;
    char *v = mx_read_file(vocab_path, (size_t)1 << 30, &vl, NULL), *m = mx_read_file(merges_path, (size_t)1 << 30, &ml, NULL);
    char path[256];
    snprintf(path, sizeof path, "/tmp/matex_test_tok_%d.mxw", (int)getpid());
    mx_status st = {0};
    mx_wf_writer *w = mx_wf_writer_create(&st);
    float one = 1.0f;
    int64_t shape[1] = {1};
    int ok = v && m && w && mx_wf_writer_add(w, "dummy", MX_F32, 1, shape, &one, MX_F32, &st) == 0 &&
             mx_wf_writer_meta(w, "tokenizer.vocab", v, &st) == 0 &&
             mx_wf_writer_meta(w, "tokenizer.merges", m, &st) == 0 && mx_wf_writer_finish(w, path, &st) == 0;
    if (!ok) fprintf(stderr, "writing %s: %s\n", path, st.msg);
    CHECK(ok);
    mx_wf_writer_free(w);
    mx_weightfile *wf;
    mx_tokenizer *tok = NULL;
    if (ok && mx_wf_open(&wf, path, &st) == 0) {
        CHECK(mx_tok_load_weights(&tok, wf, &st) == 0);
        mx_tok_result r;
        CHECK(tok && mx_tok_encode(tok, "a red jacket", &r, &st) == 0);
        CHECK(tok && r.n_tokens == 5 && r.ids[1] == 320 && r.ids[2] == 736 && r.ids[3] == 6164);
        mx_tok_free(tok);
        mx_wf_close(wf);
    } else {
        CHECK(0);
    }
    remove(path);
    free(v);
    free(m);
}

/* Hostile sizes stay fast: a 2 MB single word and 2 MB of one-letter words. */
/* Where the dropped part begins: 75 one-token words are kept, the quote starts at the 76th
 * (lower-cased, about 40 bytes, "..."), and a prompt that fits quotes nothing. */
static void test_dropped_from(const mx_tokenizer *tok) {
    char text[2048] = "";
    for (int i = 0; i < MX_CLIP_CONTEXT - 2; i++) strcat(text, "red ");
    strcat(text, "Blue green yellow purple orange brown black white grey pink");
    mx_tok_result r;
    mx_status st = {0};
    CHECK(mx_tok_encode(tok, text, &r, &st) == 0 && r.n_dropped == 10);
    printf("dropped %d from \"%s\"\n", r.n_dropped, r.dropped_from);
    CHECK(!strncmp(r.dropped_from, "blue green yellow", 17) && strlen(r.dropped_from) <= 48);
    CHECK(strcmp(r.dropped_from + strlen(r.dropped_from) - 3, "...") == 0);
    CHECK(mx_tok_encode(tok, "a red chair", &r, &st) == 0 && r.n_dropped == 0 && r.dropped_from[0] == 0);
}

static void test_huge_prompts(const mx_tokenizer *tok) {
    size_t n = (size_t)2 << 20;
    char *word = malloc(n + 1), *words = malloc(n + 1);
    CHECK(word && words);
    if (!word || !words) return;
    for (size_t i = 0; i < n; i++) {
        word[i] = (char)('a' + (i * 7) % 26);
        words[i] = (i & 1) ? ' ' : 'x';
    }
    word[n] = words[n] = 0;
    mx_tok_result r;
    mx_status st = {0};
    CHECK(mx_tok_encode(tok, word, &r, &st) == 0 && r.n_tokens == MX_CLIP_CONTEXT && r.n_dropped > 0);
    CHECK(r.ids[MX_CLIP_CONTEXT - 1] == MX_CLIP_EOS_ID);
    CHECK(mx_tok_encode(tok, words, &r, &st) == 0 && r.n_dropped >= MX_TOK_MAX_COUNTED - (MX_CLIP_CONTEXT - 2));
    CHECK(r.ids[1] == mx_tok_id(tok, "x</w>"));
    free(word);
    free(words);
}

static void test_bad_files(void) {
    mx_tokenizer *t;
    mx_status st = {0};
    const char *vocab = "{\"a\": 0, \"b\": 1}";
    CHECK(mx_tok_create(&t, vocab, strlen(vocab), "#version\na b\n", 13, "tiny", &st) != 0);
    CHECK(t == NULL && strstr(st.msg, "tiny") != NULL);
    CHECK(mx_tok_load_files(&t, "/nonexistent/vocab.json", "/nonexistent/merges.txt", &st) != 0);
    CHECK(strstr(st.msg, "/nonexistent/vocab.json") != NULL);
}

int main(void) {
    char v[1024], m[1024];
    mx_test_path(v, sizeof v, "golden/tokenizer/vocab.json");
    mx_test_path(m, sizeof m, "golden/tokenizer/merges.txt");
    mx_tokenizer *tok = NULL;
    mx_status st = {0};
    int ok = mx_tok_load_files(&tok, v, m, &st) == 0;
    if (!ok) fprintf(stderr, "%s\n", st.msg);
    CHECK(ok);
    if (ok) {
        CHECK(mx_tok_vocab_size(tok) == 49408);
        CHECK(mx_tok_id(tok, "a</w>") == 320);
        test_golden(tok);
        test_bad_utf8(tok);
        test_weight_file(v, m);
        test_dropped_from(tok);
        test_huge_prompts(tok);
    }
    test_bad_files();
    mx_tok_free(tok);
    return mx_test_finish("test_nn_tokenizer");
}
