#!/usr/bin/env bash
# Nsight Compute profile of wpctrl's control-step kernels at 1M envs, on the first CUDA GPU.
#
#   bash bench/profile_ncu.sh          # results in $OUT if set (the device machine sets it), else bench/results
#
# Profiles one eager control step (bench/ncu_target.py, synthetic 1M-Panda layout, pd_joint_target_delta_pos, K = 5)
# in three modes: implicit without interpolation (the elided substep: set_action alone), implicit with
# interpolation, explicit with interpolation (set_action + 5 substep launches). Writes 3 files:
#   ncu_report.txt   ncu's details page per kernel: Speed Of Light (DRAM throughput % of peak, memory throughput,
#                    duration), Memory Workload Analysis, Occupancy (achieved vs theoretical), Warp State Statistics
#                    (stall reasons: long scoreboard = waiting on global loads), Launch and Scheduler statistics;
#   ncu_metrics.csv  the key figures as one CSV row per kernel launch (ncu --page raw);
#   ncu.log          what ran, with ncu's own messages (e.g. ERR_NVGPUCTRPERM if counters are not accessible).
# Skips cleanly (exit 0, a line in ncu.log) without ncu or without a CUDA device. Sizes: NCU_ENVS (default 1M);
# NCU (the ncu binary), PYTHON. Measured: ~2 min on an H200 (each mode rebuilds the 1M layout; ncu replays each
# kernel once per metric pass).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/results}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
PY=${PYTHON:-python3}
NCU=${NCU:-ncu}
ENVS=${NCU_ENVS:-1M}
LOG="$OUT/ncu.log"
REPORT="$OUT/ncu_report.txt"
CSV="$OUT/ncu_metrics.csv"
export PYTHONUNBUFFERED=1

date -u | tee "$LOG"
if ! command -v "$NCU" >/dev/null 2>&1 && [ ! -x "$NCU" ]; then
  echo "profile_ncu: '$NCU' not found: skipped" | tee -a "$LOG"
  exit 0
fi
if ! $PY -c "import sys, warp as wp; wp.config.quiet = True; sys.exit(0 if wp.is_cuda_available() else 1)" >>"$LOG" 2>&1; then
  echo "profile_ncu: no CUDA device visible to Warp: skipped" | tee -a "$LOG"
  exit 0
fi
"$NCU" --version 2>&1 | tail -1 | tee -a "$LOG"
nvidia-smi --query-gpu=name,driver_version,clocks.max.sm,clocks.max.mem --format=csv,noheader 2>&1 | tee -a "$LOG"
git rev-parse --short HEAD 2>/dev/null | sed 's/^/wpctrl commit /' | tee -a "$LOG"

KERNELS='regex:wpctrl_set_action|wpctrl_substep|_targets_kernel'
SECTIONS=(--section SpeedOfLight --section MemoryWorkloadAnalysis --section Occupancy --section WarpStateStats
  --section LaunchStats --section SchedulerStats)
METRICS=gpu__time_duration.sum,dram__throughput.avg.pct_of_peak_sustained_elapsed,\
gpu__compute_memory_throughput.avg.pct_of_peak_sustained_elapsed,dram__bytes.sum.per_second,dram__bytes_read.sum,\
dram__bytes_write.sum,sm__warps_active.avg.pct_of_peak_sustained_active,sm__maximum_warps_per_active_cycle_pct,\
smsp__average_warps_issue_stalled_long_scoreboard_per_issue_active.ratio,\
smsp__average_warps_issue_stalled_lg_throttle_per_issue_active.ratio,\
smsp__average_warps_issue_stalled_wait_per_issue_active.ratio,smsp__inst_executed.sum,launch__registers_per_thread,\
launch__grid_size,launch__block_size
: > "$REPORT"
: > "$CSV"
t0=$(date +%s)
for spec in "implicit off" "implicit on" "explicit off" "explicit on"; do
  set -- $spec
  args=(bench/ncu_target.py --device cuda:0 --envs "$ENVS" --actuation "$1" --interpolate "$2" --steps 1)
  echo "=== $ENVS envs, actuation $1, interpolate $2 (at +$(( $(date +%s) - t0 ))s)" | tee -a "$LOG" "$REPORT"
  timeout 300 "$NCU" --profile-from-start off --kernel-name "$KERNELS" "${SECTIONS[@]}" --page details \
    $PY "${args[@]}" >> "$REPORT" 2>> "$LOG" || echo "=== ncu (sections) exited $?" | tee -a "$LOG"
  echo "# $ENVS envs, actuation $1, interpolate $2" >> "$CSV"
  timeout 300 "$NCU" --profile-from-start off --kernel-name "$KERNELS" --metrics "$METRICS" --csv --page raw \
    $PY "${args[@]}" 2>> "$LOG" | grep -v '^==PROF==' | grep -v '^envs \|^done' >> "$CSV" \
    || echo "=== ncu (metrics) exited $?" | tee -a "$LOG"
done
echo "=== done in $(( $(date +%s) - t0 ))s" | tee -a "$LOG"
grep -E "^  [a-zA-Z_]+.*_kernel|DRAM Throughput|Memory Throughput|Achieved Occupancy|Duration|Long Scoreboard" \
  "$REPORT" | head -80 | tee -a "$LOG"
ls -la "$OUT" | tee -a "$LOG"
