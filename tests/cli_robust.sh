#!/bin/sh
# What a new user hit (issue 12): flat, single-face and degenerate meshes; impossible options;
# bad output locations found before any work; an existing output folder refused unless --force;
# --json failures with the message; SIGINT/SIGTERM at many moments leave no partial output.
NAME=robust
. "$(dirname "$0")/lib_cli.sh"
A=$(data assets)
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
SMALL="--image-size 64 --steps 1 --texture-size 128 --render-size 128 --candidates 8 --quiet"
FILES="texture.png texture.exr mesh.obj mesh.mtl mesh.glb report.json"

complete() { # complete DIR: every output file is there and nothing else
    for f in $FILES; do [ -s "$1/$f" ] || return 1; done
    [ "$(ls "$1" | wc -l)" -eq 6 ]
}
no_staging() { ! ls -d "$1".partial-* "$1".old-* "$1".matex-lock > /dev/null 2>&1; }

# ---- flat, single-face and degenerate meshes ----
printf 'v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n' > "$T/quad.obj"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n' > "$T/tri.obj"
awk 'BEGIN { n = 10; for (y = 0; y <= n; y++) for (x = 0; x <= n; x++) print "v", x, y, 0;
     for (y = 0; y < n; y++) for (x = 0; x < n; x++) { a = y * (n + 1) + x + 1;
     print "f", a, a + 1, a + n + 2, a + n + 1 } }' > "$T/grid.obj"
printf 'v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n' > "$T/zero.obj"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 4 5\n' > "$T/some_zero.obj"
for m in quad tri grid some_zero; do
    check "$m.obj textures" [ "$(rc_of "$M" texture "$T/$m.obj" "a tile" --weights "$W" -o "$T/o_$m" $SMALL)" = 0 ]
    check "$m.obj: complete output" complete "$T/o_$m"
done
check "coverage of the quad is reported" grep -q '"coverage":' "$T/o_quad/report.json"
check "zero-area mesh exits 1" [ "$(rc_of "$M" texture "$T/zero.obj" "a tile" --weights "$W" -o "$T/o_zero" $SMALL)" = 1 ]
check "the message names the mesh and the problem" grep -q "zero.obj: .*zero area" "$T/err"
check "zero-area mesh: no output" [ ! -e "$T/o_zero" ]
check "zero-area mesh: no staging folder" no_staging "$T/o_zero"
check "transfer onto a quad" [ "$(rc_of "$M" transfer "$T/o_grid/mesh.obj" "$T/quad.obj" --size 128 -o "$T/tq")" = 0 ]
check "transfer onto a quad: mesh.glb" [ -s "$T/tq/mesh.glb" ]
S=$A/cesium_milk_truck/CesiumMilkTruck.glb # 4 materials, some faces without UVs
check "transfer onto its own mesh" [ "$(rc_of "$M" transfer "$S" "$S" --size 256 --json -o "$T/ts")" = 0 ]
check "transfer: --json summary" grep -q '"ok":true' "$T/out"
check "transfer onto its own mesh: PSNR above 20 dB (22.5 measured)" \
    awk -F'"psnr_db":' 'NF > 1 { split($2, v, /[,}]/); ok = v[1] > 20 } END { exit !ok }' "$T/ts/report.json"
check "transfer without a texture on the source exits 1" \
    [ "$(rc_of "$M" transfer "$T/quad.obj" "$T/quad.obj" -o "$T/tx")" = 1 ] && [ ! -e "$T/tx" ]
check "transfer --views 1 exits 2" [ "$(rc_of "$M" transfer "$S" "$T/quad.obj" --views 1 -o "$T/tx")" = 2 ]
check "transfer --size 12x exits 2" [ "$(rc_of "$M" transfer "$S" "$T/quad.obj" --size 12x -o "$T/tx")" = 2 ]
check "transfer onto a single triangle" [ "$(rc_of "$M" transfer "$T/o_grid/mesh.obj" "$T/tri.obj" --size 128 -o "$T/tt")" = 0 ]

# ---- several materials, one without UVs: one PNG + EXR per material, an atlas for the bare one ----
cat > "$T/box.mtl" << 'EOF2'
newmtl wood
Kd 1 1 1
newmtl metal
Kd 1 1 1
EOF2
cat > "$T/box.obj" << 'EOF2'
mtllib box.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl wood
f 4/4 3/3 2/2 1/1
f 6/2 7/3 8/4 5/1
usemtl metal
f 2 6 5 1
f 3 7 6 2
f 4 8 7 3
f 1 5 8 4
EOF2
LOUD=$(echo "$SMALL" | sed 's/--quiet//')
check "two materials, one without UVs" [ "$(rc_of "$M" texture "$T/box.obj" "a box" --weights "$W" -o "$T/box" $LOUD)" = 0 ]
check "the material without UVs is named in a warning" grep -q "material 'metal' have no UVs" "$T/err"
for f in texture_wood.png texture_wood.exr texture_metal.png texture_metal.exr mesh.obj mesh.mtl mesh.glb report.json; do
    check "two materials: $f" [ -s "$T/box/$f" ]
