/* The CLIP tokenizer (pipeline/nn/tokenizer.c). First byte even: the rest is a prompt,
 * encoded with the real SD1.5 vocabulary (tests/data/golden/tokenizer, loaded once; a built-in
 * small one when absent). Odd: the rest is "vocab.json FUZZ_SEP merges.txt FUZZ_SEP prompt", a hostile
 * vocabulary and merge list built into a tokenizer that then encodes the prompt. */
#include <stdlib.h>
#include <string.h>

#include "../../pipeline/nn/tokenizer.h"
#include "fuzz.h"

static const char small_vocab[] = "{\"a</w>\":0,\"b</w>\":1,\"a\":2,\"b\":3,\"ab</w>\":4,\"<|startoftext|>\":49406,"
                                  "\"<|endoftext|>\":49407}";
static const char small_merges[] = "#version: 0.2\na b</w>\n";

static mx_tokenizer *real_tokenizer(void) {
    static mx_tokenizer *tok; /* harness-side cache: one vocabulary load per process */
    mx_status st;
    if (!tok && mx_tok_load_files(&tok, "tests/data/golden/tokenizer/vocab.json", "tests/data/golden/tokenizer/merges.txt",
                                  &st) &&
        mx_tok_create(&tok, small_vocab, strlen(small_vocab), small_merges, strlen(small_merges), "small", &st))
        abort();
    return tok;
}

static void encode(const mx_tokenizer *tok, const uint8_t *text, size_t len) {
    char *prompt = malloc(len + 1);
    if (!prompt) return;
    if (len) memcpy(prompt, text, len);
    prompt[len] = 0;
    mx_status st;
    mx_tok_result r;
    if (!mx_tok_encode(tok, prompt, &r, &st) && (r.n_tokens < 2 || r.n_tokens > MX_CLIP_CONTEXT)) abort();
    free(prompt);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (!size) return 0;
    if (!(data[0] & 1)) {
        encode(real_tokenizer(), data + 1, size - 1);
        return 0;
    }
    size_t vlen, mlen, plen;
    const uint8_t *merges, *prompt;
    fuzz_split(data + 1, size - 1, FUZZ_SEP, &vlen, &merges, &mlen);
    fuzz_split(merges, mlen, FUZZ_SEP, &mlen, &prompt, &plen);
    mx_tokenizer *tok;
    mx_status st;
    if (mx_tok_create(&tok, (const char *)data + 1, vlen, (const char *)merges, mlen, "fuzz", &st)) return 0;
    encode(tok, prompt, plen);
    mx_tok_free(tok);
    return 0;
}
