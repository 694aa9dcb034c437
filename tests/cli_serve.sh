#!/bin/sh
# `matex serve` end to end, curl as the client (make test-serve; docs/SERVE.md): a job through the
# server gives the CLI's outputs byte for byte; the bad requests, each with its status and error
# body while the server keeps serving; the token, Host and Origin rules; 4 clients submitting 20
# jobs; kill -9 during a job and a restart (the job runs again once, then fails); the jobs folder's
# marker and lock; retention; matex batch --server, with meshes that come with side files (a zip).
NAME=serve
. tests/lib_cli.sh
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
BOX=tests/data/box.obj
SMALL='"steps": 1, "image-size": 64, "texture-size": 64, "render-size": 64, "candidates": 4, "views": 2'
SMALL_CLI="--steps 1 --image-size 64 --texture-size 64 --render-size 64 --candidates 4 --views 2"
command -v curl > /dev/null || { echo "FAIL curl is not installed (apt-get install curl)"; exit 1; }

SPID=
stop_server() { # SIGTERM, then the server must end cleanly
    [ -n "$SPID" ] || return 0
    kill -TERM "$SPID" 2> /dev/null
    wait "$SPID"
    rc=$?
    SPID=
    return $rc
}
trap 'stop_server; rm -rf "$T"' EXIT

start_server() { # start_server LOG ARGS...: matex serve on a free loopback port; sets SPID and URL
    log=$1
    shift
    "$M" serve --weights "$W" --listen 127.0.0.1:0 --threads 2 "$@" 2> "$log" &
    SPID=$!
    i=0
    while ! grep -q 'listening on' "$log" 2> /dev/null && [ $i -lt 600 ] && kill -0 "$SPID" 2> /dev/null; do
        sleep 0.1
        i=$((i + 1))
    done
    URL=http://127.0.0.1:$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/v1.*|\1|p' "$log")
}

# expect NAME STATUS CODE CURL_ARGS...: the answer's HTTP status, and for an error the body
# {"error": {"code": CODE, "message": ...}} ("-": a success, no error body)
expect() {
    ename=$1 estatus=$2 ecode=$3
    shift 3
    got=$(curl -s -o "$T/body" -w '%{http_code}' "$@")
    if [ "$got" != "$estatus" ]; then
        echo "FAIL $ename: HTTP $got, not $estatus: $(head -c 300 "$T/body")"
        fail=1
    elif [ "$ecode" != - ] && ! grep -q "^{\"error\":{\"code\":\"$ecode\",\"message\":\"..*\"}}$" "$T/body"; then
        echo "FAIL $ename: not the error body of $ecode: $(head -c 300 "$T/body")"
        fail=1
    else
        echo "ok   $ename ($estatus${ecode#-})"
    fi
}

submit() { # submit OPTIONS_FILE [CURL_ARGS...]: prints the new job's id
    o=$1
    shift
    curl -s -F "mesh=@$BOX" -F "options=<$o" "$@" "$URL/v1/jobs" | sed -n 's/^{"id":"\([0-9a-z]*\)"}$/\1/p'
}

state_of() { curl -s "$URL/v1/jobs/$1" | sed -n 's/^{"id":"[0-9a-z]*","state":"\([a-z]*\)".*/\1/p'; }

wait_state() { # wait_state ID STATE...: until the job is in one of the states (60 s at most)
    wid=$1
    shift
    i=0
    while [ $i -lt 600 ]; do
        s=$(state_of "$wid")
        for want in "$@"; do [ "$s" = "$want" ] && return 0; done
        sleep 0.1
        i=$((i + 1))
    done
    echo "     job $wid is '$s', not $*"
    return 1
}

# report.json without its time and path fields
report_core() {
    sed -E 's/"(stages_s|work_s)":\{[^}]*\}/"\1":{}/g; s/"([a-z_]+_s|seconds)":[-0-9.e+]+/"\1":0/g; s/"(mesh|weights)":"[^"]*"/"\1":""/g' "$1"
}

