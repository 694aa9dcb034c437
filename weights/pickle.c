/* The restricted unpickler of PyTorch checkpoints (pickle.h). Values live in one pool and refer
 * to each other by index; the pickle's bytes stay where they are (strings point into them).
 * Opcode meanings follow CPython's Lib/pickletools.py; the persistent id and the rebuild
 * functions follow torch/serialization.py and torch/_utils.py (what torch.save writes). */
#include "pickle.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PK_MAX_STACK (1u << 20)
#define PK_MAX_MEMO (1u << 24)
#define PK_MAX_DIMS 8
#define PK_MAX_WALK (1u << 22) /* container nodes visited in one self-containment check */

typedef enum {
    PV_NONE, PV_BOOL, PV_INT, PV_FLOAT, PV_STR, PV_BYTES, PV_TUPLE, PV_LIST, PV_DICT, PV_GLOBAL, PV_STORAGE, PV_TENSOR,
    PV_MARK
} pv_kind;

/* The globals a checkpoint may name. */
typedef enum { G_ODICT, G_REBUILD_TENSOR, G_REBUILD_PARAM, G_REBUILD_PARAM_STATE, G_STORAGE } pk_global;

static const struct {
    const char *module, *name;
    pk_global g;
    int dtype; /* mx_st_dtype of a storage type, -1 otherwise */
    size_t esize;
} allowed_globals[] = {
    {"collections", "OrderedDict", G_ODICT, -1, 0},
    {"torch._utils", "_rebuild_tensor_v2", G_REBUILD_TENSOR, -1, 0},
    {"torch._utils", "_rebuild_parameter", G_REBUILD_PARAM, -1, 0},
    {"torch._utils", "_rebuild_parameter_with_state", G_REBUILD_PARAM_STATE, -1, 0},
    {"torch", "FloatStorage", G_STORAGE, MX_ST_F32, 4},
    {"torch", "HalfStorage", G_STORAGE, MX_ST_F16, 2},
    {"torch", "BFloat16Storage", G_STORAGE, MX_ST_BF16, 2},
    {"torch", "DoubleStorage", G_STORAGE, MX_ST_F64, 8},
    {"torch", "LongStorage", G_STORAGE, MX_ST_I64, 8},
    {"torch", "IntStorage", G_STORAGE, MX_ST_I32, 4},
};

typedef struct {
    uint8_t kind;
    uint8_t global; /* PV_GLOBAL: index into allowed_globals */
    int64_t i;      /* PV_INT, PV_BOOL; PV_STORAGE: element count */
    double f;
    const char *s; /* PV_STR, PV_BYTES: not NUL-terminated */
    size_t len;
    uint32_t *items; /* PV_TUPLE, PV_LIST, PV_DICT (key, value pairs flattened) */
    size_t n, cap;
    /* PV_STORAGE */
    const uint8_t *data;
    size_t nbytes;
    int dtype;
    /* PV_TENSOR */
    uint32_t storage;
    int ndim;
    int64_t shape[PK_MAX_DIMS];
} pk_value;

typedef struct {
    const uint8_t *start, *p, *end;
    const char *what;
    mx_pickle_storage_fn storage_fn;
    void *ctx;
    mx_status *st;
    pk_value *vals;
    size_t n_vals, cap_vals;
    uint32_t *stack;
    size_t sp, cap_stack;
    size_t *marks;
    size_t n_marks, cap_marks;
    uint32_t *memo;
    size_t n_memo;
    uint32_t *walk; /* scratch of the self-containment check */
    size_t cap_walk;
    uint32_t *seen; /* generation marks, one per value */
    size_t cap_seen;
    uint32_t generation;
} pk;

