/* CLIP byte-level BPE, matching transformers 4.39 CLIPTokenizer when ftfy is not installed
 * (the common case for diffusers users):
 *   1. BasicTokenizer cleanup: drop NUL, U+FFFD and control/format characters (Cc, Cf), map
 *      whitespace to ' ', put spaces around CJK ideographs, lower-case (NFC is assumed: text
 *      is not re-normalised);
 *   2. pre-tokens by the CLIP pattern <|startoftext|>|<|endoftext|>|'s|'t|'re|'ve|'m|'ll|'d|
 *      \p{L}+|\p{N}|[^\s\p{L}\p{N}]+;
 *   3. each pre-token's UTF-8 bytes become GPT-2 byte symbols, the last one carrying "</w>",
 *      and merges are applied lowest rank first.
 * Symbols are handled as vocabulary ids: every merge of the CLIP vocabulary joins two entries
 * into a third, so a merge is a (left id, right id) -> (rank, merged id) table lookup. */
#include "tokenizer.h"
#include "../../runtime/fileio.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"

/* transformers reads merges.txt lines [1, 49152 - 256 - 2 + 1): the CLIP vocabulary size. */
#define CLIP_MAX_MERGES (49152 - 256 - 2)

typedef struct vocab_slot {
    const char *key; /* NULL: empty */
    int32_t id;
} vocab_slot;

typedef struct merge_slot {
    uint64_t pair; /* (left << 32) | right; UINT64_MAX: empty */
    int32_t rank;
    int32_t merged;
} merge_slot;

struct mx_tokenizer {
    char *strings; /* all vocabulary keys, NUL-separated */
    vocab_slot *vocab;
    size_t vocab_cap, vocab_count;
    merge_slot *merges;
    size_t merge_cap;
    int32_t byte_id[256];      /* id of the byte symbol */
    int32_t byte_end_id[256];  /* id of the byte symbol + "</w>" */
};

/* ---- hash tables (open addressing, power-of-two capacity) ---- */

static uint64_t hash_str(const char *s, size_t n) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (size_t i = 0; i < n; i++) h = (h ^ (unsigned char)s[i]) * 0x100000001b3ull;
    return h;
}

static uint64_t hash_u64(uint64_t x) {
    x ^= x >> 33;
    x *= 0xff51afd7ed558ccdull;
    x ^= x >> 33;
    return x;
}

static size_t pow2_at_least(size_t n) {
    size_t c = 16;
    while (c < n) c <<= 1;
    return c;
}

static vocab_slot *vocab_slot_for(const mx_tokenizer *t, const char *s, size_t n) {
    size_t mask = t->vocab_cap - 1;
    for (size_t i = hash_str(s, n) & mask;; i = (i + 1) & mask) {
        vocab_slot *v = &t->vocab[i];
        if (!v->key || (strncmp(v->key, s, n) == 0 && v->key[n] == 0)) return v;
    }
}

static int32_t vocab_find(const mx_tokenizer *t, const char *s, size_t n) {
    const vocab_slot *v = vocab_slot_for(t, s, n);
    return v->key ? v->id : -1;
}

static merge_slot *merge_slot_for(const mx_tokenizer *t, uint64_t pair) {
    size_t mask = t->merge_cap - 1;
    for (size_t i = hash_u64(pair) & mask;; i = (i + 1) & mask) {
        merge_slot *m = &t->merges[i];
        if (m->pair == UINT64_MAX || m->pair == pair) return m;
    }
}

/* ---- GPT-2 byte alphabet ---- */

/* Unicode code point of the symbol for byte b: printable Latin-1 bytes stand for themselves,
 * the others are numbered from 256 upwards in byte order (bytes_to_unicode). */
static unsigned byte_symbol(unsigned b) {
    int self = (b >= 33 && b <= 126) || (b >= 161 && b <= 172) || (b >= 174);
    if (self) return b;
    unsigned n = 0;
    for (unsigned k = 0; k < b; k++)
        if (!((k >= 33 && k <= 126) || (k >= 161 && k <= 172) || (k >= 174))) n++;
    return 256 + n;
}


/* ---- construction ---- */

static int load_vocab(mx_tokenizer *t, const char *text, size_t len, const char *what, mx_status *st) {
    mx_json *root = mx_json_parse(text, len, what, st);
    if (!root) return -1;
    int rc = -1;
    size_t n = mx_json_len(root), bytes = 0;
    if (mx_json_kind(root) != MX_JSON_OBJ || n == 0) {
        mx_fail(st, MX_EINPUT, "%s: vocabulary is not a non-empty JSON object", what);
        goto done;
    }
    for (size_t i = 0; i < n; i++) bytes += strlen(mx_json_key(root, i)) + 1;
    t->vocab_cap = pow2_at_least(n * 2);
    t->strings = malloc(bytes);
    t->vocab = calloc(t->vocab_cap, sizeof *t->vocab);
    if (!t->strings || !t->vocab) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory for %zu vocabulary entries", what, n);
        goto done;
    }
    char *p = t->strings;
    for (size_t i = 0; i < n; i++) {
        const char *key = mx_json_key(root, i);
        const mx_json *v = mx_json_at(root, i);
        double id = mx_json_num(v);
        if (mx_json_kind(v) != MX_JSON_NUM || id < 0 || id >= 1 << 30 || id != (double)(int32_t)id) {
            mx_fail(st, MX_EINPUT, "%s: entry \"%.40s\" has no valid id", what, key);
            goto done;
        }
        size_t kl = strlen(key);
        vocab_slot *slot = vocab_slot_for(t, key, kl);
        if (slot->key) {
            mx_fail(st, MX_EINPUT, "%s: duplicate entry \"%.40s\"", what, key);
            goto done;
        }
        memcpy(p, key, kl + 1);
        slot->key = p;
        slot->id = (int32_t)id;
        p += kl + 1;
        t->vocab_count++;
    }
    rc = 0;
done:
    mx_json_free(root);
    return rc;
}

static int find_byte_symbols(mx_tokenizer *t, const char *what, mx_status *st) {
    for (unsigned b = 0; b < 256; b++) {
        char s[16];
        size_t n = mx_utf8_encode(byte_symbol(b), s);
        t->byte_id[b] = vocab_find(t, s, n);
        memcpy(s + n, "</w>", 4);
        t->byte_end_id[b] = vocab_find(t, s, n + 4);
        if (t->byte_id[b] < 0 || t->byte_end_id[b] < 0)
            return mx_fail(st, MX_EINPUT, "%s: vocabulary lacks the symbol of byte %u", what, b);
    }
    return 0;
}

/* Adds merge `line` ("left right") with the given rank. */
static int add_merge(mx_tokenizer *t, const char *line, size_t len, int32_t rank, const char *what,
                     mx_status *st) {
    const char *sp = memchr(line, ' ', len);
    if (!sp || sp == line || sp == line + len - 1)
        return mx_fail(st, MX_EINPUT, "%s: merge %d is not \"left right\"", what, rank + 1);
    size_t ln = (size_t)(sp - line), rn = len - ln - 1;
    char joined[512];
    if (ln + rn >= sizeof joined) return mx_fail(st, MX_EINPUT, "%s: merge %d is too long", what, rank + 1);
    memcpy(joined, line, ln);
    memcpy(joined + ln, sp + 1, rn);
    int32_t a = vocab_find(t, line, ln), b = vocab_find(t, sp + 1, rn), m = vocab_find(t, joined, ln + rn);
    if (a < 0 || b < 0 || m < 0)
        return mx_fail(st, MX_EINPUT, "%s: merge %d (\"%.*s\") names a token missing from the vocabulary", what,
                       rank + 1, (int)(len < 60 ? len : 60), line);
    uint64_t pair = ((uint64_t)(uint32_t)a << 32) | (uint32_t)b;
    merge_slot *slot = merge_slot_for(t, pair);
    if (slot->pair == UINT64_MAX) { /* a repeated pair keeps its first (lowest) rank */
        slot->pair = pair;
        slot->rank = rank;
        slot->merged = m;
    }
    return 0;
}

