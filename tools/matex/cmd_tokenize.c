/* matex tokenize: the 77 CLIP token ids of a prompt, from a weight file's tokenizer or from
 * vocab.json + merges.txt. */
#include <stdio.h>
#include <string.h>

#include "../../pipeline/nn/tokenizer.h"
#include "../../weights/weights.h"
#include "cli.h"

static void tokenize_usage(FILE *f) {
    fprintf(f,
            "usage: matex tokenize (--weights FILE | --vocab vocab.json --merges merges.txt) [--json] PROMPT\n"
            "\n"
            "Prints the 77 token ids the CLIP text encoder sees (start 49406, end 49407, padded with\n"
            "49407), as transformers' CLIPTokenizer without ftfy. A prompt longer than 75 tokens is\n"
            "truncated, with a warning on stderr.\n"
            "\n"
            "  --weights FILE   matex weight file (metadata tokenizer.vocab / tokenizer.merges)\n"
            "  --vocab FILE     vocab.json (with --merges)\n"
            "  --merges FILE    merges.txt (with --vocab)\n"
            "  --json           print {\"ids\": [...], \"n_tokens\": N, \"dropped\": D}\n");
}

typedef struct tokenize_args {
    const char *weights, *vocab, *merges, *prompt;
    int json;
} tokenize_args;

/* Returns 0, or the exit code 2 after printing a usage error; 3 for --help. */
static int parse_tokenize_args(int argc, char **argv, tokenize_args *a) {
    memset(a, 0, sizeof *a);
    for (int i = 1; i < argc; i++) {
        const char *s = argv[i];
        if (!strcmp(s, "--help") || !strcmp(s, "-h")) return 3;
        if (!strcmp(s, "--json")) {
            a->json = 1;
        } else if (!strcmp(s, "--weights") || !strcmp(s, "--vocab") || !strcmp(s, "--merges")) {
            if (i + 1 >= argc) {
                fprintf(stderr, "matex tokenize: %s needs a file\n", s);
                return 2;
            }
            const char **dst = !strcmp(s, "--weights") ? &a->weights : !strcmp(s, "--vocab") ? &a->vocab : &a->merges;
            *dst = argv[++i];
        } else if (s[0] == '-' && s[1] == '-') {
            fprintf(stderr, "matex tokenize: unknown option %s\n", s);
            return 2;
        } else if (a->prompt) {
            fprintf(stderr, "matex tokenize: one prompt only (quote it)\n");
            return 2;
        } else {
            a->prompt = s;
        }
    }
    if (!a->prompt) {
        fprintf(stderr, "matex tokenize: missing PROMPT\n");
        return 2;
    }
    if (!a->weights == !(a->vocab || a->merges) || (!a->weights && !(a->vocab && a->merges))) {
        fprintf(stderr, "matex tokenize: give either --weights or both --vocab and --merges\n");
        return 2;
    }
    return 0;
}

static int load_tokenizer(const tokenize_args *a, mx_tokenizer **tok, mx_status *st) {
    if (!a->weights) return mx_tok_load_files(tok, a->vocab, a->merges, st);
    mx_weightfile *wf;
    if (mx_wf_open(&wf, a->weights, st)) return -1;
    int rc = mx_tok_load_weights(tok, wf, st);
    mx_wf_close(wf);
    return rc;
}

static void print_result(const mx_tok_result *r, int json) {
    if (json) printf("{\"ids\": [");
    for (int i = 0; i < MX_CLIP_CONTEXT; i++) printf("%s%d", i ? (json ? ", " : " ") : "", r->ids[i]);
    if (json)
        printf("], \"n_tokens\": %d, \"dropped\": %d}\n", r->n_tokens, r->n_dropped);
    else
        printf("\n");
}

int cmd_tokenize(int argc, char **argv) {
    tokenize_args a;
    int rc = parse_tokenize_args(argc, argv, &a);
    if (rc == 3) {
        tokenize_usage(stdout);
        return 0;
    }
    if (rc) {
        tokenize_usage(stderr);
        return rc;
    }
    mx_status st = {0};
    mx_tokenizer *tok;
    if (load_tokenizer(&a, &tok, &st)) {
        fprintf(stderr, "matex tokenize: %s\n", st.msg);
        return st.code == MX_EUSAGE ? 2 : 1;
    }
    mx_tok_result r;
    rc = mx_tok_encode(tok, a.prompt, &r, &st);
    mx_tok_free(tok);
    if (rc) {
        fprintf(stderr, "matex tokenize: %s\n", st.msg);
        return 1;
    }
    if (r.n_dropped > 0)
        fprintf(stderr, "matex tokenize: warning: prompt truncated to 77 tokens (%d tokens dropped)\n", r.n_dropped);
    print_result(&r, a.json);
    return 0;
}
