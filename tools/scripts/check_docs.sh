#!/bin/sh
# check_docs.sh [ROOT]: the counts and names docs/DESIGN.md states that can be computed match the
# code. Prints one line per mismatch (docs/DESIGN.md:LINE: what) and exits 1 if there is one.
# `make check` runs it; tests/cli_check_docs.sh runs it in `make test` and plants wrong claims.
#
# What it reads in DESIGN.md (keep these forms when editing the map):
# - the op table, under the header "| family | ops | ops with a weight operand |": each op of
#   ops/op_list.h exactly once, in the family whose ops/cpu/<family>_ref.c defines mx_<op>_ref and
#   whose ops/cuda/cuda_<family>.cu defines mx_cuda_<op>; its weight column true exactly for the
#   ops with an mx_wptr parameter, and each of those with its strict wrapper strict_<op> in
#   ops/backend.c; and the sentence "ops/op_list.h lists N ops";
# - the network table, under "| network | config class | in the model set |": the names, config
#   classes and model-set flags of weights/networks.c, and "weights/networks.c lists N networks";
# - the sentence "A new op touches these N files: `a`, ...; an op with a weight operand also
#   touches `x`, ...: M files ... (the list as `op1` and `op2` touch it)": N and M are the lengths
#   of the lists, and each named op touches exactly those files (<family> replaced by its family):
#   the files that hold its list entry, its reference, its CUDA kernel, its strict wrapper, or name
#   its wrapper, table entry or CUDA kernel in the op tests (tests/test_ops_*.c, tests/cuda/*.c);
# - and, in the docs and the code, every "DESIGN.md §n" (cuda-notes, PERFORMANCE) names a section.
root=${1:-.}
cd "$root" || exit 2
design=docs/DESIGN.md
for f in $design ops/op_list.h ops/backend.c weights/networks.c; do
    [ -f "$f" ] || { echo "check_docs: $root/$f: missing" >&2; exit 2; }
done
tmp=$(mktemp -d "${TMPDIR:-/tmp}/check_docs.XXXXXX") || exit 2
trap 'rm -rf "$tmp"' EXIT
bad=0
report() { echo "$design:$1: $2"; bad=$((bad + 1)); }