# ---- one server for the job tests and the bad requests ----
start_server "$T/log1" --jobs "$T/jobs" --max-upload-mb 1 --client-timeout 2
check "serve: listens" [ -n "${URL#http://127.0.0.1:}" ]
expect "health" 200 - "$URL/v1/health"
check "health body" grep -qx '{"ok":true}' "$T/body"
expect "info" 200 - "$URL/v1/info"
check "info: version, device, weight digest" grep -q '"version":.*"device":"cpu".*"weights_digest":"[0-9a-f]\{16\}"' "$T/body"
# the demo set holds every network but TAESD
check "info: the networks, loaded or not" grep -q '"networks":\[{"name":"unet","class":"UNet2DConditionModel","loaded":true},{"name":"controlnet","class":"ControlNetModel","loaded":true},{"name":"vae","class":"AutoencoderKL","loaded":true},{"name":"text_encoder","class":"CLIPTextModel","loaded":true},{"name":"taesd","class":"AutoencoderTiny","loaded":false},{"name":"image_encoder","class":"CLIPVisionModelWithProjection","loaded":true},{"name":"ip_adapter","class":"IPAdapter","loaded":true}\]' "$T/body"

# byte-identical to the CLI with the same options
printf '{"prompt": "a wooden crate", "seed": 11, %s}\n' "$SMALL" > "$T/opts.json"
ID=$(submit "$T/opts.json")
check "submit: 202 with an id" [ -n "$ID" ]
check "job done" wait_state "$ID" done
$M texture $BOX "a wooden crate" --weights "$W" --seed 11 $SMALL_CLI --threads 2 --quiet -o "$T/cli" 2> "$T/cli.err"
for f in mesh.glb mesh.obj mesh.mtl texture.png texture.exr report.json; do
    curl -s -o "$T/srv_$f" "$URL/v1/jobs/$ID/files/$f"
done
for f in mesh.glb mesh.obj mesh.mtl texture.png texture.exr; do
    check "server = CLI: $f" cmp -s "$T/srv_$f" "$T/cli/$f"
done
report_core "$T/cli/report.json" > "$T/r_cli"
report_core "$T/srv_report.json" > "$T/r_srv"
check "server = CLI: report.json but its time and path fields" cmp -s "$T/r_cli" "$T/r_srv"
check "report.json has the times the comparison leaves out" grep -q '"total_s":[0-9]' "$T/srv_report.json"
expect "GET job: done with its files" 200 - "$URL/v1/jobs/$ID"
check "GET job lists the files" grep -q '"files":\["mesh.glb","mesh.mtl","mesh.obj","report.json","texture.exr","texture.png"\]' "$T/body"
curl -s -N --max-time 20 "$URL/v1/jobs/$ID/events" > "$T/events"
check "events: progress events, then end" sh -c "grep -q '^event: progress' '$T/events' && tail -n 3 '$T/events' | grep -q '^event: end' && tail -n 2 '$T/events' | grep -q '^data: {\"id\":\"$ID\",\"state\":\"done\"'"
check "events: the CLI's progress stream" grep -q '^data: {"event":"step","stage":"grid","step":1,"steps":1,' "$T/events"
expect "GET /v1/jobs lists it" 200 - "$URL/v1/jobs"
check "list" grep -q "\"id\":\"$ID\"" "$T/body"

# ---- a .zip mesh part: an OBJ with its .mtl and texture gives the CLI's outputs on the unzipped files ----
mkdir -p "$T/z/crate/tex"
{ echo 'mtllib crate.mtl'; echo 'usemtl wood'; cat "$BOX"; } > "$T/z/crate/crate.obj"
printf 'newmtl wood\nKd 1 1 1\nmap_Kd tex/wood.png\n' > "$T/z/crate/crate.mtl"
cp "$T/cli/texture.png" "$T/z/crate/tex/wood.png"
(cd "$T/z" && zip -qr ../crate.zip crate)
ZID=$(curl -s -F "mesh=@$T/crate.zip" -F "options=<$T/opts.json" "$URL/v1/jobs" | sed -n 's/^{"id":"\([0-9a-z]*\)"}$/\1/p')
check "zip: 202 with an id" [ -n "$ZID" ]
check "zip: unpacked in the job's folder, the archive removed" sh -c "[ -f '$T/jobs/$ZID/mesh/crate/tex/wood.png' ] && [ ! -e '$T/jobs/$ZID/mesh.zip' ]"
check "zip: job done" wait_state "$ZID" done
$M texture "$T/z/crate/crate.obj" "a wooden crate" --weights "$W" --seed 11 $SMALL_CLI --threads 2 --quiet -o "$T/zcli" 2> "$T/zcli.err"
for f in mesh.glb mesh.obj mesh.mtl texture.png texture.exr; do
    curl -s -o "$T/zsrv_$f" "$URL/v1/jobs/$ZID/files/$f"
    check "zip: server = CLI on the unzipped files: $f" cmp -s "$T/zsrv_$f" "$T/zcli/$f"
