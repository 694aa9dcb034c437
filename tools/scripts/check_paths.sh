#!/bin/sh
# check_paths.sh [ROOT]: every repository path named in the docs (*.md), the code (comments and
# strings of *.c *.h *.cpp *.cu *.sh, the Makefile, .ci/run) exists. Prints one line per missing
# path (file:line: path) and exits 1 if there is one. `make check` runs it; tests/cli_check_paths.sh
# runs it in `make test` and checks that it fails on a planted bad path.
#
# What counts as a path: a word of letters, digits and . _ - / whose first part is a folder at the
# top of ROOT (ops/, tests/, docs/, ...) and that has a second part ("tests/data", "ops/cpu/gemm.c").
# Trailing punctuation and a ":LINE" suffix are dropped. Words with a placeholder (<op>, %s, $X, *,
# {a,b}) are patterns, not paths, and are passed over. Paths into ../shared (the test data beside
# the repository) are checked only when ../shared exists. Paths made by a build or a run (build*/,
# demo/, out/) are not repository files: their first part is not a repository folder.
root=${1:-.}
cd "$root" || exit 2

# Top folders of the repository, as an awk regular expression: ^(ops|runtime|...)/
tops=$(for d in */ .ci/; do
    [ -d "$d" ] || continue
    case "$d" in build*/ | demo/ | out/) continue ;; esac
    printf '%s|' "${d%/}"
done)
tops=$(printf '%s' "$tops" | sed 's/|$//; s/\./\\./g')
[ -n "$tops" ] || { echo "check_paths: no folders under $root" >&2; exit 2; }

shared=0
[ -d ../shared ] && shared=1

files=$(find . -path ./.git -prune -o -path './build*' -prune -o -path ./tests/data -prune -o -type f \
    \( -name '*.md' -o -name '*.c' -o -name '*.h' -o -name '*.cpp' -o -name '*.cu' -o -name '*.sh' \
    -o -name Makefile -o -path ./.ci/run \) -print | sort)
# tests/data holds data; only its README is prose
[ -f tests/data/README.md ] && files="$files ./tests/data/README.md"

# file:line:word for every candidate word
awk -v tops="^(($tops)|\\.\\./shared)/" -v shared="$shared" '
{
    line = $0
    while (match(line, /[A-Za-z0-9_.\/<>{}*%$-]+/)) {
        w = substr(line, RSTART, RLENGTH)
        line = substr(line, RSTART + RLENGTH)
        if (w ~ /[<>{}*%$]/) continue           # a pattern, not a path
        sub(/[.:,-]+$/, "", w)
        if (w !~ tops) continue
        if (w ~ /^\.\.\/shared\// && !shared) continue
        print FILENAME ":" FNR ":" w
    }
}' $files | sort -t: -k3,3 -u > "${TMPDIR:-/tmp}/check_paths.$$"

missing=0
while IFS=: read -r file line word; do
    [ -e "$word" ] && continue
    echo "$file:$line: $word: no such file or folder"
    missing=$((missing + 1))
done < "${TMPDIR:-/tmp}/check_paths.$$"
n=$(wc -l < "${TMPDIR:-/tmp}/check_paths.$$")
rm -f "${TMPDIR:-/tmp}/check_paths.$$"
if [ $missing -gt 0 ]; then
    echo "check_paths: $missing of $n paths named in docs and code do not exist"
    exit 1
fi
echo "check_paths: all $n paths named in docs and code exist"