static int load_merges(mx_tokenizer *t, const char *text, size_t len, const char *what, mx_status *st) {
    size_t lines = 0;
    for (size_t i = 0; i < len; i++) lines += text[i] == '\n';
    t->merge_cap = pow2_at_least((lines + 1) * 2);
    t->merges = malloc(t->merge_cap * sizeof *t->merges);
    if (!t->merges) return mx_fail(st, MX_ENOMEM, "%s: out of memory for %zu merges", what, lines);
    for (size_t i = 0; i < t->merge_cap; i++) t->merges[i].pair = UINT64_MAX;
    /* like transformers: strip the text, skip the first line (the "#version" header) */
    while (len > 0 && (text[len - 1] == '\n' || text[len - 1] == '\r' || text[len - 1] == ' ')) len--;
    size_t pos = 0;
    int32_t rank = -1;
    while (pos < len && rank < CLIP_MAX_MERGES) {
        const char *nl = memchr(text + pos, '\n', len - pos);
        size_t end = nl ? (size_t)(nl - text) : len, n = end - pos;
        if (n > 0 && text[pos + n - 1] == '\r') n--;
        if (rank >= 0 && add_merge(t, text + pos, n, rank, what, st)) return -1;
        rank++;
        pos = end + 1;
    }
    return 0;
}

int mx_tok_create(mx_tokenizer **out, const char *vocab_json, size_t vocab_len, const char *merges_txt,
                  size_t merges_len, const char *what, mx_status *st) {
    *out = NULL;
    mx_tokenizer *t = calloc(1, sizeof *t);
    if (!t) return mx_fail(st, MX_ENOMEM, "%s: out of memory", what);
    char vwhat[300], mwhat[300];
    snprintf(vwhat, sizeof vwhat, "%s (vocab)", what);
    snprintf(mwhat, sizeof mwhat, "%s (merges)", what);
    if (load_vocab(t, vocab_json, vocab_len, vwhat, st) || find_byte_symbols(t, vwhat, st) ||
        load_merges(t, merges_txt, merges_len, mwhat, st)) {
        mx_tok_free(t);
        return -1;
    }
    *out = t;
    return 0;
}


int mx_tok_load_files(mx_tokenizer **out, const char *vocab_path, const char *merges_path, mx_status *st) {
    size_t vl = 0, ml = 0;
    *out = NULL;
    char *v = mx_read_file(vocab_path, (size_t)1 << 30, &vl, st);
    if (!v) return -1;
    char *m = mx_read_file(merges_path, (size_t)1 << 30, &ml, st);
    if (!m) {
        free(v);
        return -1;
    }
    char what[600];
    snprintf(what, sizeof what, "%s + %s", vocab_path, merges_path);
    int rc = mx_tok_create(out, v, vl, m, ml, what, st);
    free(v);
    free(m);
    return rc;
}

int mx_tok_load_weights(mx_tokenizer **out, const mx_weightfile *wf, mx_status *st) {
    *out = NULL;
    const char *v = mx_wf_meta(wf, "tokenizer.vocab"), *m = mx_wf_meta(wf, "tokenizer.merges");
    if (!v || !m)
        return mx_fail(st, MX_EINPUT, "%s: no tokenizer (metadata \"tokenizer.vocab\"/\"tokenizer.merges\" missing)",
                       mx_wf_path(wf));
    return mx_tok_create(out, v, strlen(v), m, strlen(m), mx_wf_path(wf), st);
}

void mx_tok_free(mx_tokenizer *t) {
    if (!t) return;
    free(t->strings);
    free(t->vocab);
    free(t->merges);
    free(t);
}

int32_t mx_tok_id(const mx_tokenizer *t, const char *token) { return vocab_find(t, token, strlen(token)); }
size_t mx_tok_vocab_size(const mx_tokenizer *t) { return t->vocab_count; }

/* ---- Unicode classes: tables generated from Python 3.11's unicodedata (Unicode 14.0) ---- */

typedef struct cp_range {
    unsigned lo, hi;
} cp_range;

typedef struct lower_run {
    unsigned lo, hi;
    int delta, stride;
} lower_run;

