#!/bin/sh
# make test-slurm (not part of make test): a one-node Slurm cluster on localhost runs
# tools/slurm/matex-array.sbatch.
#   1. installs slurm-wlm and munge when missing (apt-get, as root or through sudo);
#   2. starts munged, slurmctld and slurmd on loopback with a generated slurm.conf in a temporary
#      folder (own munge key and socket, own ports, own state: nothing of the machine's is used);
#   3. a 3-task array over 6 tiny-weight jobs: all 6 outputs, 3 summaries, no failure;
#   4. the same catalogue into a new folder, one task at a time, cancelled (scancel) once the first
#      task is done: no partial folder; submitted again, it completes only the missing jobs and
#      leaves the finished ones untouched;
#   5. stops every daemon it started, also on failure or interrupt (trap).
# Env: MATEX (the binary), MATEX_DEMO_WEIGHTS (tiny weights), SLURM_TEST_TIMEOUT (seconds per wait).
set -u
ROOT=$(pwd)
M=$(realpath "${MATEX:-build/matex}")
W=$(realpath "${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}")
WAIT=${SLURM_TEST_TIMEOUT:-60}
fail=0
check() {
    name=$1
    shift
    if "$@"; then echo "ok   $name"; else echo "FAIL $name"; fail=1; fi
}
die() {
    echo "FAIL $*"
    exit 1
}

if ! command -v slurmctld > /dev/null || ! command -v slurmd > /dev/null || ! command -v munged > /dev/null; then
    SUDO=""
    [ "$(id -u)" = 0 ] || SUDO=sudo
    echo "installing slurm-wlm and munge"
    $SUDO apt-get update -q && $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge ||
        die "cannot install slurm-wlm and munge"
fi

