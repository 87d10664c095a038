#!/usr/bin/env bash
# Issue 12 on the first CUDA GPU, one device call beside bench/run_gpu.sh: the elided-substep control step, launch
# cost against parameter count and index chains, and the Nsight Compute profile at 1M envs.
#
#   bash bench/run_gpu_launch.sh     # results in $OUT if set (the device machine sets it), else bench/results
#
# Writes 7 files (the device machine returns at most 8): controller_step_cuda_implicit.md (implicit actuation, no
# interpolation: 1 launch per control step), launch_params_cuda.md, ncu_report.txt, ncu_metrics.csv, ncu.log (see
# bench/profile_ncu.sh), run_gpu_launch.log, and launch_json.tar holding the JSON files
# (tar -xf launch_json.tar -C bench/results). Sizes: IMPLICIT_ENVS (default 1,4k,64k,1M), LAUNCH_ENVS (4k,1M),
# NCU_ENVS (1M), REPEATS (5). Expected ~5 min on an H200 (ncu rebuilds the 1M layout for each of its 6 runs).
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
stage() {  # stage NAME LIMIT_S CMD...
  local name=$1 limit=$2; shift 2
  echo "=== $name (limit ${limit}s, at +$(( $(date +%s) - t0 ))s)" | tee -a "$LOG"
  timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
  local rc=${PIPESTATUS[0]}
  [ "$rc" = 0 ] || echo "=== $name exited $rc" | tee -a "$LOG"
}

stage controller_step_implicit 150 $PY bench/controller_step.py --device "$DEVICE" \
  --envs "${IMPLICIT_ENVS:-1,4k,64k,1M}" --repeats "$REPEATS" --actuation implicit --interpolate off \
  --tag cuda_implicit --out "$WORK"
stage launch_params 60 $PY bench/launch_params.py --device "$DEVICE" --envs "${LAUNCH_ENVS:-4k,1M}" \
  --repeats "$REPEATS" --out "$WORK"
cp "$WORK"/*.md "$OUT"/ 2>/dev/null
(cd "$WORK" && tar -cf "$OUT/launch_json.tar" ./*.json)
stage ncu 330 env OUT="$OUT" PYTHON="$PY" bash bench/profile_ncu.sh
echo "=== done in $(( $(date +%s) - t0 ))s" | tee -a "$LOG"
ls -la "$OUT" | tee -a "$LOG"