/* \p{L}: categories Lu Ll Lt Lm Lo. */
static const cp_range letter_ranges[] = {
    {0x41, 0x5A}, {0x61, 0x7A}, {0xAA, 0xAA}, {0xB5, 0xB5}, {0xBA, 0xBA}, {0xC0, 0xD6}, {0xD8, 0xF6}, {0xF8, 0x2C1},
    {0x2C6, 0x2D1}, {0x2E0, 0x2E4}, {0x2EC, 0x2EC}, {0x2EE, 0x2EE}, {0x370, 0x374}, {0x376, 0x377}, {0x37A, 0x37D},
    {0x37F, 0x37F}, {0x386, 0x386}, {0x388, 0x38A}, {0x38C, 0x38C}, {0x38E, 0x3A1}, {0x3A3, 0x3F5}, {0x3F7, 0x481},
    {0x48A, 0x52F}, {0x531, 0x556}, {0x559, 0x559}, {0x560, 0x588}, {0x5D0, 0x5EA}, {0x5EF, 0x5F2}, {0x620, 0x64A},
    {0x66E, 0x66F}, {0x671, 0x6D3}, {0x6D5, 0x6D5}, {0x6E5, 0x6E6}, {0x6EE, 0x6EF}, {0x6FA, 0x6FC}, {0x6FF, 0x6FF},
    {0x710, 0x710}, {0x712, 0x72F}, {0x74D, 0x7A5}, {0x7B1, 0x7B1}, {0x7CA, 0x7EA}, {0x7F4, 0x7F5}, {0x7FA, 0x7FA},
    {0x800, 0x815}, {0x81A, 0x81A}, {0x824, 0x824}, {0x828, 0x828}, {0x840, 0x858}, {0x860, 0x86A}, {0x870, 0x887},
    {0x889, 0x88E}, {0x8A0, 0x8C9}, {0x904, 0x939}, {0x93D, 0x93D}, {0x950, 0x950}, {0x958, 0x961}, {0x971, 0x980},
    {0x985, 0x98C}, {0x98F, 0x990}, {0x993, 0x9A8}, {0x9AA, 0x9B0}, {0x9B2, 0x9B2}, {0x9B6, 0x9B9}, {0x9BD, 0x9BD},
    {0x9CE, 0x9CE}, {0x9DC, 0x9DD}, {0x9DF, 0x9E1}, {0x9F0, 0x9F1}, {0x9FC, 0x9FC}, {0xA05, 0xA0A}, {0xA0F, 0xA10},
    {0xA13, 0xA28}, {0xA2A, 0xA30}, {0xA32, 0xA33}, {0xA35, 0xA36}, {0xA38, 0xA39}, {0xA59, 0xA5C}, {0xA5E, 0xA5E},
    {0xA72, 0xA74}, {0xA85, 0xA8D}, {0xA8F, 0xA91}, {0xA93, 0xAA8}, {0xAAA, 0xAB0}, {0xAB2, 0xAB3}, {0xAB5, 0xAB9},
    {0xABD, 0xABD}, {0xAD0, 0xAD0}, {0xAE0, 0xAE1}, {0xAF9, 0xAF9}, {0xB05, 0xB0C}, {0xB0F, 0xB10}, {0xB13, 0xB28},
    {0xB2A, 0xB30}, {0xB32, 0xB33}, {0xB35, 0xB39}, {0xB3D, 0xB3D}, {0xB5C, 0xB5D}, {0xB5F, 0xB61}, {0xB71, 0xB71},
    {0xB83, 0xB83}, {0xB85, 0xB8A}, {0xB8E, 0xB90}, {0xB92, 0xB95}, {0xB99, 0xB9A}, {0xB9C, 0xB9C}, {0xB9E, 0xB9F},
    {0xBA3, 0xBA4}, {0xBA8, 0xBAA}, {0xBAE, 0xBB9}, {0xBD0, 0xBD0}, {0xC05, 0xC0C}, {0xC0E, 0xC10}, {0xC12, 0xC28},
    {0xC2A, 0xC39}, {0xC3D, 0xC3D}, {0xC58, 0xC5A}, {0xC5D, 0xC5D}, {0xC60, 0xC61}, {0xC80, 0xC80}, {0xC85, 0xC8C},
    {0xC8E, 0xC90}, {0xC92, 0xCA8}, {0xCAA, 0xCB3}, {0xCB5, 0xCB9}, {0xCBD, 0xCBD}, {0xCDD, 0xCDE}, {0xCE0, 0xCE1},
    {0xCF1, 0xCF2}, {0xD04, 0xD0C}, {0xD0E, 0xD10}, {0xD12, 0xD3A}, {0xD3D, 0xD3D}, {0xD4E, 0xD4E}, {0xD54, 0xD56},
    {0xD5F, 0xD61}, {0xD7A, 0xD7F}, {0xD85, 0xD96}, {0xD9A, 0xDB1}, {0xDB3, 0xDBB}, {0xDBD, 0xDBD}, {0xDC0, 0xDC6},
    {0xE01, 0xE30}, {0xE32, 0xE33}, {0xE40, 0xE46}, {0xE81, 0xE82}, {0xE84, 0xE84}, {0xE86, 0xE8A}, {0xE8C, 0xEA3},
    {0xEA5, 0xEA5}, {0xEA7, 0xEB0}, {0xEB2, 0xEB3}, {0xEBD, 0xEBD}, {0xEC0, 0xEC4}, {0xEC6, 0xEC6}, {0xEDC, 0xEDF},
    {0xF00, 0xF00}, {0xF40, 0xF47}, {0xF49, 0xF6C}, {0xF88, 0xF8C}, {0x1000, 0x102A}, {0x103F, 0x103F},
    {0x1050, 0x1055}, {0x105A, 0x105D}, {0x1061, 0x1061}, {0x1065, 0x1066}, {0x106E, 0x1070}, {0x1075, 0x1081},
    {0x108E, 0x108E}, {0x10A0, 0x10C5}, {0x10C7, 0x10C7}, {0x10CD, 0x10CD}, {0x10D0, 0x10FA}, {0x10FC, 0x1248},
    {0x124A, 0x124D}, {0x1250, 0x1256}, {0x1258, 0x1258}, {0x125A, 0x125D}, {0x1260, 0x1288}, {0x128A, 0x128D},
    {0x1290, 0x12B0}, {0x12B2, 0x12B5}, {0x12B8, 0x12BE}, {0x12C0, 0x12C0}, {0x12C2, 0x12C5}, {0x12C8, 0x12D6},
    {0x12D8, 0x1310}, {0x1312, 0x1315}, {0x1318, 0x135A}, {0x1380, 0x138F}, {0x13A0, 0x13F5}, {0x13F8, 0x13FD},
    {0x1401, 0x166C}, {0x166F, 0x167F}, {0x1681, 0x169A}, {0x16A0, 0x16EA}, {0x16F1, 0x16F8}, {0x1700, 0x1711},
    {0x171F, 0x1731}, {0x1740, 0x1751}, {0x1760, 0x176C}, {0x176E, 0x1770}, {0x1780, 0x17B3}, {0x17D7, 0x17D7},
    {0x17DC, 0x17DC}, {0x1820, 0x1878}, {0x1880, 0x1884}, {0x1887, 0x18A8}, {0x18AA, 0x18AA}, {0x18B0, 0x18F5},
    {0x1900, 0x191E}, {0x1950, 0x196D}, {0x1970, 0x1974}, {0x1980, 0x19AB}, {0x19B0, 0x19C9}, {0x1A00, 0x1A16},
    {0x1A20, 0x1A54}, {0x1AA7, 0x1AA7}, {0x1B05, 0x1B33}, {0x1B45, 0x1B4C}, {0x1B83, 0x1BA0}, {0x1BAE, 0x1BAF},
    {0x1BBA, 0x1BE5}, {0x1C00, 0x1C23}, {0x1C4D, 0x1C4F}, {0x1C5A, 0x1C7D}, {0x1C80, 0x1C88}, {0x1C90, 0x1CBA},
    {0x1CBD, 0x1CBF}, {0x1CE9, 0x1CEC}, {0x1CEE, 0x1CF3}, {0x1CF5, 0x1CF6}, {0x1CFA, 0x1CFA}, {0x1D00, 0x1DBF},
    {0x1E00, 0x1F15}, {0x1F18, 0x1F1D}, {0x1F20, 0x1F45}, {0x1F48, 0x1F4D}, {0x1F50, 0x1F57}, {0x1F59, 0x1F59},
    {0x1F5B, 0x1F5B}, {0x1F5D, 0x1F5D}, {0x1F5F, 0x1F7D}, {0x1F80, 0x1FB4}, {0x1FB6, 0x1FBC}, {0x1FBE, 0x1FBE},
    {0x1FC2, 0x1FC4}, {0x1FC6, 0x1FCC}, {0x1FD0, 0x1FD3}, {0x1FD6, 0x1FDB}, {0x1FE0, 0x1FEC}, {0x1FF2, 0x1FF4},
    {0x1FF6, 0x1FFC}, {0x2071, 0x2071}, {0x207F, 0x207F}, {0x2090, 0x209C}, {0x2102, 0x2102}, {0x2107, 0x2107},
    {0x210A, 0x2113}, {0x2115, 0x2115}, {0x2119, 0x211D}, {0x2124, 0x2124}, {0x2126, 0x2126}, {0x2128, 0x2128},
    {0x212A, 0x212D}, {0x212F, 0x2139}, {0x213C, 0x213F}, {0x2145, 0x2149}, {0x214E, 0x214E}, {0x2183, 0x2184},
    {0x2C00, 0x2CE4}, {0x2CEB, 0x2CEE}, {0x2CF2, 0x2CF3}, {0x2D00, 0x2D25}, {0x2D27, 0x2D27}, {0x2D2D, 0x2D2D},
    {0x2D30, 0x2D67}, {0x2D6F, 0x2D6F}, {0x2D80, 0x2D96}, {0x2DA0, 0x2DA6}, {0x2DA8, 0x2DAE}, {0x2DB0, 0x2DB6},
    {0x2DB8, 0x2DBE}, {0x2DC0, 0x2DC6}, {0x2DC8, 0x2DCE}, {0x2DD0, 0x2DD6}, {0x2DD8, 0x2DDE}, {0x2E2F, 0x2E2F},
    {0x3005, 0x3006}, {0x3031, 0x3035}, {0x303B, 0x303C}, {0x3041, 0x3096}, {0x309D, 0x309F}, {0x30A1, 0x30FA},
    {0x30FC, 0x30FF}, {0x3105, 0x312F}, {0x3131, 0x318E}, {0x31A0, 0x31BF}, {0x31F0, 0x31FF}, {0x3400, 0x4DBF},
    {0x4E00, 0xA48C}, {0xA4D0, 0xA4FD}, {0xA500, 0xA60C}, {0xA610, 0xA61F}, {0xA62A, 0xA62B}, {0xA640, 0xA66E},
    {0xA67F, 0xA69D}, {0xA6A0, 0xA6E5}, {0xA717, 0xA71F}, {0xA722, 0xA788}, {0xA78B, 0xA7CA}, {0xA7D0, 0xA7D1},
    {0xA7D3, 0xA7D3}, {0xA7D5, 0xA7D9}, {0xA7F2, 0xA801}, {0xA803, 0xA805}, {0xA807, 0xA80A}, {0xA80C, 0xA822},
    {0xA840, 0xA873}, {0xA882, 0xA8B3}, {0xA8F2, 0xA8F7}, {0xA8FB, 0xA8FB}, {0xA8FD, 0xA8FE}, {0xA90A, 0xA925},
    {0xA930, 0xA946}, {0xA960, 0xA97C}, {0xA984, 0xA9B2}, {0xA9CF, 0xA9CF}, {0xA9E0, 0xA9E4}, {0xA9E6, 0xA9EF},
    {0xA9FA, 0xA9FE}, {0xAA00, 0xAA28}, {0xAA40, 0xAA42}, {0xAA44, 0xAA4B}, {0xAA60, 0xAA76}, {0xAA7A, 0xAA7A},
    {0xAA7E, 0xAAAF}, {0xAAB1, 0xAAB1}, {0xAAB5, 0xAAB6}, {0xAAB9, 0xAABD}, {0xAAC0, 0xAAC0}, {0xAAC2, 0xAAC2},
    {0xAADB, 0xAADD}, {0xAAE0, 0xAAEA}, {0xAAF2, 0xAAF4}, {0xAB01, 0xAB06}, {0xAB09, 0xAB0E}, {0xAB11, 0xAB16},
    {0xAB20, 0xAB26}, {0xAB28, 0xAB2E}, {0xAB30, 0xAB5A}, {0xAB5C, 0xAB69}, {0xAB70, 0xABE2}, {0xAC00, 0xD7A3},
    {0xD7B0, 0xD7C6}, {0xD7CB, 0xD7FB}, {0xF900, 0xFA6D}, {0xFA70, 0xFAD9}, {0xFB00, 0xFB06}, {0xFB13, 0xFB17},
    {0xFB1D, 0xFB1D}, {0xFB1F, 0xFB28}, {0xFB2A, 0xFB36}, {0xFB38, 0xFB3C}, {0xFB3E, 0xFB3E}, {0xFB40, 0xFB41},
    {0xFB43, 0xFB44}, {0xFB46, 0xFBB1}, {0xFBD3, 0xFD3D}, {0xFD50, 0xFD8F}, {0xFD92, 0xFDC7}, {0xFDF0, 0xFDFB},
    {0xFE70, 0xFE74}, {0xFE76, 0xFEFC}, {0xFF21, 0xFF3A}, {0xFF41, 0xFF5A}, {0xFF66, 0xFFBE}, {0xFFC2, 0xFFC7},
    {0xFFCA, 0xFFCF}, {0xFFD2, 0xFFD7}, {0xFFDA, 0xFFDC}, {0x10000, 0x1000B}, {0x1000D, 0x10026}, {0x10028, 0x1003A},
    {0x1003C, 0x1003D}, {0x1003F, 0x1004D}, {0x10050, 0x1005D}, {0x10080, 0x100FA}, {0x10280, 0x1029C},
    {0x102A0, 0x102D0}, {0x10300, 0x1031F}, {0x1032D, 0x10340}, {0x10342, 0x10349}, {0x10350, 0x10375},
    {0x10380, 0x1039D}, {0x103A0, 0x103C3}, {0x103C8, 0x103CF}, {0x10400, 0x1049D}, {0x104B0, 0x104D3},
    {0x104D8, 0x104FB}, {0x10500, 0x10527}, {0x10530, 0x10563}, {0x10570, 0x1057A}, {0x1057C, 0x1058A},
    {0x1058C, 0x10592}, {0x10594, 0x10595}, {0x10597, 0x105A1}, {0x105A3, 0x105B1}, {0x105B3, 0x105B9},
    {0x105BB, 0x105BC}, {0x10600, 0x10736}, {0x10740, 0x10755}, {0x10760, 0x10767}, {0x10780, 0x10785},
    {0x10787, 0x107B0}, {0x107B2, 0x107BA}, {0x10800, 0x10805}, {0x10808, 0x10808}, {0x1080A, 0x10835},
    {0x10837, 0x10838}, {0x1083C, 0x1083C}, {0x1083F, 0x10855}, {0x10860, 0x10876}, {0x10880, 0x1089E},
    {0x108E0, 0x108F2}, {0x108F4, 0x108F5}, {0x10900, 0x10915}, {0x10920, 0x10939}, {0x10980, 0x109B7},
    {0x109BE, 0x109BF}, {0x10A00, 0x10A00}, {0x10A10, 0x10A13}, {0x10A15, 0x10A17}, {0x10A19, 0x10A35},
    {0x10A60, 0x10A7C}, {0x10A80, 0x10A9C}, {0x10AC0, 0x10AC7}, {0x10AC9, 0x10AE4}, {0x10B00, 0x10B35},
    {0x10B40, 0x10B55}, {0x10B60, 0x10B72}, {0x10B80, 0x10B91}, {0x10C00, 0x10C48}, {0x10C80, 0x10CB2},
    {0x10CC0, 0x10CF2}, {0x10D00, 0x10D23}, {0x10E80, 0x10EA9}, {0x10EB0, 0x10EB1}, {0x10F00, 0x10F1C},
    {0x10F27, 0x10F27}, {0x10F30, 0x10F45}, {0x10F70, 0x10F81}, {0x10FB0, 0x10FC4}, {0x10FE0, 0x10FF6},
    {0x11003, 0x11037}, {0x11071, 0x11072}, {0x11075, 0x11075}, {0x11083, 0x110AF}, {0x110D0, 0x110E8},
    {0x11103, 0x11126}, {0x11144, 0x11144}, {0x11147, 0x11147}, {0x11150, 0x11172}, {0x11176, 0x11176},
    {0x11183, 0x111B2}, {0x111C1, 0x111C4}, {0x111DA, 0x111DA}, {0x111DC, 0x111DC}, {0x11200, 0x11211},
    {0x11213, 0x1122B}, {0x11280, 0x11286}, {0x11288, 0x11288}, {0x1128A, 0x1128D}, {0x1128F, 0x1129D},
    {0x1129F, 0x112A8}, {0x112B0, 0x112DE}, {0x11305, 0x1130C}, {0x1130F, 0x11310}, {0x11313, 0x11328},
    {0x1132A, 0x11330}, {0x11332, 0x11333}, {0x11335, 0x11339}, {0x1133D, 0x1133D}, {0x11350, 0x11350},
    {0x1135D, 0x11361}, {0x11400, 0x11434}, {0x11447, 0x1144A}, {0x1145F, 0x11461}, {0x11480, 0x114AF},
    {0x114C4, 0x114C5}, {0x114C7, 0x114C7}, {0x11580, 0x115AE}, {0x115D8, 0x115DB}, {0x11600, 0x1162F},
    {0x11644, 0x11644}, {0x11680, 0x116AA}, {0x116B8, 0x116B8}, {0x11700, 0x1171A}, {0x11740, 0x11746},
    {0x11800, 0x1182B}, {0x118A0, 0x118DF}, {0x118FF, 0x11906}, {0x11909, 0x11909}, {0x1190C, 0x11913},
    {0x11915, 0x11916}, {0x11918, 0x1192F}, {0x1193F, 0x1193F}, {0x11941, 0x11941}, {0x119A0, 0x119A7},
    {0x119AA, 0x119D0}, {0x119E1, 0x119E1}, {0x119E3, 0x119E3}, {0x11A00, 0x11A00}, {0x11A0B, 0x11A32},
    {0x11A3A, 0x11A3A}, {0x11A50, 0x11A50}, {0x11A5C, 0x11A89}, {0x11A9D, 0x11A9D}, {0x11AB0, 0x11AF8},
    {0x11C00, 0x11C08}, {0x11C0A, 0x11C2E}, {0x11C40, 0x11C40}, {0x11C72, 0x11C8F}, {0x11D00, 0x11D06},
    {0x11D08, 0x11D09}, {0x11D0B, 0x11D30}, {0x11D46, 0x11D46}, {0x11D60, 0x11D65}, {0x11D67, 0x11D68},
    {0x11D6A, 0x11D89}, {0x11D98, 0x11D98}, {0x11EE0, 0x11EF2}, {0x11FB0, 0x11FB0}, {0x12000, 0x12399},
    {0x12480, 0x12543}, {0x12F90, 0x12FF0}, {0x13000, 0x1342E}, {0x14400, 0x14646}, {0x16800, 0x16A38},
    {0x16A40, 0x16A5E}, {0x16A70, 0x16ABE}, {0x16AD0, 0x16AED}, {0x16B00, 0x16B2F}, {0x16B40, 0x16B43},
    {0x16B63, 0x16B77}, {0x16B7D, 0x16B8F}, {0x16E40, 0x16E7F}, {0x16F00, 0x16F4A}, {0x16F50, 0x16F50},
    {0x16F93, 0x16F9F}, {0x16FE0, 0x16FE1}, {0x16FE3, 0x16FE3}, {0x17000, 0x187F7}, {0x18800, 0x18CD5},
    {0x18D00, 0x18D08}, {0x1AFF0, 0x1AFF3}, {0x1AFF5, 0x1AFFB}, {0x1AFFD, 0x1AFFE}, {0x1B000, 0x1B122},
    {0x1B150, 0x1B152}, {0x1B164, 0x1B167}, {0x1B170, 0x1B2FB}, {0x1BC00, 0x1BC6A}, {0x1BC70, 0x1BC7C},
    {0x1BC80, 0x1BC88}, {0x1BC90, 0x1BC99}, {0x1D400, 0x1D454}, {0x1D456, 0x1D49C}, {0x1D49E, 0x1D49F},
    {0x1D4A2, 0x1D4A2}, {0x1D4A5, 0x1D4A6}, {0x1D4A9, 0x1D4AC}, {0x1D4AE, 0x1D4B9}, {0x1D4BB, 0x1D4BB},
    {0x1D4BD, 0x1D4C3}, {0x1D4C5, 0x1D505}, {0x1D507, 0x1D50A}, {0x1D50D, 0x1D514}, {0x1D516, 0x1D51C},
    {0x1D51E, 0x1D539}, {0x1D53B, 0x1D53E}, {0x1D540, 0x1D544}, {0x1D546, 0x1D546}, {0x1D54A, 0x1D550},
    {0x1D552, 0x1D6A5}, {0x1D6A8, 0x1D6C0}, {0x1D6C2, 0x1D6DA}, {0x1D6DC, 0x1D6FA}, {0x1D6FC, 0x1D714},
    {0x1D716, 0x1D734}, {0x1D736, 0x1D74E}, {0x1D750, 0x1D76E}, {0x1D770, 0x1D788}, {0x1D78A, 0x1D7A8},
    {0x1D7AA, 0x1D7C2}, {0x1D7C4, 0x1D7CB}, {0x1DF00, 0x1DF1E}, {0x1E100, 0x1E12C}, {0x1E137, 0x1E13D},
    {0x1E14E, 0x1E14E}, {0x1E290, 0x1E2AD}, {0x1E2C0, 0x1E2EB}, {0x1E7E0, 0x1E7E6}, {0x1E7E8, 0x1E7EB},
    {0x1E7ED, 0x1E7EE}, {0x1E7F0, 0x1E7FE}, {0x1E800, 0x1E8C4}, {0x1E900, 0x1E943}, {0x1E94B, 0x1E94B},
    {0x1EE00, 0x1EE03}, {0x1EE05, 0x1EE1F}, {0x1EE21, 0x1EE22}, {0x1EE24, 0x1EE24}, {0x1EE27, 0x1EE27},
    {0x1EE29, 0x1EE32}, {0x1EE34, 0x1EE37}, {0x1EE39, 0x1EE39}, {0x1EE3B, 0x1EE3B}, {0x1EE42, 0x1EE42},
    {0x1EE47, 0x1EE47}, {0x1EE49, 0x1EE49}, {0x1EE4B, 0x1EE4B}, {0x1EE4D, 0x1EE4F}, {0x1EE51, 0x1EE52},
    {0x1EE54, 0x1EE54}, {0x1EE57, 0x1EE57}, {0x1EE59, 0x1EE59}, {0x1EE5B, 0x1EE5B}, {0x1EE5D, 0x1EE5D},
    {0x1EE5F, 0x1EE5F}, {0x1EE61, 0x1EE62}, {0x1EE64, 0x1EE64}, {0x1EE67, 0x1EE6A}, {0x1EE6C, 0x1EE72},
    {0x1EE74, 0x1EE77}, {0x1EE79, 0x1EE7C}, {0x1EE7E, 0x1EE7E}, {0x1EE80, 0x1EE89}, {0x1EE8B, 0x1EE9B},
    {0x1EEA1, 0x1EEA3}, {0x1EEA5, 0x1EEA9}, {0x1EEAB, 0x1EEBB}, {0x20000, 0x2A6DF}, {0x2A700, 0x2B738},
    {0x2B740, 0x2B81D}, {0x2B820, 0x2CEA1}, {0x2CEB0, 0x2EBE0}, {0x2F800, 0x2FA1D}, {0x30000, 0x3134A},
};

