/* JSON reader (RFC 8259): a recursive-descent parser bounded by a depth limit, building a
 * tree whose nodes, strings and child arrays live in a chain of memory blocks owned by the
 * root, so mx_json_free releases everything at once. Errors carry the source name and byte
 * offset. Strict (no comments, no trailing commas, UTF-8 validated) except that NaN, Infinity
 * and -Infinity are read, as Python's json module writes them. */
#include "json.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define JSON_MAX_DEPTH 256
#define JSON_BLOCK_MIN 4096

struct mx_json {
    mx_json_type type;
    size_t n; /* string length (bytes, without NUL) or number of children */
    union {
        double num;
        int b;
        char *str;
        struct {
            mx_json **vals;
            char **keys; /* objects only */
        } c;
    } u;
};

typedef struct json_block {
    struct json_block *next;
    size_t used, cap;
    max_align_t data[]; /* cap bytes follow */
} json_block;

/* The root node is the first member, so mx_json_free can recover the document from it. */
typedef struct json_doc {
    mx_json root;
    json_block *blocks;
} json_doc;

typedef struct {
    const char *s;
    size_t len, pos;
    const char *what;
    mx_status *st;
    json_doc *doc;
    /* Scratch stack for the children of open containers: copied into the blocks when a
     * container closes, so each container's child array is exactly sized. */
    mx_json **stack_vals;
    char **stack_keys;
    size_t stack_len, stack_cap;
    /* Scratch buffer for decoding one string. */
    char *sbuf;
    size_t sbuf_cap;
} parser;

static int perr(parser *p, const char *msg) {
    return mx_fail(p->st, MX_EINPUT, "%s: invalid JSON at byte %zu: %s", p->what ? p->what : "<json>", p->pos,
                   msg);
}

static void *doc_alloc(parser *p, size_t size) {
    size = (size + sizeof(max_align_t) - 1) / sizeof(max_align_t) * sizeof(max_align_t);
    json_block *b = p->doc->blocks;
    if (!b || b->cap - b->used < size) {
        size_t cap = size > JSON_BLOCK_MIN ? size : JSON_BLOCK_MIN;
        if (b && b->cap * 2 > cap && b->cap < ((size_t)1 << 24)) cap = b->cap * 2;
        json_block *nb = malloc(sizeof *nb + cap);
        if (!nb) {
            mx_fail(p->st, MX_ENOMEM, "%s: out of memory parsing JSON", p->what ? p->what : "<json>");
            return NULL;
        }
        nb->next = b;
        nb->used = 0;
        nb->cap = cap;
        p->doc->blocks = nb;
        b = nb;
    }
    void *r = (char *)b->data + b->used;
    b->used += size;
    return r;
}

static void skip_ws(parser *p) {
    while (p->pos < p->len) {
        char c = p->s[p->pos];
        if (c != ' ' && c != '\t' && c != '\n' && c != '\r') break;
        p->pos++;
    }
}

static int stack_push(parser *p, mx_json *v, char *key) {
    if (p->stack_len == p->stack_cap) {
        size_t cap = p->stack_cap ? p->stack_cap * 2 : 64;
        mx_json **nv = realloc(p->stack_vals, cap * sizeof *nv);
        if (!nv) return mx_fail(p->st, MX_ENOMEM, "%s: out of memory parsing JSON", p->what);
        p->stack_vals = nv;
        char **nk = realloc(p->stack_keys, cap * sizeof *nk);
        if (!nk) return mx_fail(p->st, MX_ENOMEM, "%s: out of memory parsing JSON", p->what);
        p->stack_keys = nk;
        p->stack_cap = cap;
    }
    p->stack_vals[p->stack_len] = v;
    p->stack_keys[p->stack_len] = key;
    p->stack_len++;
    return 0;
}

