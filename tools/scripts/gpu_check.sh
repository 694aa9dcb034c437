#!/bin/sh
# make gpu-check: one run on a machine with an NVIDIA GPU whose output is the evidence for the CUDA
# backend (issue 21), in this order, each step under its own time limit: the GPU and its
# driver/runtime, make test-cuda (op tests at their own bounds, the network goldens found in
# tests/data and $MATEX_TESTDATA), compute-sanitizer memcheck on the tiny pipeline, SD1.5-size
# random weights, a default and a --fast `matex texture --device cuda` with their per-stage times
# (report.json stages_s / work_s), the same seed's texture on the CPU against the GPU (PSNR), the
# card's matrix peak and bench_cuda, then memcheck on the SD1.5-size networks and two guided steps.
# Uses the binaries of $GPU_CHECK_BIN (default build-cuda/gpu, or its archive build-cuda/gpu.tar.gz:
# `make gpu-check-pack` here), else builds `make cuda` (minutes). Writes its log to $GPU_CHECK_LOG
# (default $GPU_CHECK_OUT/log.txt) and the outputs under $GPU_CHECK_OUT (default gpu-check-out).
# Issue 39 adds, each beside today's path in the same run: conv2d through cuDNN (MATEX_CUDNN=1) and
# the fused attention (MATEX_CUDA_FLASH=1): the op tests, the goldens, bench_cuda for each path, a
# timed texture, two runs of one seed byte-equal, their PSNR against the CPU; and the diffusers peer (../shared/peer, packed) with the ratios matex / eager and
# matex / compiled; the weight file's load against its 1 s goal (bench_cuda --load). cuDNN is the GPU machine's own (its CUDA toolkit, else PyTorch's nvidia/cudnn).
# Issue 39 item 4 (MATEX_CUDA_GRAPH=1, the denoising step as one CUDA graph): test_nn_record and the
# tiny pipelines with graphs, two textures byte-equal to each other and to the op-by-op one, a timed
# default texture, bench_cuda's guided step op by op against one graph, the graph's node count.
# Measured: ~150 s on one H200 machine with 16 cores (weights 44 s, CPU texture of the parity 33 s),
# before issue 39's steps (never run yet; the peer alone ~200 s with torch.compile).
set -u
B=${GPU_CHECK_BIN:-build-cuda/gpu}
O=${GPU_CHECK_OUT:-gpu-check-out}
mkdir -p "$O"
LOG=${GPU_CHECK_LOG:-$O/log.txt} # a device run points it into the folder that comes back
W="$O/sd15_fast.mxw"
MESH=tests/data/assets/spot/spot_triangulated.obj
PROMPT="a cow with brown and white patches"
SAN=${COMPUTE_SANITIZER:-/usr/local/cuda/bin/compute-sanitizer}
failed=0
say() { printf '\n==== %s (%s)\n' "$*" "$(date -u +%H:%M:%S)" | tee -a "$LOG"; }
# run NAME SECONDS CMD...: runs CMD (killed after SECONDS: one hung step must not take the whole
# device call) with its output in the log; counts a failure; prints its wall time.
run() {
    name=$1
    limit=$2
    shift 2
    t0=$(date +%s.%N)
    timeout "$limit" "$@" >>"$LOG" 2>&1
    rc=$?
    t1=$(date +%s.%N)
    printf '%-58s rc=%d  %s s\n' "$name" "$rc" "$(awk "BEGIN { printf \"%.1f\", $t1 - $t0 }")" | tee -a "$LOG"
    [ $rc -eq 0 ] || failed=$((failed + 1))
    return $rc
}
stages() { # report.json -> its stage and work times, one line each
    tr -d '\n ' <"$1" | grep -o '"\(stages_s\|work_s\)":{[^}]*}' | tee -a "$LOG"
}
# summary LINE: the verdict lines of the log after line LINE (one test-cuda run).
summary() {
    tail -n +"$1" "$LOG" | grep -E "FAIL|SKIP|rel_l2=.*FAIL|device|not TESTED|all checks" | sort | uniq -c |
        sort -rn | head -40
}
# cuDNN 9 for MATEX_CUDNN=1 (dlopen libcudnn.so.9): the system's (ldconfig, the CUDA toolkit), else
# the one PyTorch's wheels carry (nvidia/cudnn/lib) on LD_LIBRARY_PATH. Says which, or that there
# is none (then the MATEX_CUDNN=1 steps show the fallback line and fail their cuDNN checks).
find_cudnn() {
    if ldconfig -p 2>/dev/null | grep -q 'libcudnn\.so\.9' || [ -f /usr/local/cuda/lib64/libcudnn.so.9 ]; then
        echo "cuDNN: the system's libcudnn.so.9" | tee -a "$LOG"
        return 0
    fi
    d=$(python3 -c 'import nvidia.cudnn, os; print(os.path.join(list(nvidia.cudnn.__path__)[0], "lib"))' 2>/dev/null)
    if [ -n "$d" ] && [ -f "$d/libcudnn.so.9" ]; then
        export LD_LIBRARY_PATH="$d${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
        echo "cuDNN: PyTorch's, $d" | tee -a "$LOG"
        return 0
    fi
    echo "cuDNN: no libcudnn.so.9 on this machine" | tee -a "$LOG"
}
# The peer (../shared/peer, packed into $B/peer by make gpu-check-pack): unpacked under $O/peer and run
# on this machine's python3 with the repository's SD1.5 configs. A missing peer, PyTorch or GPU for
# PyTorch is said in one line and the check goes on: the peer is a yardstick, not a matex step, so
# its failure is not counted either.
peer_run() {
    P=${GPU_CHECK_PEER:-$B/peer}
    if [ ! -f "$P/peer_diffusers.py" ]; then
        echo "peer NOT RUN: no $P/peer_diffusers.py (make gpu-check-pack packs \$(MATEX_TESTDATA)/peer)" | tee -a "$LOG"
        return 1
    fi
    if ! python3 -c 'import torch; assert torch.cuda.is_available()' >>"$LOG" 2>&1; then
        echo "peer NOT RUN: python3 has no PyTorch that sees the GPU" | tee -a "$LOG"
        return 1
    fi
    if ! { rm -rf "$O/peer" && mkdir -p "$O/peer/src/hub" && cp "$P/peer_diffusers.py" "$O/peer/" &&
        tar -xzf "$P"/diffusers-*-src.tar.gz -C "$O/peer/src" &&
        tar -xzf "$P"/huggingface_hub-*-src.tar.gz -C "$O/peer/src/hub"; }; then
        echo "peer NOT RUN: could not unpack its sources from $P" | tee -a "$LOG"
        return 1
    fi
    t0=$(date +%s)
    timeout 330 env PYTHONUNBUFFERED=1 python3 "$O/peer/peer_diffusers.py" tests/data/golden 11 >>"$LOG" 2>&1
    rc=$?
    printf '%-58s rc=%d  %s s (not counted)\n' "peer: eager and torch.compile" "$rc" "$(($(date +%s) - t0))" | tee -a "$LOG"
    [ $rc -eq 0 ] || { echo "peer FAILED (its log is above in $LOG): no ratios" | tee -a "$LOG"; return 1; }
}
# ratios "matex: k_ms=v ..." "peer: k_ms=v ...": matex / eager and matex / compiled per network.
ratios() {
    printf '%s\n%s\n' "$1" "$2" | awk '
        $1 == "matex:" { for (i = 2; i <= NF; i++) { split($i, kv, "="); m[kv[1]] = kv[2] } }
        $1 == "peer:"  { for (i = 2; i <= NF; i++) { split($i, kv, "="); p[kv[1]] = kv[2] } }
        END {
            n = split("controlnet_ms unet_ms guided_step_ms vae_decode_ms", k, " ")
            for (i = 1; i <= n; i++) {
                if (!(k[i] in m) || !(k[i] in p)) { printf "ratio %-16s missing (matex %s, peer %s)\n", k[i], m[k[i]], p[k[i]]; continue }
                line = sprintf("ratio %-16s matex %7.2f ms / eager %7.2f ms = %.2f", k[i], m[k[i]], p[k[i]], m[k[i]] / p[k[i]])
                c = "compiled_" k[i]
                if (c in p) line = line sprintf("; / compiled %7.2f ms = %.2f", p[c], m[k[i]] / p[c])
                print line
            }
            print "goals: guided step <= 0.80 x compiled, VAE decode <= 0.70 x eager (issue 39)"
        }'
}