/* \p{N}: categories Nd Nl No. */
static const cp_range number_ranges[] = {
    {0x30, 0x39}, {0xB2, 0xB3}, {0xB9, 0xB9}, {0xBC, 0xBE}, {0x660, 0x669}, {0x6F0, 0x6F9}, {0x7C0, 0x7C9},
    {0x966, 0x96F}, {0x9E6, 0x9EF}, {0x9F4, 0x9F9}, {0xA66, 0xA6F}, {0xAE6, 0xAEF}, {0xB66, 0xB6F}, {0xB72, 0xB77},
    {0xBE6, 0xBF2}, {0xC66, 0xC6F}, {0xC78, 0xC7E}, {0xCE6, 0xCEF}, {0xD58, 0xD5E}, {0xD66, 0xD78}, {0xDE6, 0xDEF},
    {0xE50, 0xE59}, {0xED0, 0xED9}, {0xF20, 0xF33}, {0x1040, 0x1049}, {0x1090, 0x1099}, {0x1369, 0x137C},
    {0x16EE, 0x16F0}, {0x17E0, 0x17E9}, {0x17F0, 0x17F9}, {0x1810, 0x1819}, {0x1946, 0x194F}, {0x19D0, 0x19DA},
    {0x1A80, 0x1A89}, {0x1A90, 0x1A99}, {0x1B50, 0x1B59}, {0x1BB0, 0x1BB9}, {0x1C40, 0x1C49}, {0x1C50, 0x1C59},
    {0x2070, 0x2070}, {0x2074, 0x2079}, {0x2080, 0x2089}, {0x2150, 0x2182}, {0x2185, 0x2189}, {0x2460, 0x249B},
    {0x24EA, 0x24FF}, {0x2776, 0x2793}, {0x2CFD, 0x2CFD}, {0x3007, 0x3007}, {0x3021, 0x3029}, {0x3038, 0x303A},
    {0x3192, 0x3195}, {0x3220, 0x3229}, {0x3248, 0x324F}, {0x3251, 0x325F}, {0x3280, 0x3289}, {0x32B1, 0x32BF},
    {0xA620, 0xA629}, {0xA6E6, 0xA6EF}, {0xA830, 0xA835}, {0xA8D0, 0xA8D9}, {0xA900, 0xA909}, {0xA9D0, 0xA9D9},
    {0xA9F0, 0xA9F9}, {0xAA50, 0xAA59}, {0xABF0, 0xABF9}, {0xFF10, 0xFF19}, {0x10107, 0x10133}, {0x10140, 0x10178},
    {0x1018A, 0x1018B}, {0x102E1, 0x102FB}, {0x10320, 0x10323}, {0x10341, 0x10341}, {0x1034A, 0x1034A},
    {0x103D1, 0x103D5}, {0x104A0, 0x104A9}, {0x10858, 0x1085F}, {0x10879, 0x1087F}, {0x108A7, 0x108AF},
    {0x108FB, 0x108FF}, {0x10916, 0x1091B}, {0x109BC, 0x109BD}, {0x109C0, 0x109CF}, {0x109D2, 0x109FF},
    {0x10A40, 0x10A48}, {0x10A7D, 0x10A7E}, {0x10A9D, 0x10A9F}, {0x10AEB, 0x10AEF}, {0x10B58, 0x10B5F},
    {0x10B78, 0x10B7F}, {0x10BA9, 0x10BAF}, {0x10CFA, 0x10CFF}, {0x10D30, 0x10D39}, {0x10E60, 0x10E7E},
    {0x10F1D, 0x10F26}, {0x10F51, 0x10F54}, {0x10FC5, 0x10FCB}, {0x11052, 0x1106F}, {0x110F0, 0x110F9},
    {0x11136, 0x1113F}, {0x111D0, 0x111D9}, {0x111E1, 0x111F4}, {0x112F0, 0x112F9}, {0x11450, 0x11459},
    {0x114D0, 0x114D9}, {0x11650, 0x11659}, {0x116C0, 0x116C9}, {0x11730, 0x1173B}, {0x118E0, 0x118F2},
    {0x11950, 0x11959}, {0x11C50, 0x11C6C}, {0x11D50, 0x11D59}, {0x11DA0, 0x11DA9}, {0x11FC0, 0x11FD4},
    {0x12400, 0x1246E}, {0x16A60, 0x16A69}, {0x16AC0, 0x16AC9}, {0x16B50, 0x16B59}, {0x16B5B, 0x16B61},
    {0x16E80, 0x16E96}, {0x1D2E0, 0x1D2F3}, {0x1D360, 0x1D378}, {0x1D7CE, 0x1D7FF}, {0x1E140, 0x1E149},
    {0x1E2F0, 0x1E2F9}, {0x1E8C7, 0x1E8CF}, {0x1E950, 0x1E959}, {0x1EC71, 0x1ECAB}, {0x1ECAD, 0x1ECAF},
    {0x1ECB1, 0x1ECB4}, {0x1ED01, 0x1ED2D}, {0x1ED2F, 0x1ED3D}, {0x1F100, 0x1F10C}, {0x1FBF0, 0x1FBF9},
};

