#!/usr/bin/env bash
# Planner-level results over seeds with `schrl plan train` (README, "Planner results"):
# for each planner network and task, the satisfaction of 200 sampled paths and of 200
# mean paths when training stops (95 % of sampled paths, or the update limit), and the
# updates used; one line per run, then mean ± sample std over seeds.
# Usage: [PLANNERS="gru-ode gru mlp"] [TASKS="seq cover branch"] [UPDATES=3000]
#        [EXTRA="--semantics hard"] scripts/planner-results.sh [OUT_DIR] [SEEDS...]
# (defaults: those planners and tasks, 3000 updates, runs/planner, seeds 0 1 2 3 4)
set -euo pipefail
out=${1:-runs/planner}
shift || true
seeds=("${@:-0 1 2 3 4}")
read -r -a seeds <<<"${seeds[*]}"
read -r -a planners <<<"${PLANNERS:-gru-ode gru mlp}"
read -r -a tasks <<<"${TASKS:-seq cover branch}"
read -r -a extra <<<"${EXTRA:-}"
export RAYON_NUM_THREADS=1
cargo build --release -q -p schrl-cli
source "$(dirname "${BASH_SOURCE[0]}")/summary.sh"
for planner in "${planners[@]}"; do
  for task in "${tasks[@]}"; do
    sampled=() mean=() updates=()
    for seed in "${seeds[@]}"; do
      result=$(./target/release/schrl plan train --task "$task" --planner "$planner" --seed "$seed" \
        --updates "${UPDATES:-3000}" "${extra[@]}" --out "$out/$planner-$task-$seed" --force)
      s=$(grep '^satisfaction:' <<<"$result" | awk '{print $2}')
      m=$(grep '^mean-path satisfaction:' <<<"$result" | awk '{print $3}')
      u=$(grep '^updates:' <<<"$result" | awk '{print $2}')
      printf '%s %s seed %s: sampled %s, mean paths %s, %s updates\n' "$planner" "$task" "$seed" "$s" "$m" "$u"
      sampled+=("$s") mean+=("$m") updates+=("$u")
    done
    printf '%s %s over seeds %s: sampled %s, mean paths %s, updates %s\n' "$planner" "$task" "${seeds[*]}" \
      "$(printf '%s\n' "${sampled[@]}" | summary)" "$(printf '%s\n' "${mean[@]}" | summary)" \
      "$(printf '%s\n' "${updates[@]}" | summary)"
  done
done