: >"$LOG"
if [ -f "$B.tar.gz" ]; then # the archive of make gpu-check-pack, what a device run carries
    rm -rf "$B" && tar -C "$(dirname "$B")" -xzf "$B.tar.gz" || exit 1
fi
if [ ! -x "$B/matex" ]; then
    say "no prebuilt binaries in $B: make cuda"
    run "make cuda" 600 make -j"$(nproc)" cuda || exit 1
    B=build-cuda
fi
M="$B/matex"
[ -d "$B/lib" ] && export LD_LIBRARY_PATH="$B/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" # the libraries matex needs that the GPU machine lacks
[ -d "$B/data" ] && export MATEX_TESTDATA="$B/data" # the goldens packed beside the binaries

say "GPU"
find_cudnn
run "nvidia-smi" 30 nvidia-smi
nvidia-smi --query-gpu=name,driver_version,memory.total,compute_cap --format=csv | tee -a "$LOG"
"$M" --version | tee -a "$LOG"

say "make test-cuda (op tests, network goldens, tiny pipelines; MATEX_CUDA_SYNC=1 names a faulting op)"
mark=$(($(wc -l <"$LOG") + 1)) # the first line of the next run
run "test-cuda" 180 env MATEX="$M" MX_TEST_DEVICE=cuda MATEX_FULL=1 MATEX_CUDA_SYNC=1 sh tests/cuda/run.sh \
    "$B/tests/cuda/test_cuda_ops" "$B"/tests/test_nn_*