done
# bad archives: each refused with its status and error body, nothing left in the upload folder.
# Names the zip tool will not write are patched in place (same length: the offsets stay valid).
zipof() { # zipof NAME FILE...: a zip of the files (paths relative to $T/z) as $T/NAME.zip
    zn=$1
    shift
    rm -f "$T/$zn.zip"
    (cd "$T/z" && zip -qry "../$zn.zip" "$@")
}
cp "$T/z/crate/crate.obj" "$T/z/crate/xx.obj"
zipof two crate/crate.obj crate/xx.obj crate/crate.mtl
rm "$T/z/crate/xx.obj"
expect "zip: two meshes" 400 bad_zip -F "mesh=@$T/two.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: two meshes: says so" grep -q 'holds 2 mesh files' "$T/body"
zipof none crate/crate.mtl crate/tex/wood.png
expect "zip: no mesh" 400 bad_zip -F "mesh=@$T/none.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
zipof trav crate/crate.obj crate/crate.mtl crate/tex/wood.png
LC_ALL=C sed -i 's|crate/tex/w|crate/../xw|g' "$T/trav.zip"
expect "zip: traversal in an entry name" 400 bad_zip -F "mesh=@$T/trav.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: traversal in an entry name: says why" grep -q "entry 'crate/../xwood.png': not a plain relative name" "$T/body"
zipof abs crate/crate.obj crate/crate.mtl
LC_ALL=C sed -i 's|crate/crate\.mtl|/tmp/ccrate.mtl|g' "$T/abs.zip"
expect "zip: an absolute entry name" 400 bad_zip -F "mesh=@$T/abs.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: an absolute entry name: says why" grep -q "entry '/tmp/ccrate.mtl': not a plain relative name" "$T/body"
ln -s /etc/passwd "$T/z/crate/passwd.png"
zipof link crate/crate.obj crate/passwd.png
rm "$T/z/crate/passwd.png"
expect "zip: a symbolic link" 400 bad_zip -F "mesh=@$T/link.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: a symbolic link: says why" grep -q "is a symbolic link" "$T/body"
head -c 20000000 /dev/zero > "$T/z/crate/tex/bomb.png"
zipof bomb crate/crate.obj crate/tex/bomb.png
rm "$T/z/crate/tex/bomb.png"
expect "zip: a bomb (20 MB of zeros in $(wc -c < "$T/bomb.zip") bytes)" 413 too_large -F "mesh=@$T/bomb.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: a bomb: says why" grep -q "a zip bomb" "$T/body"
head -c $(($(wc -c < "$T/crate.zip") - 30)) "$T/crate.zip" > "$T/trunc.zip"
expect "zip: truncated" 400 bad_zip -F "mesh=@$T/trunc.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: truncated: says why" grep -q "truncated" "$T/body"
printf 'newmtl wood\nmap_Kd ../../../../../../../../../../../../../../../..%s\n' "$T/cli/texture.png" > "$T/z/crate/crate.mtl"
zipof outside crate/crate.obj crate/crate.mtl
printf 'newmtl wood\nKd 1 1 1\nmap_Kd tex/wood.png\n' > "$T/z/crate/crate.mtl"
expect "zip: a texture outside the archive" 400 bad_mesh -F "mesh=@$T/outside.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: a texture outside the archive: says why" grep -q "names a texture outside the archive" "$T/body"
expect "zip: not a zip" 400 bad_zip -F "mesh=@$BOX;filename=box.zip" -F "options=<$T/opts.json" "$URL/v1/jobs"
check "zip: nothing left behind by the refused archives" sh -c "[ -z \"\$(ls '$T/jobs/.incoming')\" ] && [ ! -e /tmp/ccrate.mtl ]"

