#!/usr/bin/env bash
# The impedance controllers on the first CUDA GPU, in one go (under 10 min): their CUDA tests (CPU / CUDA parity,
# graph replay), then bench/osc_step.py (the osc_ee_delta_pose control step at 1k, 16k and 4k Pandas, graph replay
# and eager, next to joint_impedance_delta_pos, the pd_ee_delta_pose step and Newton's ControllerOperationalSpace on
# the same envs; at 4k, last, also one MuJoCo-Warp step). Each stage has a time limit (250 s, 320 s); the results are
# rewritten after every size, so a stage cut short keeps what it measured. About 6 min with a cold Warp kernel cache
# (compiling the unrolled kernels, Newton's controller kernels and MuJoCo-Warp), 2 min warm.
#
#   export PYTHONPATH=/root/site   # on the device machine
#   bash bench/osc_gpu.sh           # results in $OUT if set, else bench/results
#
# Writes osc_step_cuda.{md,json} and osc_gpu.log (the tests' output, the GPU and the versions).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/results}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
LOG="$OUT/osc_gpu.log"
{
  date -u
  nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv,noheader || true
  $PY -c "import sys, warp, newton; print('python', sys.version.split()[0], 'warp', warp.__version__, 'newton', \
newton.__version__)" || exit 1
  git rev-parse --short HEAD 2>/dev/null || true
} 2>&1 | tee "$LOG"
t0=$(date +%s)
echo "=== CUDA tests (limit 250 s)" | tee -a "$LOG"
timeout 250 $PY -m pytest -q -p no:cacheprovider tests/test_impedance_cuda.py 2>&1 | tee -a "$LOG"
echo "=== bench/osc_step.py (limit 320 s, at +$(( $(date +%s) - t0 )) s)" | tee -a "$LOG"
timeout 320 $PY bench/osc_step.py --device "${DEVICE:-cuda:0}" --envs "${OSC_ENVS:-1k,16k,4k}" --physics-envs 4096 \
  --repeats "${REPEATS:-5}" --out "$OUT" 2>&1 | tee -a "$LOG"
echo "=== done in $(( $(date +%s) - t0 )) s" | tee -a "$LOG"
