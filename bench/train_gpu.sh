#!/usr/bin/env bash
# PPO on 4,096 reach envs on one GPU, end to end, in one run of about 3-5 minutes (the durations below are estimates
# from a 4,096-env run on an H100: 120 s of setup with a cold kernel cache, 0.29 s per PPO iteration):
#
#   1. warm-up   (cold kernel cache: ~2-2.5 min; warm: ~20 s; limit 5 min)  one training iteration, so that every
#                kernel (Warp, MuJoCo-Warp, wpctrl, the task's) is compiled and cached before the measured run;
#   2. train     (~30-60 s; limit 5 min)  `python -m wpctrl train` with a warm cache, evaluating the deterministic
#                policy on 4,096 fresh episodes every 5 iterations and stopping at 95 % success (at most TRAIN_ITERS
#                iterations; the same 4,096 envs on the CPU reached 99 % after 30 iterations, 2.9M env steps);
#   3. rate      (~40 s; limit 150 s)  bench/train_rate.py on the same envs: the graph-captured MuJoCo-Warp rollout
#                without a policy, the controller's calls, the env step, rsl-rl alone, PPO's collection step (each
#                timed to a device sync, and the host's share of it), and the training run's collection rate.
#
# Writes 6 files to $OUT (default bench/results/train_gpu): train.json (time_to_target_s is
# the wall time from the command's start to the evaluation that reached 95 %), learning_curve.png, policy.pt,
# train_rate_cuda.json, train_rate_cuda.md, and train_gpu.log (every phase's output and duration).
#
#   bash bench/train_gpu.sh                        # TRAIN_ENVS (4096), TRAIN_ITERS (300), TARGET (0.95), SEED (0)
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/results/train_gpu}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
PY=${PYTHON:-python3}
ENVS=${TRAIN_ENVS:-4096}
ITERS=${TRAIN_ITERS:-300}
TARGET=${TARGET:-0.95}
SEED=${SEED:-0}
export PYTHONUNBUFFERED=1
LOG="$OUT/train_gpu.log"
{
  date -u
  nvidia-smi --query-gpu=name,driver_version --format=csv,noheader || true
  git log -1 --format='wpctrl %h %s' 2>/dev/null || true
  $PY -c "import importlib.metadata as m, torch, warp; print('torch', torch.__version__, 'cuda', torch.cuda.is_available(), \
'warp', warp.__version__, 'newton', m.version('newton'), 'mujoco-warp', m.version('mujoco-warp'), \
'rsl-rl-lib', m.version('rsl-rl-lib'), 'tensordict', m.version('tensordict'))" || exit 1
} 2>&1 | tee "$LOG"

t0=$(date +%s)
phase() {  # phase NAME LIMIT_S CMD...
  local name=$1 limit=$2 start
  shift 2
  start=$(date +%s)
  echo "=== $name (limit ${limit}s, at +$((start - t0))s)" | tee -a "$LOG"
  timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
  local rc=${PIPESTATUS[0]}
  echo "=== $name: exit $rc after $(($(date +%s) - start)) s" | tee -a "$LOG"
}

WARM=$(mktemp -d)
phase warmup 300 $PY -m wpctrl train --envs "$ENVS" --iterations 1 --seed "$SEED" --out "$WARM"
phase train 300 $PY -m wpctrl train --envs "$ENVS" --iterations "$ITERS" --seed "$SEED" --eval-every 5 \
  --target-success "$TARGET" --out "$OUT"
phase rate 150 $PY bench/train_rate.py --envs "$ENVS" --train-json "$OUT/train.json" --out "$OUT"
echo "=== total $(($(date +%s) - t0)) s" | tee -a "$LOG"
