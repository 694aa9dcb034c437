#!/bin/sh
# The goals of `matex serve` measured (docs/SERVE.md "Measurements"; not a test: it prints numbers):
#   overhead: per job, the time from POST to the `end` event minus the report's total_s, median of 20;
#   warm job: a second job through the server against one `matex texture` run of the same job, and
#             that run's load stage (report.json stages_s.load);
#   memory:   the server's VmRSS after those jobs and after 100 more.
# usage: sh tests/serve/measure.sh [MATEX [WEIGHTS]]   (the demo weights by default; curl, awk)
set -u
M=${1:-build/matex}
W=${2:-build/demo/demo.mxw}
T=$(mktemp -d /tmp/matex_serve_measure.XXXXXX)
BOX=tests/data/box.obj
SMALL='"steps": 1, "image-size": 64, "texture-size": 64, "render-size": 64, "candidates": 4, "views": 2'
"$M" serve --weights "$W" --listen 127.0.0.1:0 --jobs "$T/jobs" 2> "$T/log" &
SPID=$!
trap 'kill -TERM $SPID; wait $SPID; rm -rf "$T"' EXIT
while ! grep -q 'listening on' "$T/log" 2> /dev/null; do sleep 0.1; done
URL=http://127.0.0.1:$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/v1.*|\1|p' "$T/log")
now() { date +%s.%N; }
# one_job MESH OPTIONS_JSON: prints "SECONDS_POST_TO_END TOTAL_S"
one_job() {
    printf '%s\n' "$2" > "$T/o.json"
    t0=$(now)
    id=$(curl -s -F "mesh=@$1" -F "options=<$T/o.json" "$URL/v1/jobs" | sed -n 's/^{"id":"\([0-9a-z]*\)"}$/\1/p')
    curl -s -N "$URL/v1/jobs/$id/events" | grep -q '^event: end'
    t1=$(now)
    total=$(curl -s "$URL/v1/jobs/$id/files/report.json" | grep -o '"total_s":[0-9.e+-]*' | cut -d: -f2)
    curl -s -X DELETE "$URL/v1/jobs/$id" > /dev/null
    echo "$t0 $t1 $total" | awk '{printf "%.4f %.4f\n", $2 - $1, $3}'
}
rss() { awk '/^VmRSS/ {print $2}' /proc/$SPID/status; }

one_job $BOX "{\"prompt\": \"warm-up\", $SMALL}" > /dev/null
for i in $(seq 20); do one_job $BOX "{\"prompt\": \"crate $i\", \"seed\": $i, $SMALL}"; done > "$T/over"
sort -n -k1 "$T/over" > /dev/null
awk '{print ($1 - $2) * 1000}' "$T/over" | sort -n | awk '{v[NR] = $1} END {printf "overhead per job (POST -> end event - report total_s), 20 jobs: median %.1f ms, min %.1f ms, max %.1f ms\n", (v[10] + v[11]) / 2, v[1], v[NR]}'

# a second job of the Spot mesh through the server against one CLI run of the same job
SPOT=tests/data/assets/spot/spot_triangulated.obj
OPTS='"seed": 3, "steps": 4, "image-size": 64'
one_job $SPOT "{\"prompt\": \"a cow\", $OPTS}" > /dev/null
SERVER=$(one_job $SPOT "{\"prompt\": \"a cow\", $OPTS}" | cut -d' ' -f1)
t0=$(now)
"$M" texture $SPOT "a cow" --weights "$W" --seed 3 --steps 4 --image-size 64 --quiet -o "$T/cli"
t1=$(now)
LOAD=$(grep -o '"load":[0-9.e+-]*' "$T/cli/report.json" | head -n 1 | cut -d: -f2)
echo "$t0 $t1 $SERVER $LOAD" | awk '{cli = $2 - $1; printf "spot, 4 steps: CLI run %.3f s (its load stage %.3f s), the same job through a warm server %.3f s: %.3f s faster\n", cli, $4, $3, cli - $3}'

# memory: the baseline after the jobs above (the allocator keeps what their largest buffers took)
RSS1=$(rss)
for i in $(seq 100); do one_job $BOX "{\"prompt\": \"crate $i\", \"seed\": $i, $SMALL}" > /dev/null; done
RSS2=$(rss)
echo "server VmRSS: $RSS1 kB after 23 jobs, $RSS2 kB after 100 more"
