#!/usr/bin/env bash
# Trains and evaluates every task of a robot (ROBOT, default point) with the README's
# defaults (`schrl train`: general controller, planner pre-training, 3 M joint steps, 5 × 100 evaluation
# runs of mean paths, and the same evaluation executing sampled plans) over seeds,
# printing one line per run and a mean ± std over seeds per task (README, "Joint
# training results"). EXTRA="--freeze-planner": the frozen-planner ablation.
# Usage: [ROBOT=car] [TASKS="seq cover"] [EXTRA="--planner mlp"] [SCHRL_BIN=path] scripts/joint-results.sh [OUT_DIR] [SEEDS...]
# (SCHRL_BIN: run that binary instead of building target/release/schrl, e.g. a copy
# that stays put while the tree changes)
# (defaults: all five tasks, runs/joint, seeds 0 1 2)
set -euo pipefail
out=${1:-runs/joint}
shift || true
seeds=("${@:-0 1 2}")
read -r -a seeds <<<"${seeds[*]}"
export RAYON_NUM_THREADS=1
source "$(dirname "${BASH_SOURCE[0]}")/summary.sh"
schrl_bin
robot=${ROBOT:-point}
read -r -a tasks <<<"${TASKS:-seq cover branch loop signal}"
read -r -a extra <<<"${EXTRA:-}"
for task in "${tasks[@]}"; do
  sats=() reach=() secs=() samples=()
  for seed in "${seeds[@]}"; do
    dir="$out/$robot-$task-$seed"
    start=$(date +%s.%N)
    result=$("$bin" train --robot "$robot" --task "$task" --seed "$seed" "${extra[@]}" --out "$dir" --force)
    end=$(date +%s.%N)
    sat=$(grep '^satisfaction:' <<<"$result" | awk '{print $2}')
    steps=$(grep '^steps to reach:' <<<"$result" | awk '{print $4}')
    t=$(echo "$end - $start" | bc)
    sampled=$("$bin" eval --ckpt "$dir" --sampled-plans | grep '^satisfaction:' | awk '{print $2}')
    printf '%s %s seed %s: satisfaction %s (sampled plans %s), steps to reach %s, %.1f s\n' \
      "$robot" "$task" "$seed" "$sat" "$sampled" "$steps" "$t"
    sats+=("$sat") secs+=("$t") samples+=("$sampled")
    [[ "$steps" != "-" && -n "$steps" ]] && reach+=("$steps")
  done
  printf '%s %s over seeds %s: satisfaction %s (sampled plans %s), steps to reach %s, wall time %s s\n' \
    "$robot" "$task" "${seeds[*]}" \
    "$(printf '%s\n' "${sats[@]}" | summary)" \
    "$(printf '%s\n' "${samples[@]}" | summary)" \
    "$( ((${#reach[@]})) && printf '%s\n' "${reach[@]}" | summary || echo -)" \
    "$(printf '%s\n' "${secs[@]}" | summary)"
done