static int pk_fail(pk *k, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static int pk_fail(pk *k, const char *fmt, ...) {
    char msg[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return mx_fail(k->st, MX_EINPUT, "%s: data.pkl: %s", k->what, msg);
}

static int grow(void **p, size_t *cap, size_t need, size_t elem, size_t limit) {
    if (need <= *cap) return 0;
    if (need > limit) return -1;
    size_t c = *cap ? *cap : 64;
    while (c < need) c *= 2;
    if (c > limit) c = limit;
    void *q = realloc(*p, c * elem);
    if (!q) return -1;
    *p = q;
    *cap = c;
    return 0;
}

/* ---- values ---- */

static int new_value(pk *k, pv_kind kind, uint32_t *out) {
    if (grow((void **)&k->vals, &k->cap_vals, k->n_vals + 1, sizeof *k->vals, (size_t)UINT32_MAX))
        return pk_fail(k, "out of memory");
    pk_value *v = &k->vals[k->n_vals];
    memset(v, 0, sizeof *v);
    v->kind = (uint8_t)kind;
    *out = (uint32_t)k->n_vals++;
    return 0;
}

static int add_item(pk *k, uint32_t c, uint32_t item) {
    pk_value *v = &k->vals[c];
    if (grow((void **)&v->items, &v->cap, v->n + 1, sizeof *v->items, (size_t)UINT32_MAX))
        return pk_fail(k, "out of memory");
    v->items[v->n++] = item;
    return 0;
}

static int is_container(const pk_value *v) { return v->kind == PV_TUPLE || v->kind == PV_LIST || v->kind == PV_DICT; }

/* Whether container `target` is reachable from `from` (then adding `from` into `target` would
 * make a cycle). Iterative, with a bound on the nodes visited. */
static int reaches(pk *k, uint32_t from, uint32_t target, int *too_big) {
    if (!is_container(&k->vals[from])) return 0;
    size_t old_cap = k->cap_seen;
    if (grow((void **)&k->seen, &k->cap_seen, k->n_vals, sizeof *k->seen, (size_t)UINT32_MAX)) {
        *too_big = 1;
        return 1;
    }
    memset(k->seen + old_cap, 0, (k->cap_seen - old_cap) * sizeof *k->seen);
    uint32_t gen = ++k->generation;
    size_t depth = 0, visited = 0;
    if (grow((void **)&k->walk, &k->cap_walk, 1, sizeof *k->walk, PK_MAX_WALK)) {
        *too_big = 1;
        return 1;
    }
    k->walk[depth++] = from;
    while (depth) {
        uint32_t c = k->walk[--depth];
        if (c == target) return 1;
        if (c < k->cap_seen && k->seen[c] == gen) continue;
        k->seen[c] = gen;
        if (++visited > PK_MAX_WALK) {
            *too_big = 1;
            return 1;
        }
        const pk_value *v = &k->vals[c];
        for (size_t i = 0; i < v->n; i++) {
            if (!is_container(&k->vals[v->items[i]])) continue;
            if (grow((void **)&k->walk, &k->cap_walk, depth + 1, sizeof *k->walk, PK_MAX_WALK)) {
                *too_big = 1;
                return 1;
            }
            k->walk[depth++] = v->items[i];
        }
    }
    return 0;
}

/* Adds item into the list or dict c, refusing a container that would hold itself. */
static int insert(pk *k, uint32_t c, uint32_t item) {
    int too_big = 0;
    if (item == c || reaches(k, item, c, &too_big))
        return too_big ? pk_fail(k, "containers nested too deeply") : pk_fail(k, "a container holds itself (cycle)");
    return add_item(k, c, item);
}

/* ---- stack, marks, memo ---- */

static int push(pk *k, uint32_t v) {
    if (grow((void **)&k->stack, &k->cap_stack, k->sp + 1, sizeof *k->stack, PK_MAX_STACK))
        return pk_fail(k, "stack deeper than %u", PK_MAX_STACK);
    k->stack[k->sp++] = v;
    return 0;
}

static int push_new(pk *k, pv_kind kind, uint32_t *out) {
    uint32_t v;
    if (new_value(k, kind, &v) || push(k, v)) return -1;
    if (out) *out = v;
    return 0;
}

static int pop(pk *k, uint32_t *v) {
    size_t floor = k->n_marks ? k->marks[k->n_marks - 1] : 0;
    if (k->sp <= floor) return pk_fail(k, "stack underflow");
    *v = k->stack[--k->sp];
    return 0;
}

static int top(pk *k, uint32_t *v) {
    size_t floor = k->n_marks ? k->marks[k->n_marks - 1] : 0;
    if (k->sp <= floor) return pk_fail(k, "stack underflow");
    *v = k->stack[k->sp - 1];
    return 0;
}

static int push_mark(pk *k) {
    if (grow((void **)&k->marks, &k->cap_marks, k->n_marks + 1, sizeof *k->marks, PK_MAX_STACK))
        return pk_fail(k, "too many marks");
    k->marks[k->n_marks++] = k->sp;
    return 0;
}

/* Pops the items above the last mark; *first is their position on the stack. */
static int pop_mark(pk *k, size_t *first, size_t *count) {
    if (!k->n_marks) return pk_fail(k, "no mark on the stack");
    *first = k->marks[--k->n_marks];
    *count = k->sp - *first;
    k->sp = *first;
    return 0;
}

static int memo_put(pk *k, uint64_t idx) {
    if (idx >= PK_MAX_MEMO) return pk_fail(k, "memo index %llu too large", (unsigned long long)idx);
    uint32_t v;
    if (top(k, &v)) return -1;
    size_t old = k->n_memo;
    if (idx >= k->n_memo) {
        uint32_t *m = realloc(k->memo, (size_t)(idx + 1) * sizeof *m);
        if (!m) return pk_fail(k, "out of memory");
        k->memo = m;
        for (size_t i = old; i <= idx; i++) m[i] = UINT32_MAX;
        k->n_memo = (size_t)idx + 1;
    }
    k->memo[idx] = v;
    return 0;
}

static int memo_get(pk *k, uint64_t idx) {
    if (idx >= k->n_memo || k->memo[idx] == UINT32_MAX)
        return pk_fail(k, "memo entry %llu read before it is written", (unsigned long long)idx);
    return push(k, k->memo[idx]);
}

/* ---- reading the opcode stream ---- */

static int need(pk *k, size_t n) {
    return (size_t)(k->end - k->p) < n ? pk_fail(k, "truncated (an opcode needs %zu more bytes)", n) : 0;
}

static uint64_t read_le(pk *k, int n) {
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--) v = (v << 8) | k->p[i];
    k->p += n;
    return v;
}

static int take_le(pk *k, int n, uint64_t *v) {
    if (need(k, (size_t)n)) return -1;
    *v = read_le(k, n);
    return 0;
}

static int push_string(pk *k, pv_kind kind, int len_bytes) {
    uint64_t len;
    if (take_le(k, len_bytes, &len)) return -1;
    if (len > (uint64_t)(k->end - k->p)) return pk_fail(k, "string of %llu bytes past the end", (unsigned long long)len);
    uint32_t v;
    if (push_new(k, kind, &v)) return -1;
    k->vals[v].s = (const char *)k->p;
    k->vals[v].len = (size_t)len;
    k->p += len;
    return 0;
}

static int push_int(pk *k, int64_t i) {
    uint32_t v;
    if (push_new(k, PV_INT, &v)) return -1;
    k->vals[v].i = i;
    return 0;
}

/* LONG1: n bytes of little-endian two's complement (n <= 8 here: sizes and offsets). */
static int push_long1(pk *k) {
    uint64_t n, u;
    if (take_le(k, 1, &n)) return -1;
    if (n > 8) return pk_fail(k, "integer of %llu bytes", (unsigned long long)n);
    if (n == 0) return push_int(k, 0);
    if (take_le(k, (int)n, &u)) return -1;
    if (n < 8 && (u >> (8 * n - 1)) & 1) u |= ~(uint64_t)0 << (8 * n);
    return push_int(k, (int64_t)u);
}

static int push_float(pk *k) {
    if (need(k, 8)) return -1;
    uint64_t u = 0;
    for (int i = 0; i < 8; i++) u = (u << 8) | k->p[i]; /* big-endian */
    k->p += 8;
    uint32_t v;
    if (push_new(k, PV_FLOAT, &v)) return -1;
    memcpy(&k->vals[v].f, &u, 8);
    return 0;
}

static int find_global(pk *k, const char *mod, size_t mod_len, const char *name, size_t name_len) {
    for (size_t g = 0; g < sizeof allowed_globals / sizeof allowed_globals[0]; g++)
        if (strlen(allowed_globals[g].module) == mod_len && !memcmp(allowed_globals[g].module, mod, mod_len) &&
            strlen(allowed_globals[g].name) == name_len && !memcmp(allowed_globals[g].name, name, name_len)) {
            uint32_t v;
            if (push_new(k, PV_GLOBAL, &v)) return -1;
            k->vals[v].global = (uint8_t)g;
            return 0;
        }
    char m[96], n[96];
    snprintf(m, sizeof m, "%.*s", (int)(mod_len < 80 ? mod_len : 80), mod);
    snprintf(n, sizeof n, "%.*s", (int)(name_len < 80 ? name_len : 80), name);
    for (char *c = m; *c; c++) if ((unsigned char)*c < 0x20) *c = '?';
    for (char *c = n; *c; c++) if ((unsigned char)*c < 0x20) *c = '?';
    return pk_fail(k, "global '%s.%s' is not allowed (a tensor checkpoint names only torch storages, "
                      "torch._utils rebuild functions and collections.OrderedDict); nothing was run", m, n);
}

/* GLOBAL: "module\nname\n" */
static int op_global(pk *k) {
    const uint8_t *a = k->p, *nl1 = memchr(a, '\n', (size_t)(k->end - a));
    const uint8_t *nl2 = nl1 ? memchr(nl1 + 1, '\n', (size_t)(k->end - nl1 - 1)) : NULL;
    if (!nl2) return pk_fail(k, "truncated GLOBAL");
    k->p = nl2 + 1;
    return find_global(k, (const char *)a, (size_t)(nl1 - a), (const char *)nl1 + 1, (size_t)(nl2 - nl1 - 1));
}

static int op_stack_global(pk *k) {
    uint32_t name, mod;
    if (pop(k, &name) || pop(k, &mod)) return -1;
    if (k->vals[name].kind != PV_STR || k->vals[mod].kind != PV_STR) return pk_fail(k, "STACK_GLOBAL of non-strings");
    return find_global(k, k->vals[mod].s, k->vals[mod].len, k->vals[name].s, k->vals[name].len);
}

static int op_tuple_n(pk *k, size_t n) {
    uint32_t items[3], t;
    for (size_t i = n; i-- > 0;)
        if (pop(k, &items[i])) return -1;
    if (new_value(k, PV_TUPLE, &t)) return -1;
    for (size_t i = 0; i < n; i++)
        if (add_item(k, t, items[i])) return -1;
    return push(k, t);
}

/* TUPLE, LIST, DICT: the items above the mark. */
static int op_from_mark(pk *k, pv_kind kind) {
    size_t first = 0, count = 0;
    if (pop_mark(k, &first, &count)) return -1;
    if (kind == PV_DICT && count % 2) return pk_fail(k, "DICT with an odd number of items");
    uint32_t c;
    if (new_value(k, kind, &c)) return -1;
    for (size_t i = 0; i < count; i++)
        if (add_item(k, c, k->stack[first + i])) return -1;
    return push(k, c);
}

/* APPEND(S), SETITEM(S): items above the mark (or the top 1/2) into the container below. */
static int op_fill(pk *k, int dict, int marked) {
    size_t first = 0, count = 0;
    if (marked) {
        if (pop_mark(k, &first, &count)) return -1;
    } else {
        count = dict ? 2 : 1;
        size_t floor = k->n_marks ? k->marks[k->n_marks - 1] : 0;
        if (k->sp < floor + count) return pk_fail(k, "stack underflow");
        first = k->sp - count;
        k->sp = first;
    }
    uint32_t c;
    if (top(k, &c)) return -1;
    if (k->vals[c].kind != (dict ? PV_DICT : PV_LIST)) return pk_fail(k, "%s on a non-%s", dict ? "SETITEM" : "APPEND", dict ? "dict" : "list");
    if (dict && count % 2) return pk_fail(k, "SETITEMS with an odd number of items");
    for (size_t i = 0; i < count; i++)
        if (insert(k, c, k->stack[first + i])) return -1;
    return 0;
}

static int tuple_int(pk *k, const pk_value *t, size_t i, int64_t *out) {
    if (i >= t->n || k->vals[t->items[i]].kind != PV_INT) return -1;
    *out = k->vals[t->items[i]].i;
    return 0;
}

static int str_is(const pk_value *v, const char *s) {
    return v->kind == PV_STR && v->len == strlen(s) && !memcmp(v->s, s, v->len);
}

/* BINPERSID: ('storage', storage_type, key, location, numel) -> the storage's bytes. */
static int op_persid(pk *k) {
    uint32_t pid;
    if (pop(k, &pid)) return -1;
    const pk_value *t = &k->vals[pid];
    int64_t numel;
    if (t->kind != PV_TUPLE || t->n != 5 || !str_is(&k->vals[t->items[0]], "storage") ||
        k->vals[t->items[1]].kind != PV_GLOBAL || allowed_globals[k->vals[t->items[1]].global].g != G_STORAGE ||
        k->vals[t->items[2]].kind != PV_STR || tuple_int(k, t, 4, &numel) || numel < 0)
        return pk_fail(k, "persistent id is not ('storage', torch.<Type>Storage, key, location, numel)");
    const pk_value *key = &k->vals[t->items[2]];
    char name[64];
    if (key->len == 0 || key->len >= sizeof name || memchr(key->s, '/', key->len) || memchr(key->s, 0, key->len))
        return pk_fail(k, "bad storage key");
    memcpy(name, key->s, key->len);
    name[key->len] = 0;
    size_t esize = allowed_globals[k->vals[t->items[1]].global].esize;
    int dtype = allowed_globals[k->vals[t->items[1]].global].dtype;
    const void *data;
    size_t nbytes;
    if (k->storage_fn(k->ctx, name, &data, &nbytes, k->st)) return -1;
    if ((uint64_t)numel > nbytes / esize)
        return pk_fail(k, "storage '%s' declares %lld elements of %zu bytes, its entry holds %zu bytes", name,
                       (long long)numel, esize, nbytes);
    uint32_t v;
    if (push_new(k, PV_STORAGE, &v)) return -1;
    k->vals[v].data = data;
    k->vals[v].nbytes = (size_t)numel * esize;
    k->vals[v].i = numel;
    k->vals[v].dtype = dtype;
    return 0;
}

static size_t dtype_size(int dtype) {
    for (size_t g = 0; g < sizeof allowed_globals / sizeof allowed_globals[0]; g++)
        if (allowed_globals[g].g == G_STORAGE && allowed_globals[g].dtype == dtype) return allowed_globals[g].esize;
    return 0;
}

/* _rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks[, metadata]): a view,
 * accepted only when C-contiguous and inside its storage. */
static int rebuild_tensor(pk *k, const pk_value *args, uint32_t *out) {
    int64_t offset;
    if (args->n < 6 || args->n > 7 || k->vals[args->items[0]].kind != PV_STORAGE || tuple_int(k, args, 1, &offset) ||
        k->vals[args->items[2]].kind != PV_TUPLE || k->vals[args->items[3]].kind != PV_TUPLE)
        return pk_fail(k, "_rebuild_tensor_v2 arguments are not (storage, offset, size, stride, ...)");
    const pk_value *size = &k->vals[args->items[2]], *stride = &k->vals[args->items[3]];
    if (size->n > PK_MAX_DIMS || stride->n != size->n)
        return pk_fail(k, "tensor of %zu dimensions (at most %d) or stride of another length", size->n, PK_MAX_DIMS);
    uint32_t storage = args->items[0];
    const pk_value *s = &k->vals[storage];
    uint64_t numel = 1, expect = 1;
    int64_t shape[PK_MAX_DIMS];
    for (size_t d = size->n; d-- > 0;) {
        int64_t dim, str;
        if (tuple_int(k, size, d, &dim) || tuple_int(k, stride, d, &str) || dim < 0)
            return pk_fail(k, "tensor size or stride is not a tuple of non-negative integers");
        if (dim != 1 && str != (int64_t)expect) return pk_fail(k, "non-contiguous tensor (stride) is not read");
        shape[d] = dim;
        if (dim && expect > (uint64_t)s->i / (uint64_t)dim + 1) expect = UINT64_MAX;
        else expect *= (uint64_t)dim;
        numel = expect;
    }
    if (offset < 0 || (uint64_t)offset > (uint64_t)s->i || numel > (uint64_t)s->i - (uint64_t)offset)
        return pk_fail(k, "tensor view (offset %lld) extends past its storage of %lld elements", (long long)offset,
                       (long long)s->i);
    uint32_t v;
    if (new_value(k, PV_TENSOR, &v)) return -1;
    pk_value *t = &k->vals[v];
    t->storage = storage;
    t->ndim = (int)size->n;
    memcpy(t->shape, shape, sizeof shape);
    size_t es = dtype_size(k->vals[storage].dtype);
    t->data = k->vals[storage].data + (size_t)offset * es;
    t->nbytes = (size_t)numel * es;
    t->dtype = k->vals[storage].dtype;
    *out = v;
    return 0;
}

/* REDUCE: an allowed callable applied to its arguments; nothing is called. */
static int op_reduce(pk *k) {
    uint32_t args_i, fn_i, out = 0;
    if (pop(k, &args_i) || pop(k, &fn_i)) return -1;
    const pk_value *fn = &k->vals[fn_i], *args = &k->vals[args_i];
    if (fn->kind != PV_GLOBAL) return pk_fail(k, "REDUCE of something that is not an allowed global");
    if (args->kind != PV_TUPLE) return pk_fail(k, "REDUCE arguments are not a tuple");
    switch (allowed_globals[fn->global].g) {
    case G_ODICT:
        if (args->n != 0) return pk_fail(k, "OrderedDict with arguments");
        return push_new(k, PV_DICT, NULL);
    case G_REBUILD_TENSOR:
        if (rebuild_tensor(k, args, &out)) return -1;
        return push(k, out);
    case G_REBUILD_PARAM:
    case G_REBUILD_PARAM_STATE:
        if (args->n < 3 || k->vals[args->items[0]].kind != PV_TENSOR)
            return pk_fail(k, "_rebuild_parameter of something that is not a tensor");
        return push(k, args->items[0]);
    case G_STORAGE:
        break;
    }
    return pk_fail(k, "REDUCE of torch.%s (a storage type is not called)", allowed_globals[fn->global].name);
}

/* BUILD: only the __dict__ state torch attaches to an OrderedDict (its _metadata) or to a
 * parameter; the state is ignored. */
static int op_build(pk *k) {
    uint32_t state, obj;
    if (pop(k, &state) || top(k, &obj)) return -1;
    if (k->vals[obj].kind != PV_DICT && k->vals[obj].kind != PV_TENSOR) return pk_fail(k, "BUILD of an object");
    return 0;
}

static int op_dup(pk *k) {
    uint32_t v;
    return top(k, &v) || push(k, v);
}

static int op_bool(pk *k, int b) {
    uint32_t v;
    if (push_new(k, PV_BOOL, &v)) return -1;
    k->vals[v].i = b;
    return 0;
}

static int op_int(pk *k, int bytes, int sign) {
    uint64_t u;
    if (take_le(k, bytes, &u)) return -1;
    return push_int(k, sign ? (int64_t)(int32_t)(uint32_t)u : (int64_t)u);
}

static int op_memo(pk *k, int bytes) {
    uint64_t i;
    return take_le(k, bytes, &i) || memo_put(k, i);
}

static int op_get(pk *k, int bytes) {
    uint64_t i;
    return take_le(k, bytes, &i) || memo_get(k, i);
}

static int op_skip(pk *k, int bytes) {
    uint64_t u;
    return take_le(k, bytes, &u);
}

static int op_pop_mark(pk *k) {
    size_t f, c;
    return pop_mark(k, &f, &c);
}

static int op_pop(pk *k) {
    uint32_t v;
    return pop(k, &v);
}

/* One opcode; *stop set at STOP. */
static int step(pk *k, int *stop) {
    int op = *k->p++;
    switch (op) {
    case 0x80: return op_skip(k, 1);    /* PROTO */
    case 0x95: return op_skip(k, 8);    /* FRAME: a length hint */
    case '.': *stop = 1; return 0;      /* STOP */
    case '(': return push_mark(k);      /* MARK */
    case '1': return op_pop_mark(k);    /* POP_MARK */
    case '0': return op_pop(k);         /* POP */
    case '2': return op_dup(k);         /* DUP */
    case ')': return push_new(k, PV_TUPLE, NULL);
    case ']': return push_new(k, PV_LIST, NULL);
    case '}': return push_new(k, PV_DICT, NULL);
    case 't': return op_from_mark(k, PV_TUPLE);
    case 'l': return op_from_mark(k, PV_LIST);
    case 'd': return op_from_mark(k, PV_DICT);
    case 0x85: return op_tuple_n(k, 1);
    case 0x86: return op_tuple_n(k, 2);
    case 0x87: return op_tuple_n(k, 3);
    case 'N': return push_new(k, PV_NONE, NULL);
    case 0x88: return op_bool(k, 1);    /* NEWTRUE */
    case 0x89: return op_bool(k, 0);    /* NEWFALSE */
    case 'J': return op_int(k, 4, 1);   /* BININT */
    case 'K': return op_int(k, 1, 0);   /* BININT1 */
    case 'M': return op_int(k, 2, 0);   /* BININT2 */
    case 0x8a: return push_long1(k);    /* LONG1 */
    case 'G': return push_float(k);     /* BINFLOAT */
    case 'X': return push_string(k, PV_STR, 4);   /* BINUNICODE */
    case 0x8c: return push_string(k, PV_STR, 1);  /* SHORT_BINUNICODE */
    case 0x8d: return push_string(k, PV_STR, 8);  /* BINUNICODE8 */
    case 'U': return push_string(k, PV_STR, 1);   /* SHORT_BINSTRING */
    case 'T': return push_string(k, PV_STR, 4);   /* BINSTRING (lengths above 2^31 fail as past the end) */
    case 'C': return push_string(k, PV_BYTES, 1); /* SHORT_BINBYTES */
    case 'B': return push_string(k, PV_BYTES, 4); /* BINBYTES */
    case 0x8e: return push_string(k, PV_BYTES, 8); /* BINBYTES8 */
    case 'q': return op_memo(k, 1);     /* BINPUT */
    case 'r': return op_memo(k, 4);     /* LONG_BINPUT */
    case 0x94: return memo_put(k, k->n_memo); /* MEMOIZE */
    case 'h': return op_get(k, 1);      /* BINGET */
    case 'j': return op_get(k, 4);      /* LONG_BINGET */
    case 'c': return op_global(k);
    case 0x93: return op_stack_global(k);
    case 'R': return op_reduce(k);
    case 'Q': return op_persid(k);
    case 'b': return op_build(k);
    case 'a': return op_fill(k, 0, 0);  /* APPEND */
    case 'e': return op_fill(k, 0, 1);  /* APPENDS */
    case 's': return op_fill(k, 1, 0);  /* SETITEM */
    case 'u': return op_fill(k, 1, 1);  /* SETITEMS */
    default:
        return pk_fail(k, "opcode 0x%02x ('%c') at byte %zu is not allowed in a tensor checkpoint", op,
                       op >= 0x20 && op < 0x7f ? op : '?', (size_t)(k->p - 1 - k->start));
    }
}

/* ---- the state dict ---- */

static const pk_value *dict_get(const pk *k, const pk_value *d, const char *key) {
    for (size_t i = 0; i + 1 < d->n; i += 2)
        if (str_is(&k->vals[d->items[i]], key)) return &k->vals[d->items[i + 1]];
    return NULL;
}

static int cmp_name(const void *a, const void *b) {
    return strcmp(((const mx_st_tensor *)a)->name, ((const mx_st_tensor *)b)->name);
}

/* Appends tensor v as `name` (prefix + key, key not NUL-terminated). */
static int add_tensor(pk *k, const char *prefix, const pk_value *key, const pk_value *v, mx_pickle_result *out,
                      size_t *cap) {
    size_t plen = strlen(prefix);
    if (key->kind != PV_STR || key->len == 0 || key->len > 1000 || memchr(key->s, 0, key->len))
        return pk_fail(k, "a tensor's key is not a name");
    if (out->count == *cap) {
        size_t nc = *cap ? 2 * *cap : 64;
        mx_st_tensor *nt = realloc(out->tensors, nc * sizeof *nt);
        if (!nt) return pk_fail(k, "out of memory");
        out->tensors = nt;
        *cap = nc;
    }
    mx_st_tensor *t = &out->tensors[out->count];
    memset(t, 0, sizeof *t);
    if (!(t->name = malloc(plen + key->len + 1))) return pk_fail(k, "out of memory");
    out->count++;
    memcpy(t->name, prefix, plen);
    memcpy(t->name + plen, key->s, key->len);
    t->name[plen + key->len] = 0;
    t->dtype = (mx_st_dtype)v->dtype;
    t->ndim = v->ndim;
    memcpy(t->shape, v->shape, sizeof t->shape);
    t->data = v->data;
    t->nbytes = v->nbytes;
    return 0;
}

/* The tensors of dict d. A dict of tensors inside it under a name (the IP-Adapter's
 * {"image_proj": {...}, "ip_adapter": {...}}) gives its tensors as "name.key", one level deep;
 * other values, and entries of such a dict that are not named tensors, are skipped. */
static int collect_dict(pk *k, const pk_value *d, const char *prefix, mx_pickle_result *out, size_t *cap) {
    for (size_t i = 0; i + 1 < d->n; i += 2) {
        const pk_value *key = &k->vals[d->items[i]], *v = &k->vals[d->items[i + 1]];
        if (v->kind == PV_TENSOR) {
            if (*prefix && key->kind != PV_STR) out->skipped++;
            else if (add_tensor(k, prefix, key, v, out, cap)) return -1;
        } else if (v->kind == PV_DICT && !*prefix && key->kind == PV_STR && key->len > 0 && key->len < 200 &&
                   !memchr(key->s, 0, key->len)) {
            char sub[256];
            snprintf(sub, sizeof sub, "%.*s.", (int)key->len, key->s);
            if (collect_dict(k, v, sub, out, cap)) return -1;
        } else {
            out->skipped++;
        }
    }
    return 0;
}

static int collect_tensors(pk *k, const pk_value *d, mx_pickle_result *out) {
    size_t cap = 0;
    if (collect_dict(k, d, "", out, &cap)) return -1;
    if (out->count) qsort(out->tensors, out->count, sizeof *out->tensors, cmp_name);
    for (size_t i = 1; i < out->count; i++)
        if (!strcmp(out->tensors[i - 1].name, out->tensors[i].name))
            return pk_fail(k, "duplicate tensor name '%s'", out->tensors[i].name);
    return 0;
}

static void pk_free(pk *k) {
    for (size_t i = 0; i < k->n_vals; i++) free(k->vals[i].items);
    free(k->vals);
    free(k->stack);
    free(k->marks);
    free(k->memo);
    free(k->walk);
    free(k->seen);
}

int mx_pickle_read_state_dict(const uint8_t *p, size_t n, const char *what, mx_pickle_storage_fn storage, void *ctx,
                              mx_pickle_result *out, mx_status *st) {
    memset(out, 0, sizeof *out);
    pk k = {.start = p, .p = p, .end = p + n, .what = what, .storage_fn = storage, .ctx = ctx, .st = st};
    int stop = 0, rc = 0;
    while (!rc && !stop) rc = k.p < k.end ? step(&k, &stop) : pk_fail(&k, "ends without STOP");
    uint32_t root = 0;
    if (!rc && (k.sp != 1 || k.n_marks)) rc = pk_fail(&k, "STOP with %zu values on the stack", k.sp);
    if (!rc) root = k.stack[0];
    if (!rc && k.vals[root].kind != PV_DICT) rc = pk_fail(&k, "the checkpoint is not a dict of tensors");
    if (!rc) {
        const pk_value *d = &k.vals[root], *sd = dict_get(&k, d, "state_dict");
        rc = collect_tensors(&k, sd && sd->kind == PV_DICT ? sd : d, out);
        if (!rc && sd && sd->kind == PV_DICT) out->skipped += d->n / 2 - 1;
    }
    if (rc) {
        for (size_t i = 0; i < out->count; i++) free(out->tensors[i].name);
        free(out->tensors);
        memset(out, 0, sizeof *out);
    }
    pk_free(&k);
    return rc;
}
