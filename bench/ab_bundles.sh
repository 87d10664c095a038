#!/usr/bin/env bash
# The kernel argument bundles (@wp.struct Articulation, EEChain, NetIO, DriveArrays) A/B: the captured control step of
# every kernel family in the tree before them (A) and in this tree (B), alternating on one GPU, with the bitwise check
# of what both write (bench/ab_kernels.sh). Two steps, because the GPU copy of the repository has no usable git:
#
#   bash bench/ab_bundles.sh prepare [BASE]   # in the git checkout: BASE's wpctrl and bench into .gpu/ab_base
#   OUT=DIR bash bench/ab_bundles.sh run      # repo root, warp / newton importable: DIR/ab_kernels.md (+ .tar)
#
# BASE defaults to adfd680, main's last commit before the bundles (the merge of the actuator networks' tiled and
# unrolled kernels; the next one on main merges the bundles in). `prepare` also records both trees' commits, since a
# tree without git metadata reads a stale or foreign one. `run`: each case at 4k envs and the joint cases also at 1M
# (QUICK=1; QUICK=0 adds 16k), ROUNDS=2 alternations, REPEATS=5; BUDGET_S=200 stops starting runs so the summary is
# written within about 3.5 minutes even when both trees compile their kernels cold. DEVICE=cpu runs it on the CPU
# (64 envs per case).
set -uo pipefail
cd "$(dirname "$0")/.."
BASE_TREE=${BASE_TREE:-.gpu/ab_base}
case "${1:-}" in
  prepare)
    base=${2:-adfd680}
    rm -rf "$BASE_TREE" && mkdir -p "$BASE_TREE" || exit 2
    git archive "$base" wpctrl bench | tar -x -C "$BASE_TREE" || exit 2
    git rev-parse --short "$base" > "$BASE_TREE/COMMIT"
    dirty=$(git status --porcelain wpctrl bench | grep -q . && echo "+changes" || true)
    echo "$(git rev-parse --short HEAD)$dirty" > "$BASE_TREE/NEW_COMMIT"
    echo "baseline $(cat "$BASE_TREE/COMMIT") in $BASE_TREE; this tree $(cat "$BASE_TREE/NEW_COMMIT")"
    ;;
  run)
    if [ ! -f "$BASE_TREE/wpctrl/__init__.py" ]; then
      echo "no baseline tree in $BASE_TREE: run 'bash bench/ab_bundles.sh prepare' in the git checkout first" >&2
      exit 2
    fi
    OUT=${OUT:-bench/results} QUICK=${QUICK:-1} ROUNDS=${ROUNDS:-2} REPEATS=${REPEATS:-5} BUDGET_S=${BUDGET_S:-200} \
      A_LABEL="$(cat "$BASE_TREE/COMMIT") (before the argument bundles)" B_LABEL="$(cat "$BASE_TREE/NEW_COMMIT")" \
      bash bench/ab_kernels.sh "$BASE_TREE" .
    ;;
  *)
    echo "usage: bash bench/ab_bundles.sh prepare [BASE] | run" >&2
    exit 2
    ;;
esac