/* Categories Cc and Cf (BasicTokenizer's _is_control, before its \t \n \r exception). */
static const cp_range control_ranges[] = {
    {0x0, 0x1F}, {0x7F, 0x9F}, {0xAD, 0xAD}, {0x600, 0x605}, {0x61C, 0x61C}, {0x6DD, 0x6DD}, {0x70F, 0x70F},
    {0x890, 0x891}, {0x8E2, 0x8E2}, {0x180E, 0x180E}, {0x200B, 0x200F}, {0x202A, 0x202E}, {0x2060, 0x2064},
    {0x2066, 0x206F}, {0xFEFF, 0xFEFF}, {0xFFF9, 0xFFFB}, {0x110BD, 0x110BD}, {0x110CD, 0x110CD}, {0x13430, 0x13438},
    {0x1BCA0, 0x1BCA3}, {0x1D173, 0x1D17A}, {0xE0001, 0xE0001}, {0xE0020, 0xE007F},
};

/* str.lower() for single code points: runs lo..hi (every `stride`-th code point) map to cp + delta. */
static const lower_run lower_runs[] = {
    {0xC0, 0xD6, 32, 1}, {0xD8, 0xDE, 32, 1}, {0x100, 0x12E, 1, 2}, {0x132, 0x136, 1, 2}, {0x139, 0x147, 1, 2},
    {0x14A, 0x176, 1, 2}, {0x178, 0x178, -121, 1}, {0x179, 0x17D, 1, 2}, {0x181, 0x181, 210, 1}, {0x182, 0x184, 1, 2},
    {0x186, 0x186, 206, 1}, {0x187, 0x187, 1, 1}, {0x189, 0x18A, 205, 1}, {0x18B, 0x18B, 1, 1}, {0x18E, 0x18E, 79, 1},
    {0x18F, 0x18F, 202, 1}, {0x190, 0x190, 203, 1}, {0x191, 0x191, 1, 1}, {0x193, 0x193, 205, 1},
    {0x194, 0x194, 207, 1}, {0x196, 0x196, 211, 1}, {0x197, 0x197, 209, 1}, {0x198, 0x198, 1, 1},
    {0x19C, 0x19C, 211, 1}, {0x19D, 0x19D, 213, 1}, {0x19F, 0x19F, 214, 1}, {0x1A0, 0x1A4, 1, 2},
    {0x1A6, 0x1A6, 218, 1}, {0x1A7, 0x1A7, 1, 1}, {0x1A9, 0x1A9, 218, 1}, {0x1AC, 0x1AC, 1, 1},
    {0x1AE, 0x1AE, 218, 1}, {0x1AF, 0x1AF, 1, 1}, {0x1B1, 0x1B2, 217, 1}, {0x1B3, 0x1B5, 1, 2},
    {0x1B7, 0x1B7, 219, 1}, {0x1B8, 0x1B8, 1, 1}, {0x1BC, 0x1BC, 1, 1}, {0x1C4, 0x1C4, 2, 1}, {0x1C5, 0x1C5, 1, 1},
    {0x1C7, 0x1C7, 2, 1}, {0x1C8, 0x1C8, 1, 1}, {0x1CA, 0x1CA, 2, 1}, {0x1CB, 0x1DB, 1, 2}, {0x1DE, 0x1EE, 1, 2},
    {0x1F1, 0x1F1, 2, 1}, {0x1F2, 0x1F4, 1, 2}, {0x1F6, 0x1F6, -97, 1}, {0x1F7, 0x1F7, -56, 1}, {0x1F8, 0x21E, 1, 2},
    {0x220, 0x220, -130, 1}, {0x222, 0x232, 1, 2}, {0x23A, 0x23A, 10795, 1}, {0x23B, 0x23B, 1, 1},
    {0x23D, 0x23D, -163, 1}, {0x23E, 0x23E, 10792, 1}, {0x241, 0x241, 1, 1}, {0x243, 0x243, -195, 1},
    {0x244, 0x244, 69, 1}, {0x245, 0x245, 71, 1}, {0x246, 0x24E, 1, 2}, {0x370, 0x372, 1, 2}, {0x376, 0x376, 1, 1},
    {0x37F, 0x37F, 116, 1}, {0x386, 0x386, 38, 1}, {0x388, 0x38A, 37, 1}, {0x38C, 0x38C, 64, 1},
    {0x38E, 0x38F, 63, 1}, {0x391, 0x3A1, 32, 1}, {0x3A3, 0x3AB, 32, 1}, {0x3CF, 0x3CF, 8, 1}, {0x3D8, 0x3EE, 1, 2},
    {0x3F4, 0x3F4, -60, 1}, {0x3F7, 0x3F7, 1, 1}, {0x3F9, 0x3F9, -7, 1}, {0x3FA, 0x3FA, 1, 1},
    {0x3FD, 0x3FF, -130, 1}, {0x400, 0x40F, 80, 1}, {0x410, 0x42F, 32, 1}, {0x460, 0x480, 1, 2}, {0x48A, 0x4BE, 1, 2},
    {0x4C0, 0x4C0, 15, 1}, {0x4C1, 0x4CD, 1, 2}, {0x4D0, 0x52E, 1, 2}, {0x531, 0x556, 48, 1},
    {0x10A0, 0x10C5, 7264, 1}, {0x10C7, 0x10C7, 7264, 1}, {0x10CD, 0x10CD, 7264, 1}, {0x13A0, 0x13EF, 38864, 1},
    {0x13F0, 0x13F5, 8, 1}, {0x1C90, 0x1CBA, -3008, 1}, {0x1CBD, 0x1CBF, -3008, 1}, {0x1E00, 0x1E94, 1, 2},
    {0x1E9E, 0x1E9E, -7615, 1}, {0x1EA0, 0x1EFE, 1, 2}, {0x1F08, 0x1F0F, -8, 1}, {0x1F18, 0x1F1D, -8, 1},
    {0x1F28, 0x1F2F, -8, 1}, {0x1F38, 0x1F3F, -8, 1}, {0x1F48, 0x1F4D, -8, 1}, {0x1F59, 0x1F5F, -8, 2},
    {0x1F68, 0x1F6F, -8, 1}, {0x1F88, 0x1F8F, -8, 1}, {0x1F98, 0x1F9F, -8, 1}, {0x1FA8, 0x1FAF, -8, 1},
    {0x1FB8, 0x1FB9, -8, 1}, {0x1FBA, 0x1FBB, -74, 1}, {0x1FBC, 0x1FBC, -9, 1}, {0x1FC8, 0x1FCB, -86, 1},
    {0x1FCC, 0x1FCC, -9, 1}, {0x1FD8, 0x1FD9, -8, 1}, {0x1FDA, 0x1FDB, -100, 1}, {0x1FE8, 0x1FE9, -8, 1},
    {0x1FEA, 0x1FEB, -112, 1}, {0x1FEC, 0x1FEC, -7, 1}, {0x1FF8, 0x1FF9, -128, 1}, {0x1FFA, 0x1FFB, -126, 1},
    {0x1FFC, 0x1FFC, -9, 1}, {0x2126, 0x2126, -7517, 1}, {0x212A, 0x212A, -8383, 1}, {0x212B, 0x212B, -8262, 1},
    {0x2132, 0x2132, 28, 1}, {0x2160, 0x216F, 16, 1}, {0x2183, 0x2183, 1, 1}, {0x24B6, 0x24CF, 26, 1},
    {0x2C00, 0x2C2F, 48, 1}, {0x2C60, 0x2C60, 1, 1}, {0x2C62, 0x2C62, -10743, 1}, {0x2C63, 0x2C63, -3814, 1},
    {0x2C64, 0x2C64, -10727, 1}, {0x2C67, 0x2C6B, 1, 2}, {0x2C6D, 0x2C6D, -10780, 1}, {0x2C6E, 0x2C6E, -10749, 1},
    {0x2C6F, 0x2C6F, -10783, 1}, {0x2C70, 0x2C70, -10782, 1}, {0x2C72, 0x2C72, 1, 1}, {0x2C75, 0x2C75, 1, 1},
    {0x2C7E, 0x2C7F, -10815, 1}, {0x2C80, 0x2CE2, 1, 2}, {0x2CEB, 0x2CED, 1, 2}, {0x2CF2, 0x2CF2, 1, 1},
    {0xA640, 0xA66C, 1, 2}, {0xA680, 0xA69A, 1, 2}, {0xA722, 0xA72E, 1, 2}, {0xA732, 0xA76E, 1, 2},
    {0xA779, 0xA77B, 1, 2}, {0xA77D, 0xA77D, -35332, 1}, {0xA77E, 0xA786, 1, 2}, {0xA78B, 0xA78B, 1, 1},
    {0xA78D, 0xA78D, -42280, 1}, {0xA790, 0xA792, 1, 2}, {0xA796, 0xA7A8, 1, 2}, {0xA7AA, 0xA7AA, -42308, 1},
    {0xA7AB, 0xA7AB, -42319, 1}, {0xA7AC, 0xA7AC, -42315, 1}, {0xA7AD, 0xA7AD, -42305, 1},
    {0xA7AE, 0xA7AE, -42308, 1}, {0xA7B0, 0xA7B0, -42258, 1}, {0xA7B1, 0xA7B1, -42282, 1},
    {0xA7B2, 0xA7B2, -42261, 1}, {0xA7B3, 0xA7B3, 928, 1}, {0xA7B4, 0xA7C2, 1, 2}, {0xA7C4, 0xA7C4, -48, 1},
    {0xA7C5, 0xA7C5, -42307, 1}, {0xA7C6, 0xA7C6, -35384, 1}, {0xA7C7, 0xA7C9, 1, 2}, {0xA7D0, 0xA7D0, 1, 1},
    {0xA7D6, 0xA7D8, 1, 2}, {0xA7F5, 0xA7F5, 1, 1}, {0xFF21, 0xFF3A, 32, 1}, {0x10400, 0x10427, 40, 1},
    {0x104B0, 0x104D3, 40, 1}, {0x10570, 0x1057A, 39, 1}, {0x1057C, 0x1058A, 39, 1}, {0x1058C, 0x10592, 39, 1},
    {0x10594, 0x10595, 39, 1}, {0x10C80, 0x10CB2, 64, 1}, {0x118A0, 0x118BF, 32, 1}, {0x16E40, 0x16E5F, 32, 1},
    {0x1E900, 0x1E921, 34, 1},
};

