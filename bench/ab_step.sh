#!/usr/bin/env bash
# The captured control step of two wpctrl trees, A/B on one GPU in one run (alternating A, B, A, B), for the same
# sizes and modes: what a change of the engine costs, free of machine-to-machine and run-to-run drift.
#
#   bash bench/ab_step.sh OLD_TREE [NEW_TREE=.]     # results in $OUT (or bench/results): ab_step.md, ab_step.tar
#
# OLD_TREE is a checkout of the baseline (e.g. `git worktree add /tmp/base <commit>`); its bench/controller_step.py
# imports its own wpctrl. Sizes: AB_ENVS (default 4k,1M), REPEATS (default 7), DEVICE (default cuda:0).
set -uo pipefail
OLD=$(cd "$1" && pwd)
NEW=$(cd "${2:-.}" && pwd)
OUT=${OUT:-$NEW/bench/results}
mkdir -p "$OUT"
WORK=$(mktemp -d)
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
ENVS=${AB_ENVS:-4k,1M}
REPEATS=${REPEATS:-7}
DEVICE=${DEVICE:-cuda:0}
for round in 1 2; do
  for side in A B; do
    tree=$OLD; [ "$side" = B ] && tree=$NEW
    for act in implicit explicit; do
      (cd "$tree" && timeout 300 $PY bench/controller_step.py --device "$DEVICE" --envs "$ENVS" --repeats "$REPEATS" \
        --actuation "$act" --interpolate off --variants wpctrl_graph,wpctrl_eager \
        --tag "ab_${side}_${act}_${round}" --out "$WORK") 2>&1 | grep -E "^\[|wpctrl_commit" || true
    done
  done
done
$PY "$NEW/bench/ab_summary.py" "$WORK" > "$OUT/ab_step.md"
cat "$OUT/ab_step.md"
(cd "$WORK" && tar -cf "$OUT/ab_step.tar" ./*.json)
