#!/usr/bin/env bash
# The GPU runs behind the performance page, in stages that each fit one 10-minute device call (run them back to
# back while the machine stays warm). Results land in $OUT (the device machine sets it; else bench/results/gpu).
#
#   STAGE=tests bash bench/gpu_session.sh      # the CUDA tests (parity, graph replay, new features)
#   STAGE=ab    bash bench/gpu_session.sh      # the control step A/B against BASE_TREE (default .gpu/base)
#   STAGE=act   bash bench/gpu_session.sh      # actuator models' cost, the reach env's step by part
#   STAGE=train bash bench/gpu_session.sh      # PPO on 4,096 reach envs to 95 % success (bench/train_gpu.sh)
#   STAGE=coupled bash bench/gpu_session.sh    # the coupled drive against MuJoCo-Warp; Nsight Compute of its kernel
#   STAGE=models  bash bench/gpu_session.sh    # DC motor / position table against the plain step; Nsight Compute
#   STAGE=tasks   bash bench/gpu_session.sh    # the tasks' CUDA tests and env step (ManiSkill's Panda asset copied to
#                                              # .gpu/assets, or WPCTRL_MANISKILL_ASSETS set)
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/results/gpu}
mkdir -p "$OUT"
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
log="$OUT/${STAGE}.log"
{ date -u; nvidia-smi --query-gpu=name,driver_version --format=csv,noheader; git log -1 --format=%h 2>/dev/null; } > "$log" 2>&1
case "$STAGE" in
  tasks)
    export WPCTRL_MANISKILL_ASSETS=${WPCTRL_MANISKILL_ASSETS:-$PWD/.gpu/assets}
    timeout 280 $PY -m pytest -q -p no:cacheprovider tests/test_tasks_cuda.py 2>&1 | tee -a "$log" | tail -8
    timeout 280 $PY bench/task_step.py --device cuda:0 --envs "${TASK_ENVS:-4k}" --substeps "${TASK_SUBSTEPS:-16,8,4}" \
      --out "$OUT" 2>&1 | tee -a "$log" | tail -10 ;;
  tests)
    timeout 560 $PY -m pytest -q -p no:cacheprovider tests/test_cuda.py tests/test_cuda_features.py tests/test_ee_cuda.py \
      "tests/test_actuation.py::test_cuda_captured_randomisation_reaches_mujoco" 2>&1 | tee -a "$log" | tail -30 ;;
  ab)
    AB_ENVS=${AB_ENVS:-4k,1M} REPEATS=${REPEATS:-5} timeout 580 bash bench/ab_step.sh "${BASE_TREE:-.gpu/base}" . 2>&1 \
      | tee -a "$log" | tail -40 ;;
  act)
    # one process per model, each against the plain step of the same process (ratios in one run)
    work=$(mktemp -d)
    for v in dc_motor position_limit newton_dc mlp lstm; do
      timeout 100 $PY bench/actuator_cost.py --envs "${ACT_ENVS:-1,4k,64k,1M}" --repeats 5 --variants "plain,$v" \
        --tag "cuda_$v" --out "$work" 2>&1 | grep -E "x plain|skipped" | tee -a "$log"
    done
    (cd "$work" && tar -cf "$OUT/actuator_cost.tar" ./*)
    timeout 200 $PY bench/train_rate.py --envs 4096 --out "$OUT" 2>&1 | tee -a "$log" | tail -12 ;;
  train)
    OUT="$OUT" PYTHON="$PY" timeout 590 bash bench/train_gpu.sh 2>&1 | tee -a "$log" | tail -40 ;;
  coupled)
    timeout 300 $PY bench/inertia_update.py --device cuda:0 --envs "${COUPLED_ENVS:-1,4k,64k}" --variants coupled \
      --mujoco --repeats 5 --out "$OUT" 2>&1 | tee -a "$log" | tail -20
    # one graph-replayed coupled launch at 4k envs (the bench's warm-up launches skipped)
    timeout 200 ncu --kernel-name regex:coupled_drive --launch-skip 20 --launch-count 1 --section SpeedOfLight \
      --section LaunchStats --section Occupancy --section WarpStateStats --section MemoryWorkloadAnalysis --section InstructionStats \
      $PY bench/inertia_update.py --device cuda:0 --envs 4k --variants "coupled, H per substep" --repeats 1 \
      --out "$(mktemp -d)" > "$OUT/ncu_coupled.txt" 2>&1; tail -5 "$OUT/ncu_coupled.txt"
    if [ -n "${NCU_SOURCE:-}" ]; then  # per-source-line instruction counts and stall samples (kernel built with lineinfo)
      timeout 240 ncu --kernel-name regex:coupled_drive --launch-skip 20 --launch-count 1 --section SourceCounters \
        --section WarpStateStats --import-source yes -f -o "$OUT/coupled_src" $PY -c "import runpy, sys, warp as wp
wp.config.lineinfo = True
sys.argv = ['inertia_update.py', '--device', 'cuda:0', '--envs', '4k', '--variants', 'coupled, H per substep',
            '--repeats', '1', '--out', '/tmp/ncu_src']
runpy.run_path('bench/inertia_update.py', run_name='__main__')" > "$OUT/ncu_coupled_source.log" 2>&1
      ncu -i "$OUT/coupled_src.ncu-rep" --page source --csv --print-source cuda > "$OUT/ncu_coupled_source.csv" 2>&1
      rm -f "$OUT/coupled_src.ncu-rep"; wc -l "$OUT/ncu_coupled_source.csv"
    fi ;;
  models)
    for v in dc_motor position_limit; do
      timeout 100 $PY bench/actuator_cost.py --envs "${ACT_ENVS:-1,4k,64k}" --repeats 5 --variants "plain,$v" \
        --tag "cuda_$v" --out "$OUT" 2>&1 | grep -E "x plain|skipped" | tee -a "$log"
    done
    : > "$OUT/ncu_substep.txt"
    for v in plain dc_motor position_limit; do  # one graph-replayed substep launch at 4k envs per variant
      echo "=== $v" >> "$OUT/ncu_substep.txt"
      timeout 100 ncu --kernel-name regex:wpctrl_substep --launch-skip 20 --launch-count 1 --section SpeedOfLight \
        --section LaunchStats --section WarpStateStats $PY bench/actuator_cost.py --envs 4k --repeats 1 \
        --variants "$v" --tag ncu --out "$(mktemp -d)" >> "$OUT/ncu_substep.txt" 2>&1
    done
    grep -E "^===|Duration|Registers Per" "$OUT/ncu_substep.txt"
    for v in plain dc_motor position_limit; do  # 1M envs: one controller per process
      timeout 100 $PY bench/actuator_cost.py --envs 1M --repeats 5 --variants "$v" --tag "cuda_1M_$v" --out "$OUT" 2>&1 \
        | grep -E "graph|skipped" | tee -a "$log"
    done ;;
  *) echo "STAGE: expected tests, ab, act, train, coupled or models, got '${STAGE:-}'"; exit 2 ;;
esac
