#!/usr/bin/env bash
# The captured control step of every kernel family (generated step kernels, fused inertia / coupled drive, EE chain,
# OSC), two wpctrl trees A/B on one GPU in one run (alternating A, B, A, B), plus a bitwise comparison of what both
# trees write on a fixed sequence: what a change of the kernels' arguments costs, free of machine drift.
#
#   git worktree add /tmp/base <commit>               # the baseline (its own bench/ab_kernels.py is not needed:
#   bash bench/ab_kernels.sh /tmp/base [NEW_TREE=.]   #  this tree's script runs with the baseline's wpctrl)
#
# Results in $OUT (or bench/results): ab_kernels.md and ab_kernels.tar. ROUNDS (default 2), REPEATS (default 7),
# DEVICE (default cuda:0), CASES (default: all of bench/ab_kernels.py), BUDGET_S (default 560: no round starts
# after it, so the summary is written inside a 10-minute call), QUICK=1 (no 16k sizes: ab_kernels.py --quick), A_LABEL /
# B_LABEL (the trees' names in the summary, for trees without git metadata). About 6 minutes on a fresh H100 / H200 (the first
# round compiles each tree's kernels).
set -uo pipefail
OLD=$(cd "$1" && pwd)
NEW=$(cd "${2:-.}" && pwd)
OUT=${OUT:-$NEW/bench/results}
mkdir -p "$OUT"
WORK=$(mktemp -d)
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
ROUNDS=${ROUNDS:-2}
REPEATS=${REPEATS:-7}
DEVICE=${DEVICE:-cuda:0}
CASES=${CASES:-joint_implicit,joint_explicit,stable,accel_implicit,coupled,coupled_h_control,ee,osc,net_mlp,net_lstm}
SCRIPT="$NEW/bench/ab_kernels.py"
BUDGET_S=${BUDGET_S:-560}  # the whole run, so that the summary is written inside a 10-minute call
START=$(date +%s)
for round in $(seq 1 "$ROUNDS"); do
  for side in A B; do
    left=$((BUDGET_S - $(date +%s) + START))
    if [ "$left" -lt 60 ]; then echo "[budget] stopping before round $round $side (${left} s left)"; break 2; fi
    tree=$OLD; [ "$side" = B ] && tree=$NEW
    extra=""; [ "$round" = 1 ] && extra="--outputs $WORK/$side.npz"
    [ "${QUICK:-0}" = 1 ] && extra="$extra --quick"
    # the script from NEW, the wpctrl (and bench.common) of the tree under test
    (cd "$tree" && PYTHONPATH="$tree${PYTHONPATH:+:$PYTHONPATH}" timeout "$left" $PY "$SCRIPT" --device "$DEVICE" --cases "$CASES" \
      --repeats "$REPEATS" --out "$WORK" --tag "${side}_${round}" $extra) 2>&1 | grep -E "^\[" || true
  done
done
$PY "$NEW/bench/ab_kernels_summary.py" "$WORK" ${A_LABEL:+--label-a "$A_LABEL"} ${B_LABEL:+--label-b "$B_LABEL"} \
  > "$OUT/ab_kernels.md"
cat "$OUT/ab_kernels.md"
(cd "$WORK" && tar -cf "$OUT/ab_kernels.tar" ./*.json ./*.npz 2>/dev/null)
