/* A small JSON reader (RFC 8259) for safetensors headers, config.json files, tokenizer
 * vocabularies and golden manifests. Parses into a tree of nodes in one allocation list;
 * depth and sizes are bounded, every error has a byte offset. */
#ifndef MX_JSON_H
#define MX_JSON_H

#include <stddef.h>
#include <stdint.h>

#include "status.h"

typedef enum { MX_JSON_NULL, MX_JSON_BOOL, MX_JSON_NUM, MX_JSON_STR, MX_JSON_ARR, MX_JSON_OBJ } mx_json_type;

typedef struct mx_json mx_json;

/* Parses text[0..len). `what` names the source (a file path) in error messages. */
mx_json *mx_json_parse(const char *text, size_t len, const char *what, mx_status *st);
void mx_json_free(mx_json *root);

mx_json_type mx_json_kind(const mx_json *j);
/* Object member by key (NULL if absent or j is not an object). */
const mx_json *mx_json_get(const mx_json *j, const char *key);
/* Array/object length and i-th element (for objects: the i-th value; key via mx_json_key). */
size_t mx_json_len(const mx_json *j);
const mx_json *mx_json_at(const mx_json *j, size_t i);
const char *mx_json_key(const mx_json *j, size_t i);
/* Scalars: strings are NUL-terminated UTF-8 (escapes decoded); str_len excludes the NUL. */
double mx_json_num(const mx_json *j);
int mx_json_bool(const mx_json *j);
const char *mx_json_str(const mx_json *j);
size_t mx_json_str_len(const mx_json *j);

/* Convenience: member as number/string/bool with a default when absent or of another type. */
double mx_json_get_num(const mx_json *obj, const char *key, double dflt);
const char *mx_json_get_str(const mx_json *obj, const char *key, const char *dflt);
int mx_json_get_bool(const mx_json *obj, const char *key, int dflt);

/* UTF-8 bytes of code point cp (< 0x110000) into out[0..3]; returns the count (1..4). */
size_t mx_utf8_encode(uint32_t cp, char *out);
/* Decodes one UTF-8 sequence at s (n >= 1 bytes left): returns its length and the code point;
 * an invalid, overlong, surrogate or truncated sequence gives 1 and *cp = 0xFFFD. */
size_t mx_utf8_decode(const unsigned char *s, size_t n, uint32_t *cp);

#endif
