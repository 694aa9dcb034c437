#!/bin/sh
# make check (tools/scripts/check_docs.sh): the op table, the network table, their counts and the
# files a new op touches, as docs/DESIGN.md states them, match the code, and every "DESIGN.md §n"
# names a section; and the checker fails on each kind of wrong claim planted in a copy of the tree
# (the doc's or the code's side).
NAME=check_docs
. "$(dirname "$0")/lib_cli.sh"

check "DESIGN.md's ops, networks and a new op's files match the code" sh tools/scripts/check_docs.sh .

# A copy of what the checker reads, as a tree of its own.
R="$T/repo"
mkdir -p "$R/docs" "$R/ops/cpu" "$R/ops/cuda" "$R/weights" "$R/tests/cuda"
cp docs/DESIGN.md docs/cuda-notes.md "$R/docs/" && cp ops/op_list.h ops/backend.c "$R/ops/" && cp ops/cpu/*_ref.c "$R/ops/cpu/" &&
    cp ops/cuda/*.cu "$R/ops/cuda/" && cp weights/networks.c weights/networks.h "$R/weights/" && cp tests/test_ops_*.c "$R/tests/" &&
    cp tests/cuda/*.c "$R/tests/cuda/" || { echo "FAIL copying the tree"; exit 1; }
check "the copy passes" [ "$(rc_of sh tools/scripts/check_docs.sh "$R")" = 0 ]

# planted FILE SED-SCRIPT MESSAGE NAME: with FILE of the copy edited by SED-SCRIPT the check fails
# naming MESSAGE (a grep pattern) in one line; the file is restored after.
planted() {
    cp "$R/$1" "$T/saved"
    sed "$2" "$T/saved" > "$R/$1"
    if cmp -s "$T/saved" "$R/$1"; then
        echo "FAIL $4: the edit changed nothing"; fail=1
    else
        check "$4 fails" [ "$(rc_of sh tools/scripts/check_docs.sh "$R")" = 1 ]
        check "$4 is named" grep -q "$3" "$T/out"
    fi
    cp "$T/saved" "$R/$1"
}
planted docs/DESIGN.md 's/A new op touches these 5 files/A new op touches these 4 files/' \
    'says a new op touches 4 files but lists 5' "a wrong count of a new op's files"
planted docs/DESIGN.md 's/wrapper): 6 files/wrapper): 5 files/' \
    'weight operand touches 5 files; the lists give 6' "a wrong count of a weight op's files"
planted docs/DESIGN.md 's| `tests/test_ops_kernels.c` and$| and|; s|these 5 files|these 4 files|' \
    'layer_norm touches tests/test_ops_kernels.c, which the list' "a file left out of a new op's list"
planted docs/DESIGN.md 's/`axpy`, `lincomb`, `clamp`, `affine`/`axpy`, `lincomb`, `affine`/' \
    'op clamp of ops/op_list.h is not in the op table' "an op missing from the table"
planted docs/DESIGN.md 's/| binary | `binary`, `scale` |/| binary | `binary`, `scale`, `softmax` |/' \
    'op softmax is not in ops/op_list.h' "an op the list does not have"
planted docs/DESIGN.md 's/| vector | `axpy`, `lincomb`/| embed | `axpy`, `lincomb`/' \
    'op axpy: family embed, but ops/cpu/embed_ref.c does not define mx_axpy_ref' "an op in the wrong family"
planted docs/DESIGN.md 's/`timestep_embedding`, `embed_tokens` | `embed_tokens` |/`timestep_embedding`, `embed_tokens` | — |/' \
    'op embed_tokens: the table says weight operand no' "a wrong weight column"
planted ops/backend.c 's/strict_embed_tokens/strict_embed/g' \
    'op embed_tokens takes a weight but ops/backend.c has no strict wrapper' "a weight op without a strict wrapper"
planted docs/DESIGN.md 's|ops/op_list.h lists 27 ops|ops/op_list.h lists 28 ops|' \
    'says ops/op_list.h lists 28 ops; it lists 27' "a wrong op count"
planted weights/networks.h 's/^#define MX_NET_IP_ADAPTER "ip_adapter"/#define MX_NET_IP_ADAPTER "refiner"/' \
    'network refiner of weights/networks.c is not in the network table' "a network missing from the table"
planted docs/DESIGN.md 's/| `taesd` | `AutoencoderTiny` | no |/| `taesd` | `AutoencoderTiny` | yes |/' \
    'network taesd: in the model set yes in the table, no in' "a wrong model-set flag"
planted docs/DESIGN.md 's|weights/networks.c lists 7 networks|weights/networks.c lists 6 networks|' \
    'says weights/networks.c lists 6 networks; it lists 7' "a wrong network count"
# (section 9 spelled apart, so that this file cites none itself)
planted ops/cpu/norm_ref.c '1s|^|/* the layout: DESIGN.md §''9 */\n|' \
    'ops/cpu/norm_ref.c:1: DESIGN.md §''9: docs/DESIGN.md has no section 9' "a reference to a section that does not exist"
exit $fail