# ---- bad requests: each answered with its status and error body ----
printf '{"prompt": "x", %s' "$SMALL" > "$T/bad_json"
expect "malformed JSON" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_json" "$URL/v1/jobs"
printf '["prompt"]' > "$T/bad_arr"
expect "options not an object" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_arr" "$URL/v1/jobs"
{ printf '{"prompt": "'; head -c 70000 /dev/zero | tr '\0' a; printf '"}'; } > "$T/big_json"
expect "oversized options" 413 too_large -F "mesh=@$BOX" -F "options=<$T/big_json" "$URL/v1/jobs"
printf '{"prompt": "x", "steps": "many"}' > "$T/bad_type"
expect "wrong type" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_type" "$URL/v1/jobs"
printf '{"prompt": 3}' > "$T/bad_prompt"
expect "prompt not a string" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_prompt" "$URL/v1/jobs"
printf '{"prompt": "x", "colour": "red"}' > "$T/bad_key"
expect "unknown key" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_key" "$URL/v1/jobs"
check "unknown key: the CLI's message" grep -q 'unknown key \\"colour\\"' "$T/body"
printf '{"prompt": "x", "threads": 1}' > "$T/bad_models"
expect "a model-set key" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_models" "$URL/v1/jobs"
printf '{"prompt": "x", "mesh": "/etc/passwd"}' > "$T/bad_mesh_key"
expect "mesh as a key" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_mesh_key" "$URL/v1/jobs"
printf '{"prompt": "x", "steps": 0}' > "$T/bad_range"
expect "value out of range" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/bad_range" "$URL/v1/jobs"
printf '{"seed": 1}' > "$T/no_prompt"
expect "no prompt" 400 bad_options -F "mesh=@$BOX" -F "options=<$T/no_prompt" "$URL/v1/jobs"
expect "no mesh part" 400 bad_request -F "options=<$T/opts.json" "$URL/v1/jobs"
expect "no options part" 400 bad_request -F "mesh=@$BOX" "$URL/v1/jobs"
expect "two mesh parts" 400 bad_request -F "mesh=@$BOX" -F "mesh=@$BOX" -F "options=<$T/opts.json" "$URL/v1/jobs"
expect "unknown part" 400 bad_request -F "mesh=@$BOX" -F "weights=@$BOX" -F "options=<$T/opts.json" "$URL/v1/jobs"
expect "mesh of an unknown kind" 415 unsupported_media_type -F "mesh=@$BOX;filename=box.exe" -F "options=<$T/opts.json" "$URL/v1/jobs"
expect "style image of an unknown kind" 415 unsupported_media_type -F "mesh=@$BOX" -F "style_image=@$BOX" -F "options=<$T/opts.json" "$URL/v1/jobs"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n' > "$T/hostile.obj"
expect "hostile mesh (index out of range)" 400 bad_mesh -F "mesh=@$T/hostile.obj" -F "options=<$T/opts.json" "$URL/v1/jobs"
printf 'v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n' > "$T/nan.obj"
expect "hostile mesh (NaN)" 400 bad_mesh -F "mesh=@$T/nan.obj" -F "options=<$T/opts.json" "$URL/v1/jobs"
expect "not multipart" 415 unsupported_media_type -H 'Content-Type: application/json' --data-binary "@$T/opts.json" "$URL/v1/jobs"
head -c 1200000 /dev/zero > "$T/big.obj"
expect "upload over --max-upload" 413 too_large -F "mesh=@$T/big.obj" -F "options=<$T/opts.json" "$URL/v1/jobs"
expect "unknown route" 404 not_found "$URL/v2/jobs"
expect "unknown job" 404 not_found "$URL/v1/jobs/0123abc"
expect "wrong method" 405 method_not_allowed -X PUT "$URL/v1/jobs"
check "405 says what is allowed" sh -c "curl -s -D - -o /dev/null -X PUT '$URL/v1/jobs' | grep -qi '^Allow: GET, HEAD, POST'"
expect "traversal in a file name" 404 not_found --path-as-is "$URL/v1/jobs/$ID/files/../state"
expect "traversal, encoded" 404 not_found --path-as-is "$URL/v1/jobs/$ID/files/..%2Fstate"
expect "a hidden file" 404 not_found "$URL/v1/jobs/$ID/files/.matex-output"
expect "traversal in an id" 404 not_found --path-as-is "$URL/v1/jobs/../jobs"
ln -s /etc/passwd "$T/jobs/$ID/out/passwd"
expect "a link in the output folder is not followed" 404 not_found "$URL/v1/jobs/$ID/files/passwd"
rm "$T/jobs/$ID/out/passwd"
ID2=$(curl -s -F "mesh=@$BOX;filename=../../evil.obj" -F "options=<$T/opts.json" "$URL/v1/jobs" | sed -n 's/^{"id":"\([0-9a-z]*\)"}$/\1/p')
check "a client's file name never becomes a path" sh -c "[ -n '$ID2' ] && [ -f '$T/jobs/$ID2/mesh.obj' ] && [ -z \"\$(find '$T' -name 'evil*')\" ]"
expect "foreign Origin" 403 forbidden_origin -H 'Origin: https://evil.example' -F "mesh=@$BOX" -F "options=<$T/opts.json" "$URL/v1/jobs"
expect "foreign Origin on a GET" 403 forbidden_origin -H 'Origin: http://localhost:1' "$URL/v1/jobs"
expect "own Origin" 200 - -H "Origin: http://localhost:${URL##*:}" "$URL/v1/health"
expect "foreign Host (DNS rebinding)" 403 forbidden_host -H 'Host: evil.example' "$URL/v1/jobs"
check "no CORS header" sh -c "! curl -s -D - -o /dev/null -H 'Origin: http://localhost:${URL##*:}' '$URL/v1/health' | grep -qi '^Access-Control'"
# a client that stalls mid-upload is dropped after --client-timeout, its upload removed
(printf -- '--xx\r\nContent-Disposition: form-data; name="mesh"; filename="a.obj"\r\n\r\nv 0 0 0\n'; sleep 5) |
    curl -s -o /dev/null -X POST -H 'Content-Type: multipart/form-data; boundary=xx' -H 'Content-Length: 100000' -T - "$URL/v1/jobs" &
