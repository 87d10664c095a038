#!/usr/bin/env bash
# The actuator networks on the first CUDA GPU in one go, from the repository root, results in $OUT:
#
#   OUT=/tmp/nets bash bench/nets_gpu.sh
#   OUT=/tmp/nets NETS_VARIANTS=plain,mlp,lstm,torch_mlp,torch_lstm STAGES=bench bash bench/nets_gpu.sh
#   OUT=/tmp/nets NETS_ENVS=4k,1M \
#     NETS_VARIANTS=plain,dc_motor,position_limit,mlp_unrolled,lstm_unrolled,mlp_split4,lstm_split4,mlp_split2,lstm_split2 \
#     NCU_ENVS=4k NCU_VARIANTS=mlp_unrolled,lstm_unrolled,mlp_split4,lstm_split4,mlp_split2,lstm_split2 \
#     TESTS_K="cuda and split" bash bench/nets_gpu.sh     # the split kernel against the unrolled one
#   OUT=/tmp/nets NETS_ENVS=4k,64k,1M NETS_VARIANTS=plain,mlp_unrolled,lstm_unrolled,mlp_fused,lstm_fused \
#     NCU_ENVS=4k NCU_VARIANTS=mlp_unrolled,lstm_unrolled,mlp_fused,lstm_fused NCU_KERNELS="wpctrl_(substep|actuator_net)" \
#     TESTS_K="cuda and (unrolled or auto or two_launches)" bash bench/nets_gpu.sh   # one launch per substep vs two
#
#   nets_gpu.log                  the machine, versions, each stage's output (the bench's per-variant lines, the
#                                 torch baseline's checks against the network kernels and how it was captured, the
#                                 CUDA tests' summary)
#   actuator_cost_cuda.{json,md}  bench/actuator_cost.py at NETS_ENVS (default 4k,64k,1M): plain step, DCMotor,
#                                 position table, MLP and LSTM networks (default, unrolled, split and tiled kernels; the
#                                 kernel that ran, and a network variant's first step against the unrolled kernel's
#                                 when that variant ran before it), the torch baseline
#                                 (one CUDA graph with wpctrl's launches, else two graphs back to back: the
#                                 torch_capture field); a variant that fails is listed under "failures", the rest timed
#   ncu_net_4k.txt, ncu_net_1M.txt
#                                 Nsight Compute's details of one launch of each network kernel (bench/ncu_net.py,
#                                 NCU_VARIANTS: default mlp,lstm,mlp_tiled,lstm_tiled; NCU_ENVS: default "4k 1M"):
#                                 speed of light, compute and memory workload, occupancy, warp stalls, scheduler
#
# STAGES (default bench,ncu,tests) picks the stages and NETS_VARIANTS the bench's variants (default: all but
# newton_dc, the split and the fused ones); NCU_KERNELS the regex of the kernels Nsight Compute profiles (default
# wpctrl_actuator_net: the network kernels; "wpctrl_(substep|actuator_net)" adds the substep kernels and the fused ones); each stage runs under its own time limit (BENCH_LIMIT 300 s, NCU_LIMIT 60 s per
# size, TESTS_LIMIT 100 s; TESTS_K: the tests' -k expression, default cuda). PYTHON: the interpreter (python3);
# DEVICE: the bench's device (cuda:0; cpu for a dry run of the bench stage at NETS_ENVS=64, the torch baseline then
# eager, the split and tiled kernels in Warp's cooperative CPU blocks). Expected on an H100: the bench stage ~2 min
# with a warm kernel cache (Warp compiles first with an empty one: ~1 min more), all three stages ~3.5 min.
# The split-kernel command above (third example): 87 s on an H200 (2026-11-26, with mlp / lstm in place of
# mlp_split4 / lstm_split4, when "auto" still split over 4 at 4k).
# The one-launch command (fourth example): 73 s on an H200 (2026-11-26, with NETS_ENVS=4k,1M and
# NCU_VARIANTS=mlp_unrolled,mlp_fused). mlp / lstm (the defaults) now run what mlp_fused / lstm_fused run;
# mlp_unrolled / lstm_unrolled are the two launches (launch="separate").
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/results}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
PY=${PYTHON:-python3}
DEVICE=${DEVICE:-cuda:0}
NCU=${NCU:-ncu}
STAGES=${STAGES:-bench,ncu,tests}
LOG="$OUT/nets_gpu.log"
export PYTHONUNBUFFERED=1
t0=$(date +%s)
{
  date -u
  [[ $DEVICE == cuda* ]] && nvidia-smi --query-gpu=name,driver_version,clocks.max.sm,clocks.max.mem --format=csv,noheader
  $PY -c "import warp, torch; print('warp', warp.__version__, 'torch', torch.__version__)"
  git rev-parse --short HEAD 2>/dev/null | sed 's/^/wpctrl commit /'
} 2>&1 | tee "$LOG"

if [[ $STAGES == *bench* ]]; then
  echo "=== bench (+$(( $(date +%s) - t0 ))s)" | tee -a "$LOG"
  timeout "${BENCH_LIMIT:-300}" $PY bench/actuator_cost.py --device "$DEVICE" --envs "${NETS_ENVS:-4k,64k,1M}" \
    --variants "${NETS_VARIANTS:-plain,dc_motor,position_limit,mlp_unrolled,lstm_unrolled,mlp,lstm,mlp_tiled,lstm_tiled,torch_mlp,torch_lstm}" \
    --out "$OUT" $([[ $DEVICE == cpu ]] && echo --cpu-blocks) 2>&1 \
    | grep -v "^Module " | tee -a "$LOG"
  echo "bench: exit ${PIPESTATUS[0]}" | tee -a "$LOG"
fi

if [[ $STAGES == *ncu* && $DEVICE == cuda* ]]; then
  for n in ${NCU_ENVS:-4k 1M}; do
    echo "=== ncu $n (+$(( $(date +%s) - t0 ))s)" | tee -a "$LOG"
    timeout "${NCU_LIMIT:-60}" "$NCU" --profile-from-start off --clock-control none \
      --kernel-name "regex:${NCU_KERNELS:-wpctrl_actuator_net}" --section SpeedOfLight --section ComputeWorkloadAnalysis \
      --section MemoryWorkloadAnalysis --section Occupancy --section WarpStateStats --section SchedulerStats \
      --section LaunchStats --page details $PY bench/ncu_net.py --envs "$n" \
      --variants "${NCU_VARIANTS:-mlp,lstm,mlp_tiled,lstm_tiled}" > "$OUT/ncu_net_$n.txt" 2>&1
    echo "ncu $n: exit $?" | tee -a "$LOG"
  done
fi

if [[ $STAGES == *tests* ]]; then
  echo "=== CUDA tests (+$(( $(date +%s) - t0 ))s)" | tee -a "$LOG"
  timeout "${TESTS_LIMIT:-100}" $PY -m pytest tests/test_actuator_net.py tests/test_actuator_net_fused.py -k "${TESTS_K:-cuda}" -q -p no:cacheprovider 2>&1 \
    | tail -25 | tee -a "$LOG"
fi
echo "=== done (+$(( $(date +%s) - t0 ))s)" | tee -a "$LOG"