D=$(mktemp -d /tmp/matex_slurm.XXXXXX)
chmod 755 "$D" # munged wants its socket folder reachable by everyone
PIDS=""
# Whatever the cluster started (slurmstepd, job scripts, matex) inherits our SLURM_CONF: a marker
# unique to this run, so leftovers are found by it, never by a process name.
kill_leftovers() {
    for p in /proc/[0-9]*; do
        pid=${p#/proc/}
        [ "$pid" = $$ ] && continue
        { tr '\0' '\n' < "$p/environ"; } 2> /dev/null | grep -qx "SLURM_CONF=$SLURM_CONF" && kill -9 "$pid" 2> /dev/null
    done
}
stop_all() {
    trap - EXIT INT TERM
    if [ -n "${SLURM_CONF:-}" ] && [ -n "$PIDS" ]; then
        scancel --quiet --user "$(id -un)" 2> /dev/null
        i=0 # KillWait is 5 s
        while [ -n "$(squeue -h -o %i 2> /dev/null)" ] && [ $i -lt 50 ]; do sleep 0.2; i=$((i + 1)); done
    fi
    for pid in $PIDS; do kill "$pid" 2> /dev/null; done
    for pid in $PIDS; do
        i=0
        while kill -0 "$pid" 2> /dev/null && [ $i -lt 50 ]; do sleep 0.2; i=$((i + 1)); done
        kill -9 "$pid" 2> /dev/null
        wait "$pid" 2> /dev/null
    done
    [ -n "${SLURM_CONF:-}" ] && kill_leftovers
    echo "stopped:$PIDS"
    rm -rf "$D"
}
trap 'stop_all' EXIT
trap 'exit 1' INT TERM

port_used() { # the port is bound by some TCP socket (/proc/net/tcp*, hex, local address column)
    hex=$(printf '%04X' "$1")
    cat /proc/net/tcp /proc/net/tcp6 2> /dev/null | awk '{print $2}' | grep -q ":$hex\$"
}
free_port_pair() { # two consecutive free ports from a start that depends on this process
    p=$((20000 + $$ % 20000))
    while port_used "$p" || port_used $((p + 1)); do p=$((p + 2)); done
    echo "$p"
}

# ---- munge ----
mkdir -p "$D/munge" "$D/sock" "$D/state" "$D/spool" "$D/log" "$D/jobs"
chmod 700 "$D/munge"
dd if=/dev/urandom of="$D/munge/munge.key" bs=1024 count=1 2> /dev/null
chmod 400 "$D/munge/munge.key"
munged -F --key-file="$D/munge/munge.key" --socket="$D/sock/munge.socket" --pid-file="$D/munge/munged.pid" \
    --log-file="$D/log/munged.log" --seed-file="$D/munge/munged.seed" > "$D/log/munged.out" 2>&1 &
PIDS="$!"
i=0
while [ ! -S "$D/sock/munge.socket" ] && [ $i -lt 50 ]; do sleep 0.2; i=$((i + 1)); done
[ -S "$D/sock/munge.socket" ] || die "munged did not start: $(tail -3 "$D/log/munged.log")"

# ---- slurm.conf ----
P=$(free_port_pair)
H=$(hostname)
U=$(id -un)
export SLURM_CONF="$D/slurm.conf"
cat > "$SLURM_CONF" << EOF
ClusterName=matextest
SlurmctldHost=$H(127.0.0.1)
SlurmctldPort=$P
SlurmdPort=$((P + 1))
SlurmUser=$U
SlurmdUser=$U
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$D/sock/munge.socket
StateSaveLocation=$D/state
SlurmdSpoolDir=$D/spool
SlurmctldPidFile=$D/slurmctld.pid
SlurmdPidFile=$D/slurmd.pid
SlurmctldLogFile=$D/log/slurmctld.log
SlurmdLogFile=$D/log/slurmd.log
ProctrackType=proctrack/pgid
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SlurmdParameters=config_overrides
ReturnToService=2
KillWait=5
MpiDefault=none
NodeName=matexnode NodeHostname=$H NodeAddr=127.0.0.1 CPUs=3 RealMemory=1000 State=UNKNOWN
PartitionName=matex Nodes=matexnode Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -D -f "$SLURM_CONF" > "$D/log/slurmctld.out" 2>&1 &
PIDS="$PIDS $!"
slurmd -D -f "$SLURM_CONF" -N matexnode > "$D/log/slurmd.out" 2>&1 &
PIDS="$PIDS $!"
i=0
while [ "$(sinfo -h -o %t 2> /dev/null)" != idle ] && [ $i -lt 150 ]; do sleep 0.2; i=$((i + 1)); done
[ "$(sinfo -h -o %t)" = idle ] || die "the node did not come up: $(tail -5 "$D/log/slurmctld.log" "$D/log/slurmd.log")"
echo "cluster up on 127.0.0.1:$P (slurmctld, slurmd, munged: pids $PIDS)"

# ---- the catalogue: 6 tiny jobs ----
SMALL='"steps": 2, "image-size": 64, "texture-size": 128, "render-size": 128, "candidates": 12'
for i in 0 1 2 3 4 5; do
    echo "{\"mesh\": \"$ROOT/tests/data/box.obj\", \"prompt\": \"box number $i\", \"name\": \"j$i\", \"seed\": $i, $SMALL}"
done > "$D/catalogue.jsonl"

submit() { # submit LOGNAME OUTROOT [sbatch options]: prints the job id
    log=$1
    out=$2
    shift 2
    sbatch --parsable --cpus-per-task=1 --mem=100M -D "$D" -o "$D/jobs/$log-%a.log" --export=ALL,MATEX="$M" "$@" \
        "$ROOT/tools/slurm/matex-array.sbatch" "$D/catalogue.jsonl" "$W" "$out" --quiet
}
wait_gone() { # wait_gone JOBID: until the array has left the queue
    i=0
    while [ -n "$(squeue -h -j "$1" -o %i 2> /dev/null)" ] && [ $i -lt $((WAIT * 5)) ]; do sleep 0.2; i=$((i + 1)); done
    [ -z "$(squeue -h -j "$1" -o %i 2> /dev/null)" ]
}
complete_jobs() { ls "$1"/*/report.json 2> /dev/null | wc -l; }
all_outputs() { # all_outputs OUTROOT: every job folder holds the whole output
    for n in j0 j1 j2 j3 j4 j5; do
        for f in texture.png texture.exr mesh.obj mesh.mtl mesh.glb report.json; do [ -s "$1/$n/$f" ] || return 1; done
    done
}
sum_of() { # sum_of KEY LOG...: the sum of "KEY":N over the task summaries
    key=$1
    shift
    cat "$@" 2> /dev/null | sed -n "s/.*\"$key\":\([0-9]*\).*/\1/p" | awk '{s += $1} END {print s + 0}'
}

# ---- 3. all six in three tasks ----
t0=$(date +%s)
id=$(submit run1 "$D/out1" --array=0-2) || die "sbatch failed"
check "array 1 finishes" wait_gone "$id"
check "6 outputs" all_outputs "$D/out1"
check "3 task summaries, 6 done" [ "$(sum_of done "$D"/jobs/run1-*.log)" = 6 ]
check "no failure" [ ! -e "$D/out1/failed.jsonl" ]
echo "array of 3 tasks over 6 jobs: $(($(date +%s) - t0)) s"

# ---- 4. resubmitted, cancelled midway, submitted again ----
id=$(submit run2 "$D/out2" --array=0-2%1) || die "sbatch failed"
i=0 # task 0 runs jobs 0 and 3, then task 1 jobs 1 and 4 (%1: one task at a time); cancel during job 4
while ! { [ -e "$D/out2/j0/report.json" ] && [ -e "$D/out2/j3/report.json" ] && [ -e "$D/out2/j1/report.json" ]; } &&
    [ $i -lt $((WAIT * 10)) ]; do
    sleep 0.1
    i=$((i + 1))
done
scancel "$id"
check "cancelled array leaves the queue" wait_gone "$id"
before=$(complete_jobs "$D/out2")
echo "complete after the cancel: $before of 6; task 1 says: $(grep -o '"done":[0-9]*,.*"interrupted":[a-z]*' "$D/jobs/run2-1.log")"
check "cancelled midway (3..5 of 6 complete)" [ "$before" -ge 3 -a "$before" -le 5 ]
check "no partial folder after the cancel" [ -z "$(ls "$D/out2" | grep -v -E '^(j[0-5]|failed.jsonl)$')" ]
mkdir -p "$D/kept"
for f in "$D"/out2/*/report.json; do cp "$f" "$D/kept/$(basename "$(dirname "$f")").json"; done
id=$(submit run3 "$D/out2" --array=0-2) || die "sbatch failed"
check "array 3 finishes" wait_gone "$id"
check "6 outputs after the resubmission" all_outputs "$D/out2"
check "it ran only the missing jobs" [ "$(sum_of done "$D"/jobs/run3-*.log)" = $((6 - before)) ]
check "and skipped the finished ones" [ "$(sum_of skipped "$D"/jobs/run3-*.log)" = "$before" ]
for f in "$D"/kept/*.json; do
    n=$(basename "$f" .json)
    check "$n untouched" cmp -s "$f" "$D/out2/$n/report.json"
done
[ $fail = 0 ] || { echo "--- logs"; tail -n 5 "$D"/jobs/*.log "$D"/log/*.log; }
echo "test-slurm: $(($(date +%s) - t0)) s of jobs"
exit $fail