CURL=$!
sleep 1
check "stalled upload: staged meanwhile" [ -n "$(ls "$T/jobs/.incoming")" ]
sleep 3
check "stalled upload: dropped and removed" [ -z "$(ls "$T/jobs/.incoming")" ]
wait $CURL
expect "still serving" 200 - "$URL/v1/health"
# cancel: a queued job (behind a running one) is cancelled; its files are a 409; a finished job is removed
printf '{"prompt": "a slow crate", "seed": 2, "steps": 6, "image-size": 64, "views": 4}\n' > "$T/slow.json"
SLOW=$(submit "$T/slow.json")
QUEUED=$(submit "$T/opts.json")
expect "cancel a queued job" 200 - -X DELETE "$URL/v1/jobs/$QUEUED"
check "cancelled" [ "$(state_of "$QUEUED")" = cancelled ]
expect "files of a cancelled job" 409 not_done "$URL/v1/jobs/$QUEUED/files/mesh.glb"
wait_state "$SLOW" running > /dev/null
expect "cancel the running job" 202 - -X DELETE "$URL/v1/jobs/$SLOW"
check "running job cancelled" wait_state "$SLOW" cancelled
expect "remove a finished job" 200 - -X DELETE "$URL/v1/jobs/$QUEUED"
check "removed with its files" [ ! -e "$T/jobs/$QUEUED" ]
expect "removed job is gone" 404 not_found "$URL/v1/jobs/$QUEUED"
# the jobs folder is the server's own and locked
check "a second server on the same jobs folder is refused" sh -c "! '$M' serve --weights '$W' --listen 127.0.0.1:0 --jobs '$T/jobs' 2> '$T/err2' && grep -q 'another matex serve' '$T/err2'"
check "a taken port fails at once, before the weights load" sh -c "[ \$('$M' serve --weights /nonexistent.mxw --listen 127.0.0.1:${URL##*:} --jobs '$T/jobs_p' 2> '$T/err4'; echo \$?) = 1 ] && grep -q 'cannot listen' '$T/err4'"
mkdir -p "$T/foreign" && echo mine > "$T/foreign/notes.txt"
check "a foreign folder is refused" sh -c "! '$M' serve --weights '$W' --listen 127.0.0.1:0 --jobs '$T/foreign' 2> '$T/err3' && grep -q 'not a jobs folder' '$T/err3' && [ -f '$T/foreign/notes.txt' ]"
check "SIGTERM: clean exit" stop_server
check "no upload left behind" [ -z "$(ls "$T/jobs/.incoming")" ]

# ---- a full queue is a 429 ----
start_server "$T/log2" --jobs "$T/jobs_q" --max-queued 1
SLOW=$(submit "$T/slow.json")
expect "full queue" 429 queue_full -F "mesh=@$BOX" -F "options=<$T/opts.json" "$URL/v1/jobs"
curl -s -X DELETE "$URL/v1/jobs/$SLOW" > /dev/null
check "429 leaves no job" [ "$(ls "$T/jobs_q" | wc -l)" = 1 ]
check "server stopped cleanly (exit 0: no leak under ASan)" stop_server

