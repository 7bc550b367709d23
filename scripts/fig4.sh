#!/usr/bin/env bash
# The paper's Fig. 4 on executed runs: for every Point task and seed, (a) SCHRL as
# trained by default, (b) the run's general controller in place of the jointly
# trained one, (c) gradient-planner plans executed by the jointly trained controller,
# (d) a run trained with the planner frozen after pre-training. Writes
# OUT/fig4.csv (one row per run) and OUT/fig4.png / .svg (bars normalised per task),
# and OUT/sampled.csv: (a) and (d) executing sampled plans instead of mean paths.
# Needs the runs of scripts/joint-results.sh: DEFAULT_DIR/point-<task>-<seed> (default)
# and FROZEN_DIR/point-<task>-<seed> (EXTRA="--freeze-planner").
# Usage: [TASKS="seq cover"] [GRADIENT_EVAL="--groups 5 --per-group 20"] \
#        scripts/fig4.sh DEFAULT_DIR FROZEN_DIR OUT [SEEDS...]
set -euo pipefail
default=$1 frozen=$2 out=$3
shift 3
seeds=("${@:-0 1 2 3 4}")
read -r -a seeds <<<"${seeds[*]}"
read -r -a tasks <<<"${TASKS:-seq cover branch loop signal}"
read -r -a gradient_eval <<<"${GRADIENT_EVAL:-}"
export RAYON_NUM_THREADS=1
source "$(dirname "${BASH_SOURCE[0]}")/summary.sh"
schrl_bin
mkdir -p "$out"
csv="$out/fig4.csv" sampled="$out/sampled.csv"
for f in "$csv" "$sampled"; do echo "task,variant,seed,satisfaction,steps_to_reach" >"$f"; done
row() { # file task variant seed eval-output
  local sat steps
  sat=$(grep '^satisfaction:' <<<"$5" | awk '{print $2}')
  steps=$(grep '^steps to reach:' <<<"$5" | awk '{print $4}')
  echo "$2,$3,$4,$sat,${steps:--}" | tee -a "$1"
}
for task in "${tasks[@]}"; do
  for seed in "${seeds[@]}"; do
    run="$default/point-$task-$seed"
    frozen_run="$frozen/point-$task-$seed"
    row "$csv" "$task" "(a) SCHRL" "$seed" "$("$bin" eval --ckpt "$run")"
    row "$csv" "$task" "(b) general controller" "$seed" "$("$bin" eval --ckpt "$run" --controller "$run/general")"
    row "$csv" "$task" "(c) gradient planner" "$seed" \
      "$("$bin" eval --ckpt "$run" --planner gradient "${gradient_eval[@]}")"
    row "$csv" "$task" "(d) frozen planner" "$seed" "$("$bin" eval --ckpt "$frozen_run")"
    row "$sampled" "$task" "(a) SCHRL (sampled plans)" "$seed" "$("$bin" eval --ckpt "$run" --sampled-plans)"
    row "$sampled" "$task" "(d) frozen planner (sampled plans)" "$seed" \
      "$("$bin" eval --ckpt "$frozen_run" --sampled-plans)"
  done
done
"$bin" plot bars --results "$csv" --out "$out/fig4.png" --force
"$bin" plot bars --results "$csv" --out "$out/fig4.svg" --force