static int sbuf_put(parser *p, size_t at, const char *bytes, size_t n) {
    if (at + n + 1 > p->sbuf_cap) {
        size_t cap = p->sbuf_cap ? p->sbuf_cap : 256;
        while (cap < at + n + 1) cap *= 2;
        char *nb = realloc(p->sbuf, cap);
        if (!nb) return mx_fail(p->st, MX_ENOMEM, "%s: out of memory parsing JSON", p->what);
        p->sbuf = nb;
        p->sbuf_cap = cap;
    }
    memcpy(p->sbuf + at, bytes, n);
    return 0;
}

size_t mx_utf8_decode(const unsigned char *s, size_t n, uint32_t *cp) {
    uint32_t c = s[0];
    size_t len = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : (c >> 3) == 30 ? 4 : 0;
    *cp = 0xFFFD;
    if (len == 0 || len > n) return 1;
    uint32_t v = len == 1 ? c : len == 2 ? (c & 0x1F) : len == 3 ? (c & 0x0F) : (c & 0x07);
    for (size_t i = 1; i < len; i++) {
        if ((s[i] & 0xC0) != 0x80) return 1;
        v = (v << 6) | (s[i] & 0x3F);
    }
    static const uint32_t min_for_len[5] = {0, 0, 0x80, 0x800, 0x10000};
    if (v < min_for_len[len] || v > 0x10FFFF || (v >= 0xD800 && v <= 0xDFFF)) return 1;
    *cp = v;
    return len;
}