# ---- finished jobs are kept up to --keep-jobs, oldest removed first ----
start_server "$T/log2b" --jobs "$T/jobs_r" --keep-jobs 2
R1=$(submit "$T/opts.json") && wait_state "$R1" done > /dev/null
R2=$(submit "$T/opts.json") && wait_state "$R2" done > /dev/null
R3=$(submit "$T/opts.json") && wait_state "$R3" done > /dev/null
check "--keep-jobs 2: the oldest finished job removed, the two newest kept" \
    sh -c "[ ! -e '$T/jobs_r/$R1' ] && [ -d '$T/jobs_r/$R2' ] && [ -d '$T/jobs_r/$R3' ]"
check "server stopped cleanly (exit 0: no leak under ASan)" stop_server

# ---- the token, and an address that is not loopback ----
head -c 24 /dev/urandom | od -An -tx1 | tr -d ' \n' > "$T/token"
chmod 644 "$T/token"
check "token file readable by others: refused" sh -c "[ \$('$M' serve --weights '$W' --token-file '$T/token' --jobs '$T/jobs_t' 2> /dev/null; echo \$?) = 1 ]"
chmod 600 "$T/token"
check "non-loopback address without a token: refused" sh -c "[ \$('$M' serve --weights '$W' --listen 0.0.0.0:0 --jobs '$T/jobs_t' 2> /dev/null; echo \$?) = 2 ]"
start_server "$T/log3" --jobs "$T/jobs_t" --token-file "$T/token"
expect "no token" 401 unauthorized "$URL/v1/health"
expect "wrong token" 401 unauthorized -H "Authorization: Bearer 0123456789abcdef0123456789abcdef" "$URL/v1/health"
expect "right token" 200 - -H "Authorization: Bearer $(cat "$T/token")" "$URL/v1/health"
check "server stopped cleanly (exit 0: no leak under ASan)" stop_server

# ---- 4 clients, 5 jobs each: every job completes, none lost or duplicated ----
start_server "$T/log4" --jobs "$T/jobs_c"
CLIENTS=
for c in 1 2 3 4; do
    (for k in 1 2 3 4 5; do
        printf '{"prompt": "crate %s-%s", "seed": %s, %s}\n' $c $k $k "$SMALL" > "$T/c$c.json"
        submit "$T/c$c.json"
    done > "$T/ids$c") &
    CLIENTS="$CLIENTS $!"
done
wait $CLIENTS # not the server
cat "$T"/ids1 "$T"/ids2 "$T"/ids3 "$T"/ids4 > "$T/ids"
check "20 jobs acknowledged, 20 distinct ids" sh -c "[ \$(sort -u '$T/ids' | grep -c .) = 20 ]"
alldone=0
for id in $(cat "$T/ids"); do wait_state "$id" done failed > /dev/null && [ "$(state_of "$id")" = done ] && alldone=$((alldone + 1)); done
check "all 20 done" [ $alldone = 20 ]
check "the jobs folder holds exactly those 20" sh -c "[ \$(ls '$T/jobs_c' | grep -c .) = 20 ]"

# ---- matex batch --server: the outputs a local batch writes, resumed the same way ----
mkdir -p "$T/cat"
cp "$BOX" "$T/cat/box.obj"
printf '{"mesh": "box.obj", "prompt": "a red crate", "name": "a", "seed": 5, "image_size": 64, "texture-size": 64, "render-size": 64, "candidates": 4, "views": 2}\n{"mesh": "box.obj", "prompt": "a blue crate", "name": "b", "seed": 6, "image-size": 64, "texture-size": 64, "render-size": 64, "candidates": 4, "views": 2, "steps": 2}\n' > "$T/cat/m.jsonl"
check "batch --server: done" sh -c "'$M' batch '$T/cat/m.jsonl' --server '$URL' --steps 1 --quiet -o '$T/remote' > '$T/b1.out'"
$M batch "$T/cat/m.jsonl" --weights "$W" --threads 2 --steps 1 --quiet -o "$T/local" > /dev/null 2>&1
for n in a b; do
    for f in mesh.glb mesh.obj texture.png texture.exr .matex-output; do
        check "batch --server = local batch: $n/$f" cmp -s "$T/remote/$n/$f" "$T/local/$n/$f"
    done