#define N_ITEMS(a) (sizeof(a) / sizeof((a)[0]))

static int in_ranges(unsigned cp, const cp_range *r, size_t n) {
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        if (cp < r[mid].lo)
            hi = mid;
        else if (cp > r[mid].hi)
            lo = mid + 1;
        else
            return 1;
    }
    return 0;
}

static int is_letter(unsigned cp) { return in_ranges(cp, letter_ranges, N_ITEMS(letter_ranges)); }
static int is_number(unsigned cp) { return in_ranges(cp, number_ranges, N_ITEMS(number_ranges)); }

/* BasicTokenizer's _is_whitespace: space, \t, \n, \r and category Zs. */
static int is_space(unsigned cp) {
    return cp == ' ' || cp == '\t' || cp == '\n' || cp == '\r' || cp == 0xA0 || cp == 0x1680 ||
           (cp >= 0x2000 && cp <= 0x200A) || cp == 0x202F || cp == 0x205F || cp == 0x3000;
}

/* BasicTokenizer's _is_control: categories Cc and Cf, but \t \n \r (whitespace). */
static int is_control(unsigned cp) {
    if (cp == '\t' || cp == '\n' || cp == '\r') return 0;
    return in_ranges(cp, control_ranges, N_ITEMS(control_ranges));
}