size_t mx_utf8_encode(uint32_t cp, char *out) {
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

/* Length of the valid UTF-8 sequence at s[0..avail), or 0 if invalid (overlong forms,
 * surrogates and code points above U+10FFFF are invalid). */
static size_t utf8_valid_len(const unsigned char *s, size_t avail) {
    unsigned c = s[0];
    size_t n;
    uint32_t cp, min;
    if (c < 0x80) return 1;
    if ((c & 0xE0) == 0xC0) n = 2, cp = c & 0x1F, min = 0x80;
    else if ((c & 0xF0) == 0xE0) n = 3, cp = c & 0x0F, min = 0x800;
    else if ((c & 0xF8) == 0xF0) n = 4, cp = c & 0x07, min = 0x10000;
    else return 0;
    if (avail < n) return 0;
    for (size_t i = 1; i < n; i++) {
        if ((s[i] & 0xC0) != 0x80) return 0;
        cp = (cp << 6) | (s[i] & 0x3F);
    }
    if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
    return n;
}

static int parse_hex4(parser *p, uint32_t *out) {
    if (p->len - p->pos < 4) return perr(p, "truncated \\u escape");
    uint32_t v = 0;
    for (int i = 0; i < 4; i++) {
        char c = p->s[p->pos + (size_t)i];
        v <<= 4;
        if (c >= '0' && c <= '9') v |= (uint32_t)(c - '0');
        else if (c >= 'a' && c <= 'f') v |= (uint32_t)(c - 'a' + 10);
        else if (c >= 'A' && c <= 'F') v |= (uint32_t)(c - 'A' + 10);
        else return perr(p, "bad hex digit in \\u escape");
    }
    p->pos += 4;
    *out = v;
    return 0;
}

/* \uXXXX (p->pos just after the 'u'), combining a UTF-16 surrogate pair into one code point. */
static int parse_unicode_escape(parser *p, uint32_t *cp) {
    uint32_t hi;
    if (parse_hex4(p, &hi)) return -1;
    if (hi >= 0xDC00 && hi <= 0xDFFF) return perr(p, "unpaired low surrogate in \\u escape");
    if (hi < 0xD800 || hi > 0xDBFF) {
        *cp = hi;
        return 0;
    }
    if (p->len - p->pos < 2 || p->s[p->pos] != '\\' || p->s[p->pos + 1] != 'u')
        return perr(p, "high surrogate not followed by a low surrogate");
    p->pos += 2;
    uint32_t lo;
    if (parse_hex4(p, &lo)) return -1;
    if (lo < 0xDC00 || lo > 0xDFFF) return perr(p, "high surrogate not followed by a low surrogate");
    *cp = 0x10000 + ((hi - 0xD800) << 10) + (lo - 0xDC00);
    return 0;
}

static int parse_escape(parser *p, size_t *n) {
    if (p->pos >= p->len) return perr(p, "unterminated string");
    char e = p->s[p->pos++];
    char out[4];
    size_t k = 1;
    switch (e) {
    case '"': out[0] = '"'; break;
    case '\\': out[0] = '\\'; break;
    case '/': out[0] = '/'; break;
    case 'b': out[0] = '\b'; break;
    case 'f': out[0] = '\f'; break;
    case 'n': out[0] = '\n'; break;
    case 'r': out[0] = '\r'; break;
    case 't': out[0] = '\t'; break;
    case 'u': {
        uint32_t cp = 0;
        if (parse_unicode_escape(p, &cp)) return -1;
        k = mx_utf8_encode(cp, out);
        break;
    }
    default: p->pos--; return perr(p, "unknown escape in string");
    }
    if (sbuf_put(p, *n, out, k)) return -1;
    *n += k;
    return 0;
}

/* Decodes a string (p->pos at the opening quote) into a NUL-terminated copy in the document. */
static int parse_string(parser *p, char **out, size_t *out_len) {
    p->pos++;
    size_t n = 0;
    for (;;) {
        if (p->pos >= p->len) return perr(p, "unterminated string");
        unsigned char c = (unsigned char)p->s[p->pos];
        if (c == '"') break;
        if (c == '\\') {
            p->pos++;
            if (parse_escape(p, &n)) return -1;
            continue;
        }
        if (c < 0x20) return perr(p, "control character in string");
        size_t k = utf8_valid_len((const unsigned char *)p->s + p->pos, p->len - p->pos);
        if (!k) return perr(p, "invalid UTF-8 in string");
        if (sbuf_put(p, n, p->s + p->pos, k)) return -1;
        n += k;
        p->pos += k;
    }
    p->pos++;
    char *s = doc_alloc(p, n + 1);
    if (!s) return -1;
    if (n) memcpy(s, p->sbuf, n);
    s[n] = 0;
    *out = s;
    *out_len = n;
    return 0;
}

static int is_digit(char c) { return c >= '0' && c <= '9'; }

/* Checks the RFC 8259 number grammar, then converts with strtod (on a NUL-terminated copy,
 * since the input need not be terminated). */
static int parse_number(parser *p, double *out) {
    size_t start = p->pos, i = p->pos;
    const char *s = p->s;
    if (i < p->len && s[i] == '-') i++;
    if (i >= p->len || !is_digit(s[i])) return perr(p, "bad number");
    if (s[i] == '0') i++;
    else
        while (i < p->len && is_digit(s[i])) i++;
    if (i < p->len && s[i] == '.') {
        i++;
        if (i >= p->len || !is_digit(s[i])) return perr(p, "bad number: digit expected after '.'");
        while (i < p->len && is_digit(s[i])) i++;
    }
    if (i < p->len && (s[i] == 'e' || s[i] == 'E')) {
        i++;
        if (i < p->len && (s[i] == '+' || s[i] == '-')) i++;
        if (i >= p->len || !is_digit(s[i])) return perr(p, "bad number: digit expected in exponent");
        while (i < p->len && is_digit(s[i])) i++;
    }
    size_t n = i - start;
    char small[64];
    char *buf = n < sizeof small ? small : malloc(n + 1);
    if (!buf) return mx_fail(p->st, MX_ENOMEM, "%s: out of memory parsing JSON", p->what);
    memcpy(buf, s + start, n);
    buf[n] = 0;
    errno = 0;
    double v = strtod(buf, NULL);
    int overflow = errno == ERANGE && isinf(v);
    if (buf != small) free(buf);
    if (overflow) return perr(p, "number out of range");
    p->pos = i;
    *out = v;
    return 0;
}

static int parse_literal(parser *p, const char *word) {
    size_t n = strlen(word);
    if (p->len - p->pos < n || memcmp(p->s + p->pos, word, n)) return perr(p, "unexpected character");
    p->pos += n;
    return 0;
}

static int parse_value(parser *p, mx_json *v, int depth);

/* Moves the children pushed since `base` from the scratch stack into the node. */
static int close_container(parser *p, mx_json *v, size_t base, int with_keys) {
    size_t n = p->stack_len - base;
    v->n = n;
    v->u.c.vals = NULL;
    v->u.c.keys = NULL;
    if (n) {
        v->u.c.vals = doc_alloc(p, n * sizeof(mx_json *));
        if (!v->u.c.vals) return -1;
        memcpy(v->u.c.vals, p->stack_vals + base, n * sizeof(mx_json *));
        if (with_keys) {
            v->u.c.keys = doc_alloc(p, n * sizeof(char *));
            if (!v->u.c.keys) return -1;
            memcpy(v->u.c.keys, p->stack_keys + base, n * sizeof(char *));
        }
    }
    p->stack_len = base;
    return 0;
}

static int parse_container(parser *p, mx_json *v, int depth, int is_obj) {
    if (depth >= JSON_MAX_DEPTH) return perr(p, "nesting too deep");
    char close = is_obj ? '}' : ']';
    v->type = is_obj ? MX_JSON_OBJ : MX_JSON_ARR;
    size_t base = p->stack_len;
    p->pos++;
    skip_ws(p);
    if (p->pos < p->len && p->s[p->pos] == close) {
        p->pos++;
        return close_container(p, v, base, is_obj);
    }
    for (;;) {
        char *key = NULL;
        skip_ws(p);
        if (is_obj) {
            size_t klen;
            if (p->pos >= p->len || p->s[p->pos] != '"') return perr(p, "expected a string key");
            if (parse_string(p, &key, &klen)) return -1;
            skip_ws(p);
            if (p->pos >= p->len || p->s[p->pos] != ':') return perr(p, "expected ':' after key");
            p->pos++;
        }
        mx_json *child = doc_alloc(p, sizeof *child);
        if (!child || parse_value(p, child, depth + 1) || stack_push(p, child, key)) return -1;
        skip_ws(p);
        if (p->pos >= p->len) return perr(p, is_obj ? "unterminated object" : "unterminated array");
        char c = p->s[p->pos++];
        if (c == close) break;
        if (c != ',') {
            p->pos--;
            return perr(p, is_obj ? "expected ',' or '}'" : "expected ',' or ']'");
        }
    }
    return close_container(p, v, base, is_obj);
}

static int parse_value(parser *p, mx_json *v, int depth) {
    skip_ws(p);
    if (p->pos >= p->len) return perr(p, "unexpected end of input");
    memset(v, 0, sizeof *v);
    char c = p->s[p->pos];
    switch (c) {
    case '{': return parse_container(p, v, depth, 1);
    case '[': return parse_container(p, v, depth, 0);
    case '"': v->type = MX_JSON_STR; return parse_string(p, &v->u.str, &v->n);
    case 't': v->type = MX_JSON_BOOL; v->u.b = 1; return parse_literal(p, "true");
    case 'f': v->type = MX_JSON_BOOL; v->u.b = 0; return parse_literal(p, "false");
    case 'n': v->type = MX_JSON_NULL; return parse_literal(p, "null");
    /* NaN, Infinity, -Infinity: not RFC 8259, but Python's json module writes them and
     * diffusers configs contain them (scheduler "lambda_min_clipped": -Infinity). */
    case 'N': v->type = MX_JSON_NUM; v->u.num = NAN; return parse_literal(p, "NaN");
    case 'I': v->type = MX_JSON_NUM; v->u.num = INFINITY; return parse_literal(p, "Infinity");
    default:
        if (c == '-' && p->len - p->pos > 1 && p->s[p->pos + 1] == 'I') {
            v->type = MX_JSON_NUM;
            v->u.num = -INFINITY;
            p->pos++;
            return parse_literal(p, "Infinity");
        }
        if (c == '-' || is_digit(c)) {
            v->type = MX_JSON_NUM;
            return parse_number(p, &v->u.num);
        }
        return perr(p, "unexpected character");
    }
}

mx_json *mx_json_parse(const char *text, size_t len, const char *what, mx_status *st) {
    json_doc *doc = calloc(1, sizeof *doc);
    if (!doc) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory parsing JSON", what ? what : "<json>");
        return NULL;
    }
    parser p = {.s = text, .len = text ? len : 0, .what = what ? what : "<json>", .st = st, .doc = doc};
    /* A UTF-8 byte order mark is allowed to precede the text (RFC 8259 §8.1). */
    if (p.len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3)) p.pos = 3;
    int rc = parse_value(&p, &doc->root, 0);
    if (!rc) {
        skip_ws(&p);
        if (p.pos != p.len) rc = perr(&p, "trailing characters after the JSON value");
    }
    free(p.stack_vals);
    free(p.stack_keys);
    free(p.sbuf);
    if (rc) {
        mx_json_free(&doc->root);
        return NULL;
    }
    return &doc->root;
}