done
check "batch --server: a rerun skips the complete jobs" sh -c "'$M' batch '$T/cat/m.jsonl' --server '$URL' --steps 1 -o '$T/remote' 2> /dev/null | grep -q '0 done, 2 skipped'"
check "batch --server: the server keeps no copy" sh -c "[ \$(ls '$T/jobs_c' | grep -c .) = 20 ]"
printf '{"mesh": "box.obj", "prompt": "x", "colour": "red"}\n' > "$T/cat/bad.jsonl"
check "batch --server: a bad line fails before the server" sh -c "! '$M' batch '$T/cat/bad.jsonl' --server '$URL' -o '$T/remote2' > /dev/null 2> '$T/b2.err' && grep -q 'unknown key' '$T/b2.err'"
check "batch --server with --weights: usage error" sh -c "[ \$('$M' batch '$T/cat/m.jsonl' --server '$URL' --weights '$W' -o '$T/r3' 2> /dev/null; echo \$?) = 2 ]"
# a mesh with side files goes as a zip of them (tools/matex/serve/serve_upload.h): an OBJ with its
# .mtl and texture in folders below it, a glTF with its .bin and a %-escaped image, a GLB with its
# .bin. The server unpacks exactly those files (its upload and job folders watched while the batch
# runs) and the outputs are a local batch's.
mkdir -p "$T/cat/crate/mat/tex" "$T/cat/tetra/geo" "$T/cat/tetra/tex"
{ echo 'mtllib mat/crate.mtl'; cat "$BOX"; } > "$T/cat/crate/crate.obj"
printf 'newmtl oak\nKd 1 1 1\nmap_Kd -s 1 1 1 tex/wood.png\n' > "$T/cat/crate/mat/crate.mtl"
cp "$T/cli/texture.png" "$T/cat/crate/mat/tex/wood.png"
echo "not a side file" > "$T/cat/crate/notes.txt"
# a tetrahedron: 4 float positions and 12 uint16 indices
printf '%s' AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAAAAAAIA/AAACAAEAAAABAAMAAAADAAIAAQACAAMA |
    base64 -d > "$T/cat/tetra/geo/tetra.bin"
cp "$T/cli/texture.png" "$T/cat/tetra/tex/base color.png"
cat > "$T/cat/tetra/tetra.gltf" << 'GLTF'
{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
 "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
 "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
 "textures": [{"source": 0}], "images": [{"uri": "tex/base%20color.png"}],
 "buffers": [{"uri": "geo/tetra.bin", "byteLength": 72}],
 "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
 "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1]},
               {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}]}