summary "$mark"
say "make test-cuda with conv2d through cuDNN and the fused attention (MATEX_CUDNN=1 MATEX_CUDA_FLASH=1)"
mark=$(($(wc -l <"$LOG") + 1)) # the first line of the next run
run "test-cuda, MATEX_CUDNN=1 MATEX_CUDA_FLASH=1" 240 env MATEX_CUDNN=1 MATEX_CUDA_FLASH=1 MATEX="$M" \
    MX_TEST_DEVICE=cuda MATEX_FULL=1 MATEX_CUDA_SYNC=1 sh tests/cuda/run.sh "$B/tests/cuda/test_cuda_ops" \
    "$B"/tests/test_nn_*
summary "$mark"
tail -n +"$mark" "$LOG" | grep -E "cuDNN|fused kernel" | sort | uniq -c | sort -rn | head -20

say "compute-sanitizer memcheck: tiny pipeline"
run "memcheck tiny pipeline" 120 env MX_TEST_DEVICE=cuda "$SAN" --tool memcheck --error-exitcode 99 \
    "$B/tests/test_nn_pipeline"

say "SD1.5-size random weights (fp16, with LCM-LoRA and TAESD)"
run "make_sd15_weights --fast" 180 sh tools/scripts/make_sd15_weights.sh "$M" "$W" --fast || exit 1

# Issue 39 item 5: the weight file (in the page cache: just written) onto the GPU in under 1 s, in a
# new process each time; the default readers twice, then fewer and more (MATEX_CUDA_LOAD_THREADS).
say "load: the SD1.5-size fp16 set onto the GPU (goal: under 1 s for 3.6 GB; bench_cuda --load)"
for threads in default default 4 12; do
    if [ "$threads" = default ]; then lt=""; else lt="MATEX_CUDA_LOAD_THREADS=$threads"; fi
    # shellcheck disable=SC2086
    run "bench_cuda --load, readers: $threads" 60 env $lt "$B/bench_cuda" "$W" --load && grep "^load:" "$LOG" | tail -4
done

# The timed runs and the parity first, the slow SD1.5-size memchecks last: a device call that runs
# out of time still brings back the speed and the PSNR.
say "timed: default texture on the GPU (6 views, 10 steps, 1024^2)"
run "texture --device cuda" 120 "$M" texture "$MESH" "$PROMPT" --weights "$W" --device cuda --seed 1 \
    -o "$O/gpu_default" --force && stages "$O/gpu_default/report.json"
say "timed: default texture on the GPU, cuDNN convolution and the fused attention (MATEX_CUDNN=1 MATEX_CUDA_FLASH=1)"
run "texture --device cuda, new paths" 120 env MATEX_CUDNN=1 MATEX_CUDA_FLASH=1 "$M" texture "$MESH" "$PROMPT" --weights "$W" \
    --device cuda --seed 1 -o "$O/gpu_cudnn" --force && stages "$O/gpu_cudnn/report.json"