void mx_json_free(mx_json *root) {
    if (!root) return;
    json_doc *doc = (json_doc *)root;
    json_block *b = doc->blocks;
    while (b) {
        json_block *next = b->next;
        free(b);
        b = next;
    }
    free(doc);
}

mx_json_type mx_json_kind(const mx_json *j) { return j ? j->type : MX_JSON_NULL; }

const mx_json *mx_json_get(const mx_json *j, const char *key) {
    if (!j || j->type != MX_JSON_OBJ || !key) return NULL;
    for (size_t i = 0; i < j->n; i++)
        if (!strcmp(j->u.c.keys[i], key)) return j->u.c.vals[i];
    return NULL;
}

size_t mx_json_len(const mx_json *j) {
    if (!j || (j->type != MX_JSON_ARR && j->type != MX_JSON_OBJ)) return 0;
    return j->n;
}

const mx_json *mx_json_at(const mx_json *j, size_t i) {
    if (i >= mx_json_len(j)) return NULL;
    return j->u.c.vals[i];
}

const char *mx_json_key(const mx_json *j, size_t i) {
    if (!j || j->type != MX_JSON_OBJ || i >= j->n) return NULL;
    return j->u.c.keys[i];
}

double mx_json_num(const mx_json *j) { return j && j->type == MX_JSON_NUM ? j->u.num : 0.0; }

int mx_json_bool(const mx_json *j) { return j && j->type == MX_JSON_BOOL ? j->u.b : 0; }

const char *mx_json_str(const mx_json *j) { return j && j->type == MX_JSON_STR ? j->u.str : NULL; }

size_t mx_json_str_len(const mx_json *j) { return j && j->type == MX_JSON_STR ? j->n : 0; }

double mx_json_get_num(const mx_json *obj, const char *key, double dflt) {
    const mx_json *v = mx_json_get(obj, key);
    return v && v->type == MX_JSON_NUM ? v->u.num : dflt;
}

const char *mx_json_get_str(const mx_json *obj, const char *key, const char *dflt) {
    const mx_json *v = mx_json_get(obj, key);
    return v && v->type == MX_JSON_STR ? v->u.str : dflt;
}

int mx_json_get_bool(const mx_json *obj, const char *key, int dflt) {
    const mx_json *v = mx_json_get(obj, key);
    return v && v->type == MX_JSON_BOOL ? v->u.b : dflt;
}
