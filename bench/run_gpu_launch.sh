#!/usr/bin/env bash
# The launch-bound side of the control step on the first CUDA GPU, beside bench/run_gpu.sh: the 1-launch control
# step, launch cost against parameter count and index chains, and the Nsight Compute profile at 1M envs.
#
#   STAGES=cuda_tests,implicit,explicit,block_dim bash bench/run_gpu_launch.sh   # one device call
#   STAGES=launch_params,ncu bash bench/run_gpu_launch.sh                       # another
#
#   bash bench/run_gpu_launch.sh     # results in $OUT if set (the device machine sets it), else bench/results
#
# Stages (STAGES, below): the CUDA tests of the step kernels, the implicit (elided, 1 launch) and explicit control
# steps, the step kernels' block size, launch cost against parameters, the Nsight Compute profile. Writes at most 8
# files: controller_step_cuda_implicit.md, controller_step_cuda.md, ncu_report.txt, ncu_metrics.csv, ncu.log (see
# bench/profile_ncu.sh), run_gpu_launch.log, and launch_json.tar holding the JSON and the other .md files
# (tar -xf launch_json.tar -C bench/results). Sizes: IMPLICIT_ENVS (default 1,64,1k,4k,16k,64k,256k,1M), CTRL_ENVS
# (1,4k,64k,1M), BLOCK_ENVS (4k,1M), LAUNCH_ENVS (4k,1M), NCU_ENVS (1M), REPEATS (5).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/results}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
WORK=$(mktemp -d)
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
DEVICE=${DEVICE:-cuda:0}
REPEATS=${REPEATS:-5}
LOG="$OUT/run_gpu_launch.log"

{
  date -u
  nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv,noheader || true
  git rev-parse --short HEAD 2>/dev/null | sed 's/^/wpctrl commit /'
} 2>&1 | tee "$LOG"

t0=$(date +%s)
# STAGES: a comma-separated subset (default: all; cuda_tests + implicit + explicit + block_dim fit one 10-minute device
# call, ncu another).
STAGES=${STAGES:-cuda_tests,implicit,explicit,block_dim,launch_params,ncu}
stage() {  # stage NAME LIMIT_S CMD...
  local name=$1 limit=$2; shift 2
  [[ ",$STAGES," == *",$name,"* ]] || return 0
  echo "=== $name (limit ${limit}s, at +$(( $(date +%s) - t0 ))s)" | tee -a "$LOG"
  timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
  local rc=${PIPESTATUS[0]}
  [ "$rc" = 0 ] || echo "=== $name exited $rc" | tee -a "$LOG"
}
ENVS=${IMPLICIT_ENVS:-1,64,1k,4k,16k,64k,256k,1M}

stage cuda_tests 200 $PY -m pytest -q -p no:cacheprovider tests/test_cuda.py tests/test_launches.py
stage implicit 150 $PY bench/controller_step.py --device "$DEVICE" --envs "$ENVS" --repeats "$REPEATS" \
  --actuation implicit --interpolate off --tag cuda_implicit --out "$WORK"
stage explicit 200 $PY bench/controller_step.py --device "$DEVICE" --envs "${CTRL_ENVS:-1,4k,64k,1M}" \
  --repeats "$REPEATS" --out "$WORK"
for b in 32 64 128 256; do  # the step kernels' block size (launch.step_block_dim) against the alternatives
  stage block_dim 60 $PY bench/controller_step.py --device "$DEVICE" --envs "${BLOCK_ENVS:-4k,1M}" \
    --repeats "$REPEATS" --actuation implicit --interpolate off --variants wpctrl_graph,floor --block-dim "$b" \
    --tag "cuda_block$b" --out "$WORK"
done
stage launch_params 60 $PY bench/launch_params.py --device "$DEVICE" --envs "${LAUNCH_ENVS:-4k,1M}" \
  --repeats "$REPEATS" --out "$WORK"
cp "$WORK"/controller_step_cuda*.md "$OUT"/ 2>/dev/null
rm -f "$OUT"/controller_step_cuda_block*.md
if ls "$WORK"/*.json >/dev/null 2>&1; then (cd "$WORK" && tar -cf "$OUT/launch_json.tar" ./*.json ./*.md 2>/dev/null); fi
[[ ",$STAGES," == *",ncu,"* ]] && stage ncu 330 env OUT="$OUT" PYTHON="$PY" bash bench/profile_ncu.sh
echo "=== done in $(( $(date +%s) - t0 ))s" | tee -a "$LOG"
ls -la "$OUT" | tee -a "$LOG"