done
check "two materials: no texture.png copy of one of them" [ ! -e "$T/box/texture.png" ] && [ ! -e "$T/box/texture.exr" ]
check "two materials: mesh.mtl maps both" grep -q "map_Kd texture_metal.png" "$T/box/mesh.mtl"
# a uniform grey 128x128 PNG compresses to a few hundred bytes; a painted one does not
check "the atlas material is painted, not grey" [ "$(wc -c < "$T/box/texture_metal.png")" -gt 4000 ]

# ---- impossible options: exit 2, the valid range in the message, nothing written ----
bad_option() { # bad_option EXPECTED_TEXT OPTIONS...
    want=$1; shift
    rc=$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/bad" $SMALL "$@" --json)
    [ "$rc" = 2 ] && grep -qF -- "$want" "$T/err" && grep -qF -- "$want" "$T/out" && grep -q '"ok":false' "$T/out" &&
        [ ! -e "$T/bad" ] && no_staging "$T/bad"
}
check "--frontal-threshold 1.5" bad_option "--frontal-threshold must be a number in [0, 1), not '1.5'" --frontal-threshold 1.5
check "--coverage-stop 2" bad_option "--coverage-stop must be a number in (0, 1], not '2'" --coverage-stop 2
check "--guidance -3" bad_option "--guidance must be a number in [0, 50], not '-3'" --guidance -3
check "--guidance nan exits 2" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/bad" $SMALL --guidance nan)" = 2 ]
check "--depth-weight 1,-1" bad_option "--depth-weight must be one or two numbers (A or A,B) in [0, 2], not '1,-1'" --depth-weight 1,-1
check "--batch 0" bad_option "--batch must be an integer in 1..64, not '0'" --batch 0
check "--texture-size 8" bad_option "--texture-size must be an integer in 16..8192, not '8'" --texture-size 8
check "a bad number with --json: the message in the JSON" \
    [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/bad" --steps ten --json)" = 2 ]
check "... names the option and value" grep -q '"error":"--steps must be an integer in 1..200, not .ten."' "$T/out"
check "empty prompt" [ "$(rc_of "$M" texture "$T/quad.obj" " " --weights "$W" -o "$T/bad" $SMALL)" = 2 ]
check "empty prompt: message" grep -q "prompt is empty" "$T/err"
check "enhance --strength 0" [ "$(rc_of "$M" enhance "$T/o_quad/mesh.obj" --strength 0 --weights "$W" -o "$T/bad")" = 2 ]
check "enhance --strength 0: range" grep -qF "(0, 1]" "$T/err"

# ---- output location: checked before any work (no weights loaded) ----
: > "$T/afile"
check "-o naming a file exits 1" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/afile" $SMALL --json)" = 1 ]
check "-o naming a file: message" grep -q "afile: exists and is not a folder" "$T/err"
check "-o naming a file: --json carries it" grep -q '"error":".*afile: exists and is not a folder"' "$T/out"
"$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/afile" --image-size 64 --steps 1 > /dev/null 2> "$T/err"
check "-o naming a file: refused before the weights load" sh -c "! grep -q 'loaded weights' '$T/err'"
check "unwritable location exits 1" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o /proc/matex_out $SMALL)" = 1 ]
check "unwritable location: message names it" grep -q "/proc/matex_out: cannot create" "$T/err"
if [ "$(id -u)" != 0 ]; then
    mkdir "$T/ro" && chmod 555 "$T/ro"
    check "read-only folder exits 1" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/ro/x" $SMALL)" = 1 ]
    chmod 755 "$T/ro"
fi

# ---- an existing output folder ----
mkdir "$T/empty"
check "an empty existing folder is used" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/empty" $SMALL)" = 0 ]
check "an empty existing folder: complete" complete "$T/empty"
mkdir "$T/full" && echo old > "$T/full/old_texture.png"
check "a non-empty folder is refused" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/full" $SMALL)" = 1 ]
check "a non-empty folder: message says --force" grep -q "not empty (--force replaces it)" "$T/err"
check "a non-empty folder: left alone" [ "$(ls "$T/full")" = old_texture.png ]
# --force replaces only what matex wrote (issue 24: `-o . --force` deleted a user's folder)
check "--force over a user's files: refused" \
    [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/full" $SMALL --force)" = 1 ]
