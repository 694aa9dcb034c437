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

static size_t utf8_put(unsigned cp, char *out) {
    if (cp < 0x80) {
        out[0] = (char)cp;
        return 1;
    }
    if (cp < 0x800) {
        out[0] = (char)(0xC0 | (cp >> 6));
        out[1] = (char)(0x80 | (cp & 0x3F));
        return 2;
    }
    if (cp < 0x10000) {
        out[0] = (char)(0xE0 | (cp >> 12));
        out[1] = (char)(0x80 | ((cp >> 6) & 0x3F));
        out[2] = (char)(0x80 | (cp & 0x3F));
        return 3;
    }
    out[0] = (char)(0xF0 | (cp >> 18));
    out[1] = (char)(0x80 | ((cp >> 12) & 0x3F));
    out[2] = (char)(0x80 | ((cp >> 6) & 0x3F));
    out[3] = (char)(0x80 | (cp & 0x3F));
    return 4;
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
        size_t n = utf8_put(byte_symbol(b), s);
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

static char *read_file(const char *path, size_t *len, mx_status *st) {
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open", path), NULL;
    char *buf = NULL;
    long n = -1;
    if (fseek(f, 0, SEEK_END) == 0) n = ftell(f);
    if (n < 0 || n > (1L << 30) || fseek(f, 0, SEEK_SET) != 0) {
        mx_fail(st, MX_EINPUT, "%s: cannot determine size (or larger than 1 GiB)", path);
    } else if (!(buf = malloc((size_t)n + 1))) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    } else if (fread(buf, 1, (size_t)n, f) != (size_t)n) {
        mx_fail(st, MX_EIO, "%s: read error", path);
        free(buf);
        buf = NULL;
    } else {
        buf[n] = 0;
        *len = (size_t)n;
    }
    fclose(f);
    return buf;
}

