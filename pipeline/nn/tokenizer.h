/* CLIP tokenizer: byte-level BPE exactly as transformers' CLIPTokenizer (4.39) without ftfy.
 * Text is lower-cased and its whitespace collapsed, split into pre-tokens by the CLIP pattern
 * ('s|'t|'re|'ve|'m|'ll|'d|letters+|one digit|other non-space run), each pre-token's UTF-8
 * bytes are mapped to the GPT-2 byte alphabet, "</w>" marks the end of a word, and BPE merges
 * are applied by rank. The result is framed as 49406 <tokens> 49407 and padded with 49407
 * to 77 ids (the pad token of the SD1.5 tokenizer is <|endoftext|>). */
#ifndef MX_TOKENIZER_H
#define MX_TOKENIZER_H

#include <stddef.h>
#include <stdint.h>

#include "../../runtime/status.h"
#include "../../weights/weights.h"

#define MX_CLIP_CONTEXT 77
#define MX_CLIP_BOS_ID 49406
#define MX_CLIP_EOS_ID 49407

typedef struct mx_tokenizer mx_tokenizer;

/* Builds a tokenizer from vocab.json text (token -> id) and merges.txt text (one merge
 * "a b" per line, a first line starting with "#version" is skipped). `what` names the source
 * in error messages. The texts are copied; the caller may free them afterwards. */
int mx_tok_create(mx_tokenizer **out, const char *vocab_json, size_t vocab_len, const char *merges_txt,
                  size_t merges_len, const char *what, mx_status *st);
/* Reads vocab.json and merges.txt from files. */
int mx_tok_load_files(mx_tokenizer **out, const char *vocab_path, const char *merges_path, mx_status *st);
/* Reads the metadata "tokenizer.vocab" and "tokenizer.merges" of a matex weight file. */
int mx_tok_load_weights(mx_tokenizer **out, const mx_weightfile *wf, mx_status *st);
void mx_tok_free(mx_tokenizer *t);

/* Result of encoding one prompt. */
/* Tokens are counted up to this many; past it the rest of the prompt is not encoded (so
 * n_dropped is then a lower bound) and the work per prompt stays bounded. */
#define MX_TOK_MAX_COUNTED 4096

typedef struct mx_tok_result {
    int32_t ids[MX_CLIP_CONTEXT]; /* BOS, tokens, EOS, then EOS padding */
    int n_tokens;                 /* ids used before padding, BOS and EOS included (2..77) */
    int n_dropped;                /* BPE tokens cut by truncation (0: the prompt fit) */
    char dropped_from[64];        /* where the dropped tokens begin: the cleaned (lower-case) text
                                     of the first word cut, and a little more, "..." when longer;
                                     "" when nothing was dropped */
} mx_tok_result;

/* Encodes a NUL-terminated UTF-8 prompt. Truncation keeps the first 75 tokens and the EOS;
 * the caller decides whether to warn (see n_dropped). Invalid UTF-8 sequences are dropped,
 * as the reference cleaner drops U+FFFD; "<|startoftext|>"/"<|endoftext|>" written in the
 * text become the special ids, as in transformers. Fails only on running out of memory. */
int mx_tok_encode(const mx_tokenizer *t, const char *text, mx_tok_result *out, mx_status *st);

/* Token id of a vocabulary entry (e.g. "a</w>"), -1 when absent. */
int32_t mx_tok_id(const mx_tokenizer *t, const char *token);
/* Number of vocabulary entries. */
size_t mx_tok_vocab_size(const mx_tokenizer *t);

#endif