say "timed: texture --fast on the GPU"
run "texture --fast --device cuda" 60 "$M" texture "$MESH" "$PROMPT" --weights "$W" --device cuda --fast --seed 1 \
    -o "$O/gpu_fast" --force && stages "$O/gpu_fast/report.json"

say "same seed, CPU (fp32) vs GPU: PSNR of the textures (2 views, 4 steps, 512^2 texture)"
small="--seed 7 --views 2 --steps 4 --texture-size 512 --render-size 512"
# shellcheck disable=SC2086
run "texture small, cuda" 60 "$M" texture "$MESH" "$PROMPT" --weights "$W" --device cuda $small -o "$O/par_gpu" --force
# shellcheck disable=SC2086
run "texture small, cpu fp32" 240 "$M" texture "$MESH" "$PROMPT" --weights "$W" --device cpu --precision fp32 \
    $small -o "$O/par_cpu" --force
[ -f "$O/par_gpu/texture.png" ] && [ -f "$O/par_cpu/texture.png" ] &&
    run "psnr cpu vs gpu (goal >= 40 dB)" 30 "$M" info "$O/par_cpu/texture.png" --compare "$O/par_gpu/texture.png" &&
    tail -1 "$LOG"
say "same seed twice on the GPU, new paths (MATEX_CUDNN=1 MATEX_CUDA_FLASH=1): byte-equal textures, PSNR vs the CPU"
for i in 1 2; do
    # shellcheck disable=SC2086
    run "texture small, cuda, new paths, run $i" 60 env MATEX_CUDNN=1 MATEX_CUDA_FLASH=1 "$M" texture "$MESH" "$PROMPT" \
        --weights "$W" --device cuda $small -o "$O/par_cudnn$i" --force
done
run "two runs of one seed, new paths: texture.png byte-equal" 10 cmp "$O/par_cudnn1/texture.png" "$O/par_cudnn2/texture.png"
[ -f "$O/par_cudnn1/texture.png" ] && [ -f "$O/par_cpu/texture.png" ] &&
    run "psnr cpu vs gpu, new paths (goal >= 40 dB)" 30 "$M" info "$O/par_cpu/texture.png" \
        --compare "$O/par_cudnn1/texture.png" && tail -1 "$LOG"

# Issue 39 item 4: the networks' part of each denoising step captured once as a CUDA graph and
# replayed (MATEX_CUDA_GRAPH=1, docs/cuda-notes.md §11). Expected byte-equal to the op-by-op run: the
# graph holds the same kernels with the same cuBLASLt plans (made by the first step, op by op).
say "CUDA graphs (MATEX_CUDA_GRAPH=1): the tests, two textures byte-equal to each other and to op by op"
mark=$(($(wc -l <"$LOG") + 1))
for t in test_nn_record test_nn_pipeline test_nn_pipeline_fast; do
    run "$t, MATEX_CUDA_GRAPH=1" 60 env MATEX_CUDA_GRAPH=1 MX_TEST_DEVICE=cuda "$B/tests/$t"
done
for i in 1 2; do
    # shellcheck disable=SC2086
    run "texture small, cuda, graphs, run $i" 60 env MATEX_CUDA_GRAPH=1 "$M" texture "$MESH" "$PROMPT" --weights "$W" \
        --device cuda $small -o "$O/par_graph$i" --force
done
run "two runs of one seed with graphs: texture.png byte-equal" 10 cmp "$O/par_graph1/texture.png" "$O/par_graph2/texture.png"
run "graphs against op by op (same seed): texture.png byte-equal" 10 cmp "$O/par_gpu/texture.png" "$O/par_graph1/texture.png"
[ -f "$O/par_graph1/texture.png" ] && [ -f "$O/par_cpu/texture.png" ] &&
    run "psnr cpu vs gpu, graphs (goal >= 40 dB)" 30 "$M" info "$O/par_cpu/texture.png" --compare "$O/par_graph1/texture.png" &&
    tail -1 "$LOG"
tail -n +"$mark" "$LOG" | grep -E "CUDA graph" | sort | uniq -c | sort -rn | head # node counts, or why not
run "timed: default texture on the GPU, graphs" 120 env MATEX_CUDA_GRAPH=1 "$M" texture "$MESH" "$PROMPT" --weights "$W" \
    --device cuda --seed 1 -o "$O/gpu_graph" --force && stages "$O/gpu_graph/report.json"