check "... says matex did not write it" grep -q "not written by matex" "$T/err"
check "... and leaves it alone" [ "$(ls "$T/full")" = old_texture.png ] && check "... no staging" no_staging "$T/full"
mkdir "$T/userdir" && cp "$T/quad.obj" "$T/userdir/chair.obj" && echo mine > "$T/userdir/notes.txt"
check "-o . --force in the mesh's folder: refused" \
    [ "$(M_ABS=$(realpath "$M") W_ABS=$(realpath "$W") && cd "$T/userdir" &&
        rc_of "$M_ABS" texture chair.obj "a tile" --weights "$W_ABS" -o . $SMALL --force)" = 1 ]
check "... says why" grep -q "current folder" "$T/err"
check "... the user's files stay" [ -s "$T/userdir/chair.obj" ] && check "... all of them" [ -s "$T/userdir/notes.txt" ]
mkdir "$T/wdir" && cp "$W" "$T/wdir/w.mxw"
check "-o the weights' folder --force: refused" \
    [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$T/wdir/w.mxw" -o "$T/wdir" $SMALL --force)" = 1 ]
check "... says it holds the input" grep -q "holds the input" "$T/err" && check "... the weights stay" [ -s "$T/wdir/w.mxw" ]
rm -rf "$T/full" && mkdir "$T/full"
check "an output of matex's" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/full" $SMALL)" = 0 ]
check "... carries the marker listing its files" grep -q "^report.json$" "$T/full/.matex-output"
check "--force replaces it" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/full" $SMALL --force)" = 0 ]
check "--force: only the new files" complete "$T/full"
check "--force: no staging or old folder left" no_staging "$T/full"
echo mine > "$T/full/notes.txt"
check "--force over matex's output with a user's file added: refused" \
    [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/full" $SMALL --force)" = 1 ]
check "... names the file" grep -q "holds notes.txt, which matex did not write" "$T/err"
rm "$T/full/notes.txt"
mkdir -p "$T/home/docs" && echo keep > "$T/home/docs/letter.txt"
check "--force refuses a folder with sub-folders" \
    [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/home" $SMALL --force)" = 1 ]
check "... says why" grep -q "holds sub-folders" "$T/err"
check "... and leaves it alone" [ -s "$T/home/docs/letter.txt" ] && check "... no staging" no_staging "$T/home"
ln -s "$T/full" "$T/link"
check "--force through a link to a folder" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/link" $SMALL --force)" = 0 ]
check "--force through a link: the link stays a link" [ -L "$T/link" ] && check "... to a complete folder" complete "$T/full"
check "trailing slash" [ "$(rc_of "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/slash/" $SMALL)" = 0 ]
check "trailing slash: complete" complete "$T/slash"

