#!/bin/sh
# make check (tools/scripts/check_paths.sh): every repository path named in docs and code exists; and the
# checker itself fails on a planted missing path, in prose and in a code comment, while patterns
# (tests/test_<folder>_<name>.c), output folders (out/chair) and trailing punctuation pass.
NAME=check_paths
. "$(dirname "$0")/lib_cli.sh"

check "every path named in docs and code exists" sh tools/scripts/check_paths.sh .

# A small tree; its paths are spelled through $t and $d so that this file names none itself.
R="$T/repo" t=tools d=docs
mkdir -p "$R/$t" "$R/$d"
echo 'echo' > "$R/$t/real.sh"
printf '# r\nSee %s/real.sh, %s/ and %s/real.sh:12. Results go to out/chair;\n' $t $d $t > "$R/README.md"
printf 'tests of a folder: %s/test_<folder>_<name>.c, %s/%%s.c, %s/*.sh.\n' $t $t $t >> "$R/README.md"
check "a tree whose paths exist passes" [ "$(rc_of sh tools/scripts/check_paths.sh "$R")" = 0 ]
printf 'Written by %s/gone.c.\n' $t > "$R/$d/notes.md"
printf '/* the format: %s/nothere.md */\nint x;\n' $d > "$R/$t/a.c"
check "a missing path fails" [ "$(rc_of sh tools/scripts/check_paths.sh "$R")" = 1 ]
check "the missing prose path is named with its file and line" grep -q "^./$d/notes.md:1: $t/gone.c: no such file" "$T/out"
check "the missing path of a comment is named" grep -q "^./$t/a.c:1: $d/nothere.md: no such file" "$T/out"
check "only the two missing paths are reported" [ "$(grep -c 'no such file' "$T/out")" = 2 ]
exit $fail