say "the networks at one view step's shapes (tools/bench/bench_cuda.c), and the card's matrix peak as the anchor"
run "anchor: 8192^3 bf16 matrix product through PyTorch" 60 python3 -c '
import torch
a, b = (torch.randn(8192, 8192, device="cuda", dtype=torch.bfloat16) for _ in range(2))
for _ in range(3): a @ b
ts = []
for _ in range(10):
    s, e = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    s.record(); a @ b; e.record(); torch.cuda.synchronize(); ts.append(s.elapsed_time(e) / 1e3)
ts.sort()
print("anchor: bf16 8192^3 matrix product %.0f TFLOP/s (median of 10)" % (2 * 8192**3 / ts[5] / 1e12))'
grep "^anchor:" "$LOG"
# The four paths in turn, each one's matex: line kept for the ratios: today's, cuDNN convolution,
# the fused attention, both.
matex_lines=""
for paths in "MATEX_CUDNN=0 MATEX_CUDA_FLASH=0" "MATEX_CUDNN=1 MATEX_CUDA_FLASH=0" "MATEX_CUDNN=0 MATEX_CUDA_FLASH=1" \
    "MATEX_CUDNN=1 MATEX_CUDA_FLASH=1"; do
    # shellcheck disable=SC2086
    if run "bench_cuda (11 calls per network), $paths" 120 env $paths "$B/bench_cuda" "$W" --calls 11; then
        grep -E "median|load|launches" "$LOG" | tail -7
        matex_lines="$matex_lines$paths $(grep '^matex:' "$LOG" | tail -1)
"
    fi
done
if run "bench_cuda, MATEX_CUDA_GRAPH=1 (the guided step replayed as one graph)" 120 env MATEX_CUDA_GRAPH=1 \
    "$B/bench_cuda" "$W" --calls 11; then
    grep -E "^guided step" "$LOG" | tail -2
    printf '%s\n' "$matex_lines" | head -1 | sed 's/.*guided_step_ms=\([0-9.]*\).*/guided step op by op: \1 ms/' | tee -a "$LOG"
    grep '^matex:' "$LOG" | tail -1 | sed 's/.*guided_step_ms=\([0-9.]*\).*/guided step as one CUDA graph: \1 ms/' | tee -a "$LOG"
fi
run "bench_cuda --profile, MATEX_CUDA_SYNC=1 (per-op GPU time)" 120 env MATEX_CUDA_SYNC=1 "$B/bench_cuda" "$W" \
    --calls 3 --profile

say "the peer beside matex: diffusers 0.35.2 on this machine's PyTorch, same shapes (peer_diffusers.py)"
if peer_run; then
    grep -E "^(torch|peer|compile)" "$LOG" | tail -8
    printf '%s' "$matex_lines" | while read -r cudnn flash line; do
        echo "matex with $cudnn $flash:" | tee -a "$LOG"
        ratios "$line" "$(grep '^peer:' "$LOG" | tail -1)" | tee -a "$LOG"
    done
fi

say "compute-sanitizer memcheck: SD1.5-size networks"
run "memcheck ControlNet, UNet, VAE decode (bench_cuda, 1 call each after 2)" 180 "$SAN" --tool memcheck \
    --error-exitcode 99 "$B/bench_cuda" "$W" --calls 1
CN_IN="${MATEX_TESTDATA:-../shared}/golden/sd15_controlnet/inputs.safetensors" # 2 MB: carry it
if [ -f "$CN_IN" ]; then
    run "memcheck one UNet call" 180 "$SAN" --tool memcheck --error-exitcode 99 "$M" run-net unet --device cuda \
        --weights "$W" --inputs "$CN_IN" --out "$O/unet_out.safetensors"
else
    echo "NOT RUN: the UNet call needs golden/sd15_controlnet/inputs.safetensors (carry it)" | tee -a "$LOG"
    failed=$((failed + 1))
fi
run "memcheck guided steps, two ControlNets (texture 2 views, 1 step)" 240 "$SAN" --tool memcheck \
    --error-exitcode 99 "$M" texture "$MESH" "$PROMPT" --weights "$W" --device cuda --views 2 --steps 1 \
    --texture-size 512 --render-size 512 -o "$O/memcheck_step" --force

rm -f "$W"
say "gpu-check: $failed step(s) failed; the whole log: $LOG"
[ $failed -eq 0 ]