GLTF
# the same tetrahedron as a .glb whose buffer is a file beside it (its JSON chunk padded to 4 bytes)
mkdir -p "$T/cat/tetrab/buf"
cp "$T/cat/tetra/geo/tetra.bin" "$T/cat/tetrab/buf/tetrab.bin"
J='{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],"buffers":[{"uri":"buf/tetrab.bin","byteLength":72}],"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":48},{"buffer":0,"byteOffset":48,"byteLength":24}],"accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,1]},{"bufferView":1,"componentType":5123,"count":12,"type":"SCALAR"}]}'
while [ $((${#J} % 4)) != 0 ]; do J="$J "; done
le32() { printf "$(printf '\\%03o\\%03o\\%03o\\%03o' $(($1 % 256)) $(($1 / 256 % 256)) $(($1 / 65536 % 256)) $(($1 / 16777216)))"; }
{ printf 'glTF'; le32 2; le32 $((20 + ${#J})); le32 ${#J}; printf 'JSON'; printf '%s' "$J"; } > "$T/cat/tetrab/tetrab.glb"
PARTS='"image-size": 64, "texture-size": 64, "render-size": 64, "candidates": 4, "views": 2, "steps": 12'
job() { printf '{"mesh": "%s", "prompt": "a box", "name": "%s", "seed": %s, %s}\n' "$1" "$2" "$3" "$PARTS"; }
{ job crate/crate.obj crate 5; job tetra/tetra.gltf tetra 6; job tetrab/tetrab.glb tetrab 7; } > "$T/cat/parts.jsonl"
"$M" batch "$T/cat/parts.jsonl" --server "$URL" --quiet -o "$T/premote" > /dev/null 2> "$T/bp.err" &
BP=$!
: > "$T/seen"
while kill -0 $BP 2> /dev/null; do
    find "$T/jobs_c" -path '*/mesh/*' -type f | sed -e 's|^.*/jobs_c/||' -e 's|^\.incoming/||' -e 's|^[0-9a-z]*/mesh/||' >> "$T/seen"
    sleep 0.02
done
wait $BP
check "batch --server, meshes with side files: done" [ $? = 0 ]
sort -u "$T/seen" > "$T/seen_u"
printf '%s\n' crate.obj mat/crate.mtl mat/tex/wood.png tetra.gltf geo/tetra.bin 'tex/base color.png' tetrab.glb buf/tetrab.bin |
    sort > "$T/want_u"
check "... the server got each mesh with exactly its side files" cmp -s "$T/seen_u" "$T/want_u"
$M batch "$T/cat/parts.jsonl" --weights "$W" --threads 2 --quiet -o "$T/plocal" > /dev/null 2>&1
for n in crate tetra tetrab; do
    for f in mesh.glb mesh.obj texture.png; do
        check "... = local batch: $n/$f" cmp -s "$T/premote/$n/$f" "$T/plocal/$n/$f"
    done
done
# refused before anything is sent: a side file outside the mesh's folder (named with '..', or a link
# leading out: a mesh must not send the user's other files), a glTF buffer that is not there
head -n 1 "$T/cat/parts.jsonl" > "$T/cat/crate.jsonl"
sed -n 2p "$T/cat/parts.jsonl" > "$T/cat/tetra.jsonl"
cp "$T/cli/texture.png" "$T/cat/secret.png"
printf 'newmtl oak\nmap_Kd ../../secret.png\n' > "$T/cat/crate/mat/crate.mtl"
check "batch --server: a texture named outside the mesh's folder is refused" sh -c "! '$M' batch '$T/cat/crate.jsonl' --server '$URL' -o '$T/pout1' > /dev/null 2> '$T/po.err' && grep -q \"crate.mtl: names '../../secret.png', outside the mesh's folder\" '$T/po.err'"
ln -s "$T/cat/secret.png" "$T/cat/crate/mat/tex/link.png"
printf 'newmtl oak\nmap_Kd tex/link.png\n' > "$T/cat/crate/mat/crate.mtl"
check "batch --server: a link leading out of the mesh's folder is refused" sh -c "! '$M' batch '$T/cat/crate.jsonl' --server '$URL' -o '$T/pout2' > /dev/null 2> '$T/po.err' && grep -q \"crate.mtl: names 'tex/link.png', outside the mesh's folder\" '$T/po.err'"
rm "$T/cat/tetra/geo/tetra.bin"
check "batch --server: a glTF buffer that is not there" sh -c "! '$M' batch '$T/cat/tetra.jsonl' --server '$URL' -o '$T/pout3' > /dev/null 2> '$T/po.err' && grep -q \"tetra.gltf: names 'geo/tetra.bin', which is not there\" '$T/po.err'"
check "... none of them sent: the server holds its 20 jobs only" sh -c "[ \$(ls '$T/jobs_c' | grep -c .) = 20 ]"
check "server stopped cleanly (exit 0: no leak under ASan)" stop_server

# ---- kill -9 during a job: it runs again once after a restart, then fails if killed again ----
start_server "$T/log5" --jobs "$T/jobs_k"
K=$(submit "$T/slow.json")
wait_state "$K" running > /dev/null
kill -9 "$SPID"
wait "$SPID" 2> /dev/null
SPID=
start_server "$T/log6" --jobs "$T/jobs_k"
check "after kill -9 and a restart the job completes" wait_state "$K" done
check "it ran twice" sh -c "curl -s '$URL/v1/jobs/$K' | grep -q '\"attempts\":2'"
K2=$(submit "$T/slow.json")
wait_state "$K2" running > /dev/null
kill -9 "$SPID"
wait "$SPID" 2> /dev/null
start_server "$T/log7" --jobs "$T/jobs_k"
wait_state "$K2" running > /dev/null
kill -9 "$SPID"
wait "$SPID" 2> /dev/null
start_server "$T/log8" --jobs "$T/jobs_k"
check "killed twice: failed with the reason" sh -c "curl -s '$URL/v1/jobs/$K2' | grep -q '\"state\":\"failed\".*\"error\":\"the server stopped while running this job, twice'"
check "server stopped cleanly (exit 0: no leak under ASan)" stop_server

exit $fail