int mx_tok_load_files(mx_tokenizer **out, const char *vocab_path, const char *merges_path, mx_status *st) {
    size_t vl = 0, ml = 0;
    *out = NULL;
    char *v = read_file(vocab_path, &vl, st);
    if (!v) return -1;
    char *m = read_file(merges_path, &ml, st);
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

/* ---- Unicode classes (enough of the tables for the scripts prompts are written in) ---- */

typedef struct cp_range {
    unsigned lo, hi;
} cp_range;

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

/* \p{N}: decimal digits, letter-like and other numbers. Sorted. */
static const cp_range number_ranges[] = {
    {0x30, 0x39},       {0xB2, 0xB3},       {0xB9, 0xB9},       {0xBC, 0xBE},     {0x660, 0x669},
    {0x6F0, 0x6F9},     {0x7C0, 0x7C9},     {0x966, 0x96F},     {0x9E6, 0x9EF},   {0x9F4, 0x9F9},
    {0xA66, 0xA6F},     {0xAE6, 0xAEF},     {0xB66, 0xB6F},     {0xB72, 0xB77},   {0xBE6, 0xBF2},
    {0xC66, 0xC6F},     {0xC78, 0xC7E},     {0xCE6, 0xCEF},     {0xD58, 0xD5E},   {0xD66, 0xD78},
    {0xDE6, 0xDEF},     {0xE50, 0xE59},     {0xED0, 0xED9},     {0xF20, 0xF33},   {0x1040, 0x1049},
    {0x1090, 0x1099},   {0x1369, 0x137C},   {0x16EE, 0x16F0},   {0x17E0, 0x17E9}, {0x17F0, 0x17F9},
    {0x1810, 0x1819},   {0x1946, 0x194F},   {0x19D0, 0x19DA},   {0x1A80, 0x1A99}, {0x1B50, 0x1B59},
    {0x1BB0, 0x1BB9},   {0x1C40, 0x1C49},   {0x1C50, 0x1C59},   {0x2070, 0x2070}, {0x2074, 0x2079},
    {0x2080, 0x2089},   {0x2150, 0x2182},   {0x2185, 0x2189},   {0x2460, 0x249B}, {0x24EA, 0x24FF},
    {0x2776, 0x2793},   {0x2CFD, 0x2CFD},   {0x3007, 0x3007},   {0x3021, 0x3029}, {0x3038, 0x303A},
    {0x3192, 0x3195},   {0x3220, 0x3229},   {0x3248, 0x324F},   {0x3251, 0x325F}, {0x3280, 0x3289},
    {0x32B1, 0x32BF},   {0xA620, 0xA629},   {0xA6E6, 0xA6EF},   {0xA830, 0xA835}, {0xA8D0, 0xA8D9},
    {0xA900, 0xA909},   {0xA9D0, 0xA9D9},   {0xAA50, 0xAA59},   {0xABF0, 0xABF9}, {0xFF10, 0xFF19},
    {0x1D7CE, 0x1D7FF}, {0x1F100, 0x1F10C},
};

/* \p{L}: letters. Combining marks (Mn, Mc) of the Brahmic, Arabic, Hebrew and Thai scripts are
 * left out, as in Unicode: the CLIP pattern splits words at them. Sorted. */
static const cp_range letter_ranges[] = {
    {0x41, 0x5A},       {0x61, 0x7A},       {0xAA, 0xAA},       {0xB5, 0xB5},       {0xBA, 0xBA},
    {0xC0, 0xD6},       {0xD8, 0xF6},       {0xF8, 0x2C1},      {0x2C6, 0x2D1},     {0x2E0, 0x2E4},
    {0x2EC, 0x2EC},     {0x2EE, 0x2EE},     {0x370, 0x374},     {0x376, 0x377},     {0x37A, 0x37D},
    {0x37F, 0x37F},     {0x386, 0x386},     {0x388, 0x38A},     {0x38C, 0x38C},     {0x38E, 0x3A1},
    {0x3A3, 0x3F5},     {0x3F7, 0x481},     {0x48A, 0x52F},     {0x531, 0x556},     {0x559, 0x559},
    {0x560, 0x588},     {0x5D0, 0x5EA},     {0x5EF, 0x5F2},     {0x620, 0x64A},     {0x66E, 0x66F},
    {0x671, 0x6D3},     {0x6D5, 0x6D5},     {0x6E5, 0x6E6},     {0x6EE, 0x6EF},     {0x6FA, 0x6FC},
    {0x6FF, 0x6FF},     {0x710, 0x710},     {0x712, 0x72F},     {0x74D, 0x7A5},     {0x7B1, 0x7B1},
    {0x7CA, 0x7EA},     {0x904, 0x939},     {0x93D, 0x93D},     {0x950, 0x950},     {0x958, 0x961},
    {0x971, 0x980},     {0x985, 0x98C},     {0x98F, 0x990},     {0x993, 0x9A8},     {0x9AA, 0x9B0},
    {0x9B2, 0x9B2},     {0x9B6, 0x9B9},     {0x9BD, 0x9BD},     {0x9CE, 0x9CE},     {0x9DC, 0x9DD},
    {0x9DF, 0x9E1},     {0x9F0, 0x9F1},     {0xA05, 0xA0A},     {0xA0F, 0xA10},     {0xA13, 0xA28},
    {0xA2A, 0xA30},     {0xA32, 0xA33},     {0xA35, 0xA36},     {0xA38, 0xA39},     {0xA59, 0xA5C},
    {0xA5E, 0xA5E},     {0xA72, 0xA74},     {0xA85, 0xA8D},     {0xA8F, 0xA91},     {0xA93, 0xAA8},
    {0xAAA, 0xAB0},     {0xAB2, 0xAB3},     {0xAB5, 0xAB9},     {0xABD, 0xABD},     {0xAD0, 0xAD0},
    {0xAE0, 0xAE1},     {0xB05, 0xB0C},     {0xB0F, 0xB10},     {0xB13, 0xB28},     {0xB2A, 0xB30},
    {0xB32, 0xB33},     {0xB35, 0xB39},     {0xB3D, 0xB3D},     {0xB5C, 0xB5D},     {0xB5F, 0xB61},
    {0xB83, 0xB83},     {0xB85, 0xB8A},     {0xB8E, 0xB90},     {0xB92, 0xB95},     {0xB99, 0xB9F},
    {0xBA3, 0xBA4},     {0xBA8, 0xBAA},     {0xBAE, 0xBB9},     {0xBD0, 0xBD0},     {0xC05, 0xC39},
    {0xC3D, 0xC3D},     {0xC58, 0xC5A},     {0xC60, 0xC61},     {0xC80, 0xC80},     {0xC85, 0xCB9},
    {0xCBD, 0xCBD},     {0xCDE, 0xCE1},     {0xCF1, 0xCF2},     {0xD04, 0xD3A},     {0xD3D, 0xD3D},
    {0xD4E, 0xD4E},     {0xD54, 0xD56},     {0xD5F, 0xD61},     {0xD7A, 0xD7F},     {0xD85, 0xDC6},
    {0xE01, 0xE30},     {0xE32, 0xE33},     {0xE40, 0xE46},     {0xE81, 0xEB0},     {0xEB2, 0xEB3},
    {0xEBD, 0xEC6},     {0xEDC, 0xEDF},     {0xF00, 0xF00},     {0xF40, 0xF6C},     {0xF88, 0xF8C},
    {0x1000, 0x102A},   {0x103F, 0x103F},   {0x1050, 0x1055},   {0x10A0, 0x10FF},   {0x1100, 0x1248},
    {0x124A, 0x135A},   {0x1380, 0x138F},   {0x13A0, 0x13FD},   {0x1401, 0x166C},   {0x166F, 0x169A},
    {0x16A0, 0x16EA},   {0x1780, 0x17B3},   {0x17D7, 0x17D7},   {0x17DC, 0x17DC},   {0x1820, 0x1878},
    {0x1C80, 0x1C88},   {0x1C90, 0x1CBF},   {0x1D00, 0x1DBF},   {0x1E00, 0x1F15},   {0x1F18, 0x1F1D},
    {0x1F20, 0x1F45},   {0x1F48, 0x1F4D},   {0x1F50, 0x1F57},   {0x1F59, 0x1F7D},   {0x1F80, 0x1FBC},
    {0x1FBE, 0x1FBE},   {0x1FC2, 0x1FCC},   {0x1FD0, 0x1FDB},   {0x1FE0, 0x1FEC},   {0x1FF2, 0x1FFC},
    {0x2071, 0x2071},   {0x207F, 0x207F},   {0x2090, 0x209C},   {0x2102, 0x2102},   {0x2107, 0x2107},
    {0x210A, 0x2113},   {0x2115, 0x2115},   {0x2119, 0x211D},   {0x2124, 0x2124},   {0x2126, 0x2126},
    {0x2128, 0x2128},   {0x212A, 0x212D},   {0x212F, 0x2139},   {0x213C, 0x213F},   {0x2145, 0x2149},
    {0x214E, 0x214E},   {0x2183, 0x2184},   {0x2C00, 0x2CE4},   {0x2CEB, 0x2CEE},   {0x2D00, 0x2D25},
    {0x2D30, 0x2D67},   {0x2D80, 0x2DDE},   {0x3005, 0x3006},   {0x3031, 0x3035},   {0x303B, 0x303C},
    {0x3041, 0x3096},   {0x309D, 0x309F},   {0x30A1, 0x30FA},   {0x30FC, 0x30FF},   {0x3105, 0x312F},
    {0x3131, 0x318E},   {0x31A0, 0x31BF},   {0x31F0, 0x31FF},   {0x3400, 0x4DBF},   {0x4E00, 0x9FFF},
    {0xA000, 0xA48C},   {0xA4D0, 0xA4FD},   {0xA500, 0xA60C},   {0xA610, 0xA61F},   {0xA640, 0xA66E},
    {0xA67F, 0xA69D},   {0xA6A0, 0xA6E5},   {0xA717, 0xA71F},   {0xA722, 0xA788},   {0xA78B, 0xA7FF},
    {0xAC00, 0xD7A3},   {0xD7B0, 0xD7FB},   {0xF900, 0xFAFF},   {0xFB00, 0xFB06},   {0xFB13, 0xFB17},
    {0xFB1D, 0xFB1D},   {0xFB1F, 0xFB28},   {0xFB2A, 0xFB4F},   {0xFB50, 0xFDFB},   {0xFE70, 0xFEFC},
    {0xFF21, 0xFF3A},   {0xFF41, 0xFF5A},   {0xFF66, 0xFFBE},   {0xFFC2, 0xFFDC},   {0x10000, 0x100FA},
    {0x10400, 0x1049D}, {0x1D400, 0x1D7CB}, {0x1E900, 0x1E943}, {0x20000, 0x2FA1F}, {0x30000, 0x3134A},
};

#define N_RANGES(a) (sizeof(a) / sizeof((a)[0]))

static int is_letter(unsigned cp) { return in_ranges(cp, letter_ranges, N_RANGES(letter_ranges)); }
static int is_number(unsigned cp) { return in_ranges(cp, number_ranges, N_RANGES(number_ranges)); }

/* BasicTokenizer's _is_whitespace: space, \t, \n, \r and category Zs. */
static int is_space(unsigned cp) {
    return cp == ' ' || cp == '\t' || cp == '\n' || cp == '\r' || cp == 0xA0 || cp == 0x1680 ||
           (cp >= 0x2000 && cp <= 0x200A) || cp == 0x202F || cp == 0x205F || cp == 0x3000;
}

/* Categories Cc and Cf (but \t \n \r, which are whitespace). */
static int is_control(unsigned cp) {
    if (cp == '\t' || cp == '\n' || cp == '\r') return 0;
    return cp < 0x20 || (cp >= 0x7F && cp <= 0x9F) || cp == 0xAD || (cp >= 0x600 && cp <= 0x605) ||
           cp == 0x61C || cp == 0x6DD || cp == 0x70F || cp == 0x180E || (cp >= 0x200B && cp <= 0x200F) ||
           (cp >= 0x202A && cp <= 0x202E) || (cp >= 0x2060 && cp <= 0x2064) || (cp >= 0x2066 && cp <= 0x206F) ||
           cp == 0xFEFF || (cp >= 0xFFF9 && cp <= 0xFFFB) || cp == 0x110BD || (cp >= 0x1BCA0 && cp <= 0x1BCA3) ||
           (cp >= 0x1D173 && cp <= 0x1D17A) || cp == 0xE0001 || (cp >= 0xE0020 && cp <= 0xE007F);
}

/* BasicTokenizer's _is_chinese_char: the CJK ideograph blocks (not kana or Hangul). */
static int is_cjk(unsigned cp) {
    return (cp >= 0x4E00 && cp <= 0x9FFF) || (cp >= 0x3400 && cp <= 0x4DBF) || (cp >= 0x20000 && cp <= 0x2A6DF) ||
           (cp >= 0x2A700 && cp <= 0x2B73F) || (cp >= 0x2B740 && cp <= 0x2B81F) ||
           (cp >= 0x2B820 && cp <= 0x2CEAF) || (cp >= 0xF900 && cp <= 0xFAFF) || (cp >= 0x2F800 && cp <= 0x2FA1F);
}

/* str.lower() for the cased scripts (one code point to one; the rare expanding cases of
 * Python's full mapping, like U+0130, map to their simple lower case). */
static unsigned to_lower(unsigned cp) {
    if (cp < 0x80) return (cp >= 'A' && cp <= 'Z') ? cp + 32 : cp;
    if ((cp >= 0xC0 && cp <= 0xDE && cp != 0xD7)) return cp + 32;
    if (cp >= 0x100 && cp <= 0x17F) {
        if (cp == 0x130) return 'i';
        if (cp == 0x178) return 0xFF;
        if ((cp >= 0x139 && cp <= 0x148) || (cp >= 0x179 && cp <= 0x17E)) return (cp & 1) ? cp + 1 : cp;
        if (cp == 0x138 || cp == 0x149 || cp == 0x17F) return cp;
        return (cp & 1) ? cp : cp + 1;
    }
    if (cp >= 0x391 && cp <= 0x3AB && cp != 0x3A2) return cp + 32;
    if (cp == 0x386) return 0x3AC;
    if (cp >= 0x388 && cp <= 0x38A) return cp + 37;
    if (cp == 0x38C) return 0x3CC;
    if (cp == 0x38E || cp == 0x38F) return cp + 63;
    if (cp >= 0x400 && cp <= 0x40F) return cp + 80;
    if (cp >= 0x410 && cp <= 0x42F) return cp + 32;
    if ((cp >= 0x460 && cp <= 0x481) || (cp >= 0x48A && cp <= 0x4BF) || (cp >= 0x4D0 && cp <= 0x52F))
        return (cp & 1) ? cp : cp + 1;
    if (cp >= 0x531 && cp <= 0x556) return cp + 48;
    if (cp >= 0x1E00 && cp <= 0x1EFF && !(cp >= 0x1E96 && cp <= 0x1E9F)) return (cp & 1) ? cp : cp + 1;
    if (cp >= 0x2160 && cp <= 0x216F) return cp + 16;
    if (cp >= 0x24B6 && cp <= 0x24CF) return cp + 26;
    if (cp >= 0xFF21 && cp <= 0xFF3A) return cp + 32;
    return cp;
}

/* Decodes one UTF-8 sequence at s (n bytes left); returns its length, *cp = 0xFFFD when invalid. */
static size_t utf8_get(const unsigned char *s, size_t n, unsigned *cp) {
    unsigned c = s[0];
    size_t len = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : (c >> 3) == 30 ? 4 : 0;
    *cp = 0xFFFD;
    if (len == 0 || len > n) return 1;
    unsigned v = len == 1 ? c : len == 2 ? (c & 0x1F) : len == 3 ? (c & 0x0F) : (c & 0x07);
    for (size_t i = 1; i < len; i++) {
        if ((s[i] & 0xC0) != 0x80) return 1;
        v = (v << 6) | (s[i] & 0x3F);
    }
    static const unsigned min_for_len[5] = {0, 0, 0x80, 0x800, 0x10000};
    if (v < min_for_len[len] || v > 0x10FFFF || (v >= 0xD800 && v <= 0xDFFF)) return 1;
    *cp = v;
    return len;
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
        unsigned cp;
        i += utf8_get((const unsigned char *)text + i, len - i, &cp);
        if (cp == 0 || cp == 0xFFFD || is_control(cp)) continue;
        if (is_space(cp)) {
            cps[n++] = ' ';
        } else if (is_cjk(cp)) {
            cps[n++] = ' ';
            cps[n++] = cp;
            cps[n++] = ' ';
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
        size_t k = utf8_put(cps[i], u);
        for (size_t j = 0; j < k; j++) sym[nb++] = t->byte_id[(unsigned char)u[j]];
    }
    if (word_end) {
        size_t k = utf8_put(cps[n - 1], u);
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
    for (size_t i = 0; i < n && tokens.n < MX_TOK_MAX_COUNTED;) {
        if (cps[i] == ' ') {
            i++;
            continue;
        }
        int32_t special;
        size_t k = pretoken_at(cps, n, i, &special);
        if (special >= 0 ? id_push(&tokens, special, st) : encode_pretoken(t, cps + i, k, &tokens, sym, st))
            goto done;
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