# ---- SIGINT / SIGTERM during start-up: a signal already pending when matex starts (blocked by
# perl, then exec: as one arriving before main could install a handler) is taken by the handler
# once installed: exit 130, "interrupted", nothing written (without that, the run ignored it).
# The default disposition first: a suite started in the background by a shell without job
# control inherits SIGINT ignored, and an ignored signal is never pending ----
pending() { sig=$1; shift; perl -MPOSIX -e '$SIG{INT} = $SIG{TERM} = "DEFAULT";
    sigprocmask(SIG_BLOCK, POSIX::SigSet->new(SIGINT, SIGTERM));
    kill shift(@ARGV), $$; exec @ARGV or exit 127' "$sig" "$@"; }
if perl -MPOSIX -e 1 2> /dev/null; then
    for sig in INT TERM; do
        check "SIG$sig pending at start (texture): exit 130" \
            [ "$(rc_of pending $sig "$M" texture "$T/quad.obj" "a tile" --weights "$W" -o "$T/pend$sig" $SMALL)" = 130 ]
        check "... says interrupted" grep -q "interrupted" "$T/err"
        check "... no output" [ ! -e "$T/pend$sig" ] && check "... no staging" no_staging "$T/pend$sig"
    done
    check "SIGINT pending at start (render): exit 130" \
        [ "$(rc_of pending INT "$M" render "$T/quad.obj" --views 2 --size 32 -o "$T/pendrender")" = 130 ]
    check "... no output" [ ! -e "$T/pendrender" ] && check "... no staging" no_staging "$T/pendrender"
    check "SIGINT pending at start (info, no handler): ends by the signal" \
        [ "$(rc_of pending INT "$M" info "$T/quad.obj")" = 130 ] && check "... silently" [ ! -s "$T/out" ]
else
    echo "NOT TESTED: signals pending at start (no perl POSIX module)"
fi

# ---- matex render is staged like texture: refused over a non-empty folder, --force replaces ----
check "render into a new folder" [ "$(rc_of "$M" render "$T/quad.obj" --views 2 --size 32 -o "$T/rend")" = 0 ]
check "... complete" [ -s "$T/rend/contact_sheet.png" ] && check "... two views" [ -s "$T/rend/view_01.png" ]
check "render over it without --force: refused" [ "$(rc_of "$M" render "$T/quad.obj" --views 1 --size 32 -o "$T/rend")" = 1 ]
check "... says why" grep -q "not empty" "$T/err" && check "... and leaves it" [ -s "$T/rend/view_01.png" ]
check "render --force replaces it" [ "$(rc_of "$M" render "$T/quad.obj" --views 1 --size 32 --force -o "$T/rend")" = 0 ]
check "render --force over the mesh's folder: refused" \
    [ "$(rc_of "$M" render "$T/userdir/chair.obj" --views 1 --size 32 --force -o "$T/userdir")" = 1 ]
check "... the user's files stay" [ -s "$T/userdir/chair.obj" ] && check "... all of them" [ -s "$T/userdir/notes.txt" ]
check "... with only the new views" [ ! -e "$T/rend/view_01.png" ] && check "... complete" [ -s "$T/rend/contact_sheet.png" ]
check "render of a missing mesh: exit 1" [ "$(rc_of "$M" render "$T/none.obj" -o "$T/rendbad")" = 1 ]
check "... no folder, no staging" [ ! -e "$T/rendbad" ] && check "... no staging" no_staging "$T/rendbad"

# ---- SIGINT / SIGTERM at moments of the run: exit 130 and nothing, or exit 0 and everything.
# Each signal is sent DELAY seconds after the staging folder appeared (the run is then past
# start-up with its handler installed), so the outcome does not depend on the machine's load;
# the first delays always interrupt. (A 1024 texture makes the fill and export about half the run.) ----
LONG="--image-size 64 --steps 2 --texture-size 1024 --render-size 256 --candidates 12 --quiet"
interrupted=0
i=0
for delay in 0 0.3 0.6 1.0 1.4 2.0; do
    i=$((i + 1))
    sig=INT
    [ $((i % 2)) = 0 ] && sig=TERM
    out="$T/sig$i"
    "$M" texture "$A/fedora_hat/fedora.obj" "a hat" --weights "$W" -o "$out" $LONG > /dev/null 2> "$T/err" &
    pid=$!
    n=0 # wait for the staging folder (at most 120 s) or the end of the run
    while [ $n -lt 1200 ] && ! ls -d "$out".partial-* > /dev/null 2>&1 && kill -0 $pid 2> /dev/null; do
        sleep 0.1
        n=$((n + 1))
    done
    sleep $delay
    kill -$sig $pid 2> /dev/null
    wait $pid
    rc=$?
    if [ $rc = 130 ]; then
        interrupted=$((interrupted + 1))
        check "SIG$sig ${delay}s after staging: interrupted, no output" [ ! -e "$out" ]
        check "SIG$sig ${delay}s after staging: says interrupted" grep -q "interrupted" "$T/err"
    else
        check "SIG$sig ${delay}s after staging: finished (exit $rc) with a complete folder" complete "$out"
    fi
    check "SIG$sig ${delay}s after staging: no staging folder" no_staging "$out"
done
check "the signals sent right after staging interrupted ($interrupted of $i)" [ $interrupted -ge 2 ]

# waits (at most 120 s) for the staging folder of output $1 of the run $2
wait_staging() {
    n=0
    while [ $n -lt 1200 ] && ! ls -d "$1".partial-* > /dev/null 2>&1 && kill -0 $2 2> /dev/null; do
        sleep 0.1
        n=$((n + 1))
    done
}

# ---- two runs into one output folder at once: the second is refused at once, saying why; the
# first completes (issue 24 item 12) ----
"$M" texture "$A/fedora_hat/fedora.obj" "a hat" --weights "$W" -o "$T/both" $LONG > /dev/null 2> "$T/err1" &
pid=$!
wait_staging "$T/both" $pid
check "a second run into the folder a run is writing: exit 1" \
    [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" "a hat" --weights "$W" -o "$T/both" $SMALL)" = 1 ]
check "... says another matex run is writing it" grep -q "another matex run is writing this output folder" "$T/err"
wait $pid
check "... the first run completes" [ $? = 0 ] && check "... its folder complete" complete "$T/both"
check "... no staging or lock left" no_staging "$T/both"

# ---- a second signal ends the run at once, still leaving nothing behind: the run is stopped
# (SIGSTOP) while both are sent, so both arrive before it can act on the first ----
"$M" texture "$A/fedora_hat/fedora.obj" "a hat" --weights "$W" -o "$T/twice" $LONG > /dev/null 2> "$T/err" &
pid=$!
wait_staging "$T/twice" $pid
signal_twice $pid
rc=$?
check "two signals: exit 130" [ $rc = 130 ]
check "... stopped at the second" grep -q "interrupted again, stopped now" "$T/err"
check "... no output" [ ! -e "$T/twice" ] && check "... no staging or lock" no_staging "$T/twice"
exit $fail
