#!/usr/bin/env bash
# Every benchmark, once, on the first CUDA GPU. Measured: 4 min on an H200 with a cold Warp kernel cache
# (MuJoCo-Warp's and XPBD's first-use compilation and the first MuJoCo solver build are about 2 min of it).
#
#   bash bench/run_gpu.sh        # results in $OUT if set (the device machine sets it), else bench/results
#
# Writes 8 files (the device machine returns at most 8): controller_step_cuda.md, profile_overhead_cuda.md,
# rollout_cuda.md, inertia_update_cuda.md, actuation_cost_cuda.md, fidelity_cuda.md, run_gpu.log (with the CUDA tests' output), and json.tar
# holding the JSON files
# (tar -xf json.tar -C bench/results). Each stage has a time limit so that a slow stage cannot starve the others.
# Sizes: CTRL_ENVS, ROLLOUT_ENVS, ROLLOUT_SOLVERS, REPEATS; DEVICE (default cuda:0; "cpu" only to test
# the script: use the CPU commands of bench/README.md for CPU numbers).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/results}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
WORK=$(mktemp -d)
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
CTRL_ENVS=${CTRL_ENVS:-1,64,1k,4k,16k,64k,256k,1M}
ROLLOUT_ENVS=${ROLLOUT_ENVS:-1k,4k}
ROLLOUT_SOLVERS=${ROLLOUT_SOLVERS:-mujoco,xpbd}
REPEATS=${REPEATS:-5}
DEVICE=${DEVICE:-cuda:0}
LOG="$OUT/run_gpu.log"

{
  date -u
  nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv,noheader || true
  $PY -c "import sys, torch, warp, newton, gymnasium; print('python', sys.version.split()[0], 'torch', torch.__version__, \
'cuda', torch.version.cuda, torch.cuda.is_available(), 'warp', warp.__version__, 'newton', newton.__version__)" || exit 1
} 2>&1 | tee "$LOG"

t0=$(date +%s)
# STAGES: a comma-separated subset of the stages below (default: all but ee_step and fidelity; the stage limits add up
# to more than one 10-minute device call, so split a full run over calls, e.g. STAGES=cuda_tests,controller_step,...).
STAGES=${STAGES:-cuda_tests,controller_step,profile_overhead,rollout,actuation_cost,inertia_update}
stage() {  # stage NAME LIMIT_S CMD...
  local name=$1 limit=$2; shift 2
  [[ ",$STAGES," == *",$name,"* ]] || return 0
  echo "=== $name (limit ${limit}s, at +$(( $(date +%s) - t0 ))s)" | tee -a "$LOG"
  timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
  local rc=${PIPESTATUS[0]}
  [ "$rc" = 0 ] || echo "=== $name exited $rc" | tee -a "$LOG"
}

stage cuda_tests 240 $PY -m pytest -q -p no:cacheprovider tests/test_cuda.py tests/test_semantics.py \
  "tests/test_actuation.py::test_cuda_captured_randomisation_reaches_mujoco" tests/test_ee_cuda.py
stage controller_step 200 $PY bench/controller_step.py --device "$DEVICE" --envs "$CTRL_ENVS" --repeats "$REPEATS" \
  --out "$WORK"
stage profile_overhead 60 $PY bench/profile_overhead.py --device "$DEVICE" --envs 1,4k --repeats "$REPEATS" \
  --profile-steps 1000 --out "$WORK"
stage rollout 200 $PY bench/rollout.py --device "$DEVICE" --envs "$ROLLOUT_ENVS" --solver "$ROLLOUT_SOLVERS" --steps 20 \
  --repeats 3 --out "$WORK"
stage actuation_cost 120 $PY bench/actuation_cost.py --device "$DEVICE" --envs "${ACT_ENVS:-1,4k,64k,1M}" \
  --repeats "$REPEATS" --eager --out "$WORK"
stage inertia_update 150 $PY bench/inertia_update.py --device "$DEVICE" --envs 1,4k,64k --repeats "$REPEATS" \
  --out "$WORK"
stage ee_step 300 $PY bench/ee_step.py --device "$DEVICE" --out "$WORK"
stage fidelity 150 $PY bench/fidelity.py --device "$DEVICE" --out "$WORK"
cp "$WORK"/*.md "$OUT"/ 2>/dev/null
(cd "$WORK" && tar -cf "$OUT/json.tar" ./*.json 2>/dev/null)
echo "=== done in $(( $(date +%s) - t0 ))s" | tee -a "$LOG"
ls -la "$OUT" | tee -a "$LOG"