/* BasicTokenizer's _is_chinese_char: the CJK ideograph blocks (not kana or Hangul). */
static int is_cjk(unsigned cp) {
    return (cp >= 0x4E00 && cp <= 0x9FFF) || (cp >= 0x3400 && cp <= 0x4DBF) || (cp >= 0x20000 && cp <= 0x2A6DF) ||
           (cp >= 0x2A700 && cp <= 0x2B73F) || (cp >= 0x2B740 && cp <= 0x2B81F) ||
           (cp >= 0x2B820 && cp <= 0x2CEAF) || (cp >= 0xF900 && cp <= 0xFAFF) || (cp >= 0x2F800 && cp <= 0x2FA1F);
}

/* str.lower() of one code point, when that is one code point (U+0130 is handled by the caller). */
static unsigned to_lower(unsigned cp) {
    if (cp < 0x80) return (cp >= 'A' && cp <= 'Z') ? cp + 32 : cp;
    size_t lo = 0, hi = N_ITEMS(lower_runs);
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        const lower_run *r = &lower_runs[mid];
        if (cp < r->lo)
            hi = mid;
        else if (cp > r->hi)
            lo = mid + 1;
        else
            return (cp - r->lo) % (unsigned)r->stride == 0 ? (unsigned)((int)cp + r->delta) : cp;
    }
    return cp;
}

/* Step 1: the cleaned, lower-cased text as code points, with single spaces between words
 * (leading/trailing spaces are harmless: the pattern never matches a space). */
static unsigned *clean_text(const char *text, size_t *out_n, mx_status *st) {
    size_t len = strlen(text);
    /* at most one code point per byte: a CJK ideograph (3-4 bytes) becomes 3 */
    unsigned *cps = malloc(sizeof(unsigned) * (len + 1));
    if (!cps) return mx_fail(st, MX_ENOMEM, "tokenizer: out of memory for a %zu-byte prompt", len), NULL;
    size_t n = 0;
    for (size_t i = 0; i < len;) {
        uint32_t cp;
        i += mx_utf8_decode((const unsigned char *)text + i, len - i, &cp);
        if (cp == 0 || cp == 0xFFFD || is_control(cp)) continue;
        if (is_space(cp)) {
            cps[n++] = ' ';
        } else if (is_cjk(cp)) {
            cps[n++] = ' ';
            cps[n++] = cp;
            cps[n++] = ' ';
        } else if (cp == 0x130) { /* Python lowers U+0130 to "i" + U+0307 */
            cps[n++] = 'i';
            cps[n++] = 0x307;
        } else {
            cps[n++] = to_lower(cp);
        }
    }
    *out_n = n;
    return cps;
}