# ---- the code's facts ----
# "op weight" per op of the MX_OPS X-macro (weight 1 when its parameters hold an mx_wptr)
awk '/^#define MX_OPS\(X\)/ { on = 1; next }
     on && match($0, /X\([a-z_0-9]+,/) { if (op != "") print op, w; op = substr($0, RSTART + 2, RLENGTH - 3); w = 0 }
     on && op != "" && /mx_wptr/ { w = 1 }
     on && !/\\$/ { on = 0 }
     END { if (op != "") print op, w }' ops/op_list.h > "$tmp/ops"
[ -s "$tmp/ops" ] || { echo "check_docs: no ops found in ops/op_list.h" >&2; exit 2; }
# "name class in_model_set" per entry of weights/networks.c (names are weights/networks.h's MX_NET_*)
awk 'FNR == NR { if ($1 == "#define" && $2 ~ /^MX_NET_/ && $3 ~ /^"/) { v = $3; gsub(/"/, "", v); names[$2] = v }; next }
     match($0, /\.name = MX_NET_[A-Z_]*/) {
         n = names[substr($0, RSTART + 8, RLENGTH - 8)]; c = "-"; m = 0
         if (match($0, /\.class_name = "[^"]*"/)) c = substr($0, RSTART + 15, RLENGTH - 16)
         if (match($0, /\.in_model_set = [01]/)) m = substr($0, RSTART + RLENGTH - 1, 1)
         print n, c, m
     }' weights/networks.h weights/networks.c > "$tmp/nets"

# ---- the map's claims ----
# rows of the markdown table under a header line holding $1: "LINE|cell|cell|..." (cells trimmed,
# backticks dropped)
table_rows() {
    awk -v head="$1" 'index($0, head) { on = 1; getline; next }
        on && /^[ \t]*\|/ { line = $0; gsub(/`/, "", line); sub(/^[ \t]*\|/, "", line); sub(/\|[ \t]*$/, "", line)
                           n = split(line, c, "|"); out = FNR
                           for (i = 1; i <= n; i++) { gsub(/^[ \t]+|[ \t]+$/, "", c[i]); out = out "|" c[i] }
                           print out; next }
        on { on = 0 }' "$design"
}
# "LINE family op weight" for each op of the op table
table_rows "| family | ops | ops with a weight operand |" | awk -F'|' '{
    nw = split($4, w, /, */); delete hw
    for (i = 1; i <= nw; i++) hw[w[i]] = 1
    n = split($3, o, /, */)
    for (i = 1; i <= n; i++) print $1, $2, o[i], (o[i] in hw) ? 1 : 0
}' > "$tmp/doc_ops"
table_rows "| network | config class | in the model set |" |
    awk -F'|' '{ print $1, $2, $3, ($4 == "yes") ? 1 : 0 }' > "$tmp/doc_nets"
[ -s "$tmp/doc_ops" ] || report 1 "no op table (header \"| family | ops | ops with a weight operand |\")"
[ -s "$tmp/doc_nets" ] || report 1 "no network table (header \"| network | config class | in the model set |\")"

# the line of the first match of an extended regular expression, and the number in its match
line_of() { grep -nE "$1" "$design" | head -n 1 | cut -d: -f1; }
number_in() { grep -oE "$1" "$design" | head -n 1 | grep -oE '[0-9]+' | head -n 1; }
yes_no() { if [ "$1" = 1 ]; then echo yes; else echo no; fi; }
# not_in_code KIND FILE COLUMN DOC_ROWS CODE_ROWS: each name in COLUMN of the map's rows ("LINE ...")
# that is not the first word of a row of the code's is reported
not_in_code() {
    awk -v col="$3" 'NR == FNR { have[$1] = 1; next } !($col in have) { print $1, $col }' "$5" "$4" > "$tmp/missing"
    while read -r line name; do report "$line" "$1 $name is not in $2"; done < "$tmp/missing"
}
# count_claim FILE NOUN N: the map's "FILE lists M NOUN" says M = N
count_claim() {
    said=$(number_in "$1 lists [0-9]+ $2")
    [ "$said" = "$3" ] || report "$(line_of "$1 lists [0-9]+ $2")" "says $1 lists ${said:-?} $2; it lists $3"
}

# ---- ops ----
while read -r op w; do
    rows=$(awk -v op="$op" '$3 == op' "$tmp/doc_ops")
    if [ -z "$rows" ]; then
        report "$(line_of '\| family \| ops \|')" "op $op of ops/op_list.h is not in the op table"
        continue
    fi
    [ "$(printf '%s\n' "$rows" | wc -l)" -eq 1 ] || report "$(echo "$rows" | awk 'NR == 2 { print $1 }')" "op $op is in the op table twice"
    set -- $rows # LINE FAMILY OP WEIGHT: split on purpose
    line=$1 fam=$2 dw=$4
    grep -q "^void mx_${op}_ref(" "ops/cpu/${fam}_ref.c" 2> /dev/null ||
        report "$line" "op $op: family $fam, but ops/cpu/${fam}_ref.c does not define mx_${op}_ref"
    grep -qE "^[A-Za-z].*[^A-Za-z0-9_]mx_cuda_${op}\(" "ops/cuda/cuda_${fam}.cu" 2> /dev/null ||
        report "$line" "op $op: family $fam, but ops/cuda/cuda_${fam}.cu does not define mx_cuda_${op}"
    [ "$dw" = "$w" ] || report "$line" "op $op: the table says weight operand $(yes_no "$dw"), ops/op_list.h $(yes_no "$w")"
    [ "$w" = 1 ] && ! grep -q "[^A-Za-z0-9_]strict_${op}(" ops/backend.c &&
        report "$line" "op $op takes a weight but ops/backend.c has no strict wrapper strict_$op"
done < "$tmp/ops"
not_in_code op ops/op_list.h 3 "$tmp/doc_ops" "$tmp/ops"
nops=$(wc -l < "$tmp/ops" | tr -d ' ')
count_claim ops/op_list.h ops "$nops"

# ---- networks ----
while read -r name class set; do
    row=$(awk -v n="$name" '$2 == n' "$tmp/doc_nets")
    if [ -z "$row" ]; then
        report "$(line_of '\| network \| config class \|')" "network $name of weights/networks.c is not in the network table"
        continue
    fi
    set -- $row # LINE NAME CLASS SET: split on purpose
    [ "$3" = "$class" ] || report "$1" "network $name: config class $3 in the table, $class in weights/networks.c"
    [ "$4" = "$set" ] || report "$1" "network $name: in the model set $(yes_no "$4") in the table, $(yes_no "$set") in weights/networks.c"
done < "$tmp/nets"
not_in_code network weights/networks.c 2 "$tmp/doc_nets" "$tmp/nets"
nnets=$(wc -l < "$tmp/nets" | tr -d ' ')
count_claim weights/networks.c networks "$nnets"

# ---- the files a new op touches ----
sline=$(line_of 'A new op touches these')
# the sentence, from "A new op touches these" to "touch it)", on one line
awk -v from="${sline:-0}" 'FNR >= from && from > 0 { s = s " " $0; if (index($0, "touch it)")) exit }
    END { gsub(/[ \t]+/, " ", s); print s }' "$design" > "$tmp/sentence"
sentence=$(cat "$tmp/sentence")
case "$sentence" in
*"A new op touches these "*" files: "*"; an op with a weight operand also touches "*" files"*"(the list as "*" touch it)"*) ;;
*)
    report "${sline:-1}" "no sentence \"A new op touches these N files: ...; an op with a weight operand also touches ...: M files ... (the list as \`op\` and \`op\` touch it)\""
    sline=
    ;;
esac
if [ -n "$sline" ]; then
    # backticked words of a part of the sentence, one a line
    ticks() { printf '%s\n' "$1" | grep -oE '`[^`]+`' | tr -d '`'; }
    base_part=${sentence#*A new op touches these }
    base_part=${base_part%%; an op with a weight operand*}
    extra_part=${sentence#*; an op with a weight operand also touches }
    extra_part=${extra_part%%files*}
    ops_part=${sentence#*(the list as }
    ops_part=${ops_part%%touch it)*}
    ticks "$base_part" | sort > "$tmp/base"
    ticks "$extra_part" | sort > "$tmp/extra"
    n=$(printf '%s\n' "$base_part" | grep -oE '^[0-9]+')
    m=$(printf '%s\n' "$extra_part" | grep -oE '[0-9]+ *$' | tr -d ' ')
    nb=$(wc -l < "$tmp/base" | tr -d ' ')
    ne=$(wc -l < "$tmp/extra" | tr -d ' ')
    [ "$n" = "$nb" ] || report "$sline" "says a new op touches ${n:-?} files but lists $nb"
    [ "$m" = "$((nb + ne))" ] || report "$sline" "says an op with a weight operand touches ${m:-?} files; the lists give $((nb + ne))"
    for op in $(ticks "$ops_part"); do
        fam=$(awk -v op="$op" '$3 == op { print $2 }' "$tmp/doc_ops")
        w=$(awk -v op="$op" '$1 == op { print $2 }' "$tmp/ops")
        if [ -z "$fam" ] || [ -z "$w" ]; then
            report "$sline" "the example op $op is not an op of the table and ops/op_list.h"
            continue
        fi
        { sed "s/<family>/$fam/g" "$tmp/base"; [ "$w" = 1 ] && cat "$tmp/extra"; } | sort -u > "$tmp/want"
        {
            grep -l "X($op," ops/op_list.h
            grep -l "^void mx_${op}_ref(" ops/cpu/*_ref.c
            grep -lE "^[A-Za-z].*[^A-Za-z0-9_]mx_cuda_${op}\(" ops/cuda/*.cu
            grep -l "[^A-Za-z0-9_]strict_${op}(" ops/backend.c
            grep -lE "(mx_|mx_cuda_|->)${op}([^A-Za-z0-9_]|\$)" tests/test_ops_*.c tests/cuda/*.c
        } 2> /dev/null | sort -u > "$tmp/got"
        comm -23 "$tmp/want" "$tmp/got" | while read -r f; do
            echo "$design:$sline: a new op touches $f, but $op does not"
        done > "$tmp/diff"
        comm -13 "$tmp/want" "$tmp/got" | while read -r f; do
            echo "$design:$sline: $op touches $f, which the list of a new op's files leaves out"
        done >> "$tmp/diff"
        if [ -s "$tmp/diff" ]; then
            cat "$tmp/diff"
            bad=$((bad + $(wc -l < "$tmp/diff")))
        fi
    done
fi

# ---- section references ----
# "DESIGN.md §4", "docs/cuda-notes.md §3", "cuda-notes §5" in the docs and the code name a heading
# "## 4." of that file in docs/. README.md is left out until its Speed section, which still cites
# the GPU timings' old section, gives way to docs/PERFORMANCE.md (issue 41's README rewrite).
find . -path ./.git -prune -o -path './build*' -prune -o -path ./tests/data -prune -o -type f \
    \( -name '*.md' -o -name '*.c' -o -name '*.h' -o -name '*.inc' -o -name '*.cpp' -o -name '*.cu' \
    -o -name '*.cuh' -o -name '*.sh' -o -name Makefile \) ! -path ./README.md -print | sort > "$tmp/files"
xargs grep -noE '(DESIGN|cuda-notes|PERFORMANCE)(\.md)? §[0-9]+' < "$tmp/files" > "$tmp/refs" 2> /dev/null
while IFS=: read -r file line ref; do
    doc=docs/$(printf '%s\n' "$ref" | sed 's/[ .].*//').md
    sec=${ref##*§}
    grep -q "^## $sec\." "$doc" 2> /dev/null && continue
    echo "${file#./}:$line: $ref: $doc has no section $sec"
    bad=$((bad + 1))
done < "$tmp/refs"

if [ $bad -gt 0 ]; then
    echo "check_docs: $bad claims of the docs do not match the code"
    exit 1
fi
echo "check_docs: $design's $nops ops, $nnets networks and a new op's files match the code; $(wc -l < "$tmp/refs" | tr -d ' ') section references name a section"