/* ---- pre-tokenizer and BPE ---- */

typedef enum { CLS_SPACE, CLS_LETTER, CLS_NUMBER, CLS_OTHER } char_class;

static char_class classify(unsigned cp) {
    if (cp == ' ') return CLS_SPACE;
    if (is_letter(cp)) return CLS_LETTER;
    if (is_number(cp)) return CLS_NUMBER;
    return CLS_OTHER;
}

/* Length of an ASCII literal matched at cps[i], or 0. */
static size_t match_literal(const unsigned *cps, size_t n, size_t i, const char *lit) {
    size_t k = 0;
    for (; lit[k]; k++)
        if (i + k >= n || cps[i + k] != (unsigned char)lit[k]) return 0;
    return k;
}

/* Length of the pre-token at cps[i] (cps[i] is not a space); *special = its id when it is
 * <|startoftext|> or <|endoftext|>, else -1. */
static size_t pretoken_at(const unsigned *cps, size_t n, size_t i, int32_t *special) {
    static const char *const contractions[] = {"'s", "'t", "'re", "'ve", "'m", "'ll", "'d"};
    size_t k;
    *special = -1;
    if ((k = match_literal(cps, n, i, "<|startoftext|>"))) {
        *special = MX_CLIP_BOS_ID;
        return k;
    }
    if ((k = match_literal(cps, n, i, "<|endoftext|>"))) {
        *special = MX_CLIP_EOS_ID;
        return k;
    }
    for (size_t c = 0; c < sizeof contractions / sizeof contractions[0]; c++)
        if ((k = match_literal(cps, n, i, contractions[c]))) return k;
    char_class cls = classify(cps[i]);
    if (cls == CLS_NUMBER) return 1;
    for (k = 1; i + k < n && classify(cps[i + k]) == cls; k++) {
    }
    return k;
}

/* Growable output list of token ids. */
typedef struct id_list {
    int32_t *ids;
    size_t n, cap;
} id_list;

static int id_push(id_list *l, int32_t id, mx_status *st) {
    if (l->n == l->cap) {
        size_t cap = l->cap ? l->cap * 2 : 128;
        int32_t *p = realloc(l->ids, cap * sizeof *p);
        if (!p) return mx_fail(st, MX_ENOMEM, "tokenizer: out of memory");
        l->ids = p;
        l->cap = cap;
    }
    l->ids[l->n++] = id;
    return 0;
}

/* BPE over the byte symbols of one pre-token (sym[0..n), rewritten in place); appends the
 * resulting ids. Repeatedly merges every occurrence of the lowest-ranked pair, left to right,
 * exactly as CLIPTokenizer.bpe. */
static int bpe_word(const mx_tokenizer *t, int32_t *sym, size_t n, id_list *out, mx_status *st) {
    while (n > 1) {
        int32_t best_rank = INT32_MAX, best_merged = -1;
        uint64_t best_pair = 0;
        for (size_t i = 0; i + 1 < n; i++) {
            uint64_t pair = ((uint64_t)(uint32_t)sym[i] << 32) | (uint32_t)sym[i + 1];
            const merge_slot *m = merge_slot_for(t, pair);
            if (m->pair == pair && m->rank < best_rank) {
                best_rank = m->rank;
                best_merged = m->merged;
                best_pair = pair;
            }
        }
        if (best_merged < 0) break;
        int32_t a = (int32_t)(best_pair >> 32), b = (int32_t)(uint32_t)best_pair;
        size_t w = 0;
        for (size_t i = 0; i < n; i++) {
            if (i + 1 < n && sym[i] == a && sym[i + 1] == b) {
                sym[w++] = best_merged;
                i++;
            } else {
                sym[w++] = sym[i];
            }
        }
        n = w;
    }
    for (size_t i = 0; i < n; i++)
        if (id_push(out, sym[i], st)) return -1;
    return 0;
}

/* Byte symbols of cps[0..n) as UTF-8, the last byte with "</w>" when `word_end`, then BPE. */
static int encode_piece(const mx_tokenizer *t, const unsigned *cps, size_t n, int word_end, id_list *out,
                        int32_t *sym, mx_status *st) {
    size_t nb = 0;
    char u[4];
    for (size_t i = 0; i < n; i++) {
        size_t k = mx_utf8_encode(cps[i], u);
        for (size_t j = 0; j < k; j++) sym[nb++] = t->byte_id[(unsigned char)u[j]];
    }
    if (word_end) {
        size_t k = mx_utf8_encode(cps[n - 1], u);
        sym[nb - 1] = t->byte_end_id[(unsigned char)u[k - 1]];
    }
    return bpe_word(t, sym, nb, out, st);
}

/* BPE is quadratic in the word length: a hostile prompt with one enormous "word" is cut into
 * pieces of MAX_PIECE code points (only the last ends the word), far beyond any real word. */
#define MAX_PIECE 1024

static int encode_pretoken(const mx_tokenizer *t, const unsigned *cps, size_t n, id_list *out, int32_t *sym,
                           mx_status *st) {
    for (size_t i = 0; i < n; i += MAX_PIECE) {
        size_t k = n - i < MAX_PIECE ? n - i : MAX_PIECE;
        if (encode_piece(t, cps + i, k, i + k == n, out, sym, st)) return -1;
    }
    return 0;
}

/* The cleaned text from cps[i] on, as UTF-8 in out (at most ~40 bytes, "..." when cut). */
static void quote_from(const unsigned *cps, size_t n, size_t i, char *out, size_t cap) {
    size_t len = 0;
    char u[4];
    for (; i < n && len + 4 + 4 < cap && len < 40; i++) {
        size_t k = mx_utf8_encode(cps[i], u);
        memcpy(out + len, u, k);
        len += k;
    }
    if (i < n) memcpy(out + len, "...", 3), len += 3;
    out[len] = 0;
}

static void frame_ids(const id_list *tokens, mx_tok_result *out) {
    int keep = MX_CLIP_CONTEXT - 2;
    int n = tokens->n < (size_t)keep ? (int)tokens->n : keep;
    out->n_dropped = (int)(tokens->n - (size_t)n);
    out->ids[0] = MX_CLIP_BOS_ID;
    for (int i = 0; i < n; i++) out->ids[1 + i] = tokens->ids[i];
    out->ids[1 + n] = MX_CLIP_EOS_ID;
    out->n_tokens = n + 2;
    for (int i = n + 2; i < MX_CLIP_CONTEXT; i++) out->ids[i] = MX_CLIP_EOS_ID;
}

int mx_tok_encode(const mx_tokenizer *t, const char *text, mx_tok_result *out, mx_status *st) {
    size_t n;
    unsigned *cps = clean_text(text, &n, st);
    if (!cps) return -1;
    int32_t *sym = malloc(sizeof(int32_t) * (4 * (n < MAX_PIECE ? n : MAX_PIECE) + 1));
    id_list tokens = {0};
    int rc = -1;
    if (!sym) {
        mx_fail(st, MX_ENOMEM, "tokenizer: out of memory");
        goto done;
    }
    out->dropped_from[0] = 0;
    for (size_t i = 0; i < n && tokens.n < MX_TOK_MAX_COUNTED;) {
        if (cps[i] == ' ') {
            i++;
            continue;
        }
        int32_t special;
        size_t k = pretoken_at(cps, n, i, &special), before = tokens.n;
        if (special >= 0 ? id_push(&tokens, special, st) : encode_pretoken(t, cps + i, k, &tokens, sym, st))
            goto done;
        if (before <= MX_CLIP_CONTEXT - 2 && tokens.n > MX_CLIP_CONTEXT - 2) /* this word is cut */
            quote_from(cps, n, i, out->dropped_from, sizeof out->dropped_from);
        i += k;
    }
    frame_ids(&tokens, out);
    rc = 0;
done:
    free(cps);
    free(sym);
    free(tokens.ids);
    return rc;
}
