#!/usr/bin/env bash
# The paper's Table 6 (App. K) on Point: environment steps until convergence of one
# goal-conditioned controller against 1, 2 and 4 options (one policy per goal, the
# options framework), every policy trained by `schrl control train` with the same PPO
# settings and budget (the controller's default 1 M steps, so the learning-rate
# schedule is the same). The options' goals are Seq's g0..g3; k options cost the sum
# of the first k options' steps, in the same seed.
# Convergence: the first update at which the success rate over the last 100 settled
# goals (reached, or lost with their episode) is ≥ 0.95, once 100 goals have been
# settled in all. Writes OUT/table6.csv (one row per policy) and prints the table.
# Resumable: a run with result.txt is kept.
# Usage: [SCHRL_BIN=path] scripts/options.sh OUT [SEEDS...]
set -euo pipefail
out=$1
shift
seeds=("${@:-0 1 2 3 4}")
read -r -a seeds <<<"${seeds[*]}"
export RAYON_NUM_THREADS=1
source "$(dirname "${BASH_SOURCE[0]}")/summary.sh"
schrl_bin
goals=("2.0,2.0" "-1.0,2.0" "-2.0,-1.0" "1.0,-2.0")

# Prints the steps at convergence of the run in $1, or "-" when it never converged.
converged() {
  awk '{
      steps = success = settled = ""
      if (match($0, /"steps":[0-9]+/)) steps = substr($0, RSTART + 8, RLENGTH - 8)
      if (match($0, /"success_rate":[0-9.eE+-]+/)) success = substr($0, RSTART + 15, RLENGTH - 15)
      if (match($0, /"goals_settled":[0-9]+/)) settled = substr($0, RSTART + 16, RLENGTH - 16)
      total += settled
      if (success != "" && total >= 100 && success + 0 >= 0.95) { print steps; found = 1; exit }
    } END { if (!found) print "-" }' "$1/metrics.jsonl"
}

train() { # dir seed [goal]
  local dir=$1 seed=$2 extra=()
  [[ -f "$dir/result.txt" ]] && return 0
  [[ $# -ge 3 ]] && extra=("--goal=$3")
  if [[ -f "$dir/manifest.json" ]]; then
    "$bin" control train --resume --out "$dir" "${extra[@]}" --eval-episodes 0 >"$dir.out" 2>"$dir.err"
  else
    mkdir -p "$(dirname "$dir")"
    "$bin" control train --robot point --seed "$seed" "${extra[@]}" --eval-episodes 0 --out "$dir" \
      >"$dir.out" 2>"$dir.err"
  fi
  mv "$dir.out" "$dir/result.txt"
}

csv="$out/table6.csv"
for seed in "${seeds[@]}"; do
  train "$out/conditioned-$seed" "$seed"
  for i in 0 1 2 3; do train "$out/option-g$i-$seed" "$seed" "${goals[$i]}"; done
  echo "seed $seed: conditioned $(converged "$out/conditioned-$seed")," \
    "options $(for i in 0 1 2 3; do converged "$out/option-g$i-$seed"; done | paste -sd' ')"
done

echo "policy,seed,steps_to_converge" >"$csv"
for seed in "${seeds[@]}"; do
  echo "conditioned,$seed,$(converged "$out/conditioned-$seed")" >>"$csv"
  for i in 0 1 2 3; do echo "option-g$i,$seed,$(converged "$out/option-g$i-$seed")" >>"$csv"; done
done
# k options: per seed, the sum of options g0..g(k-1); "-" if any of them never converged.
options() {
  for seed in "${seeds[@]}"; do
    grep -E "^option-g[0-$(($1 - 1))],$seed," "$csv" | cut -d, -f3 |
      awk '{ if ($1 == "-") bad = 1; s += $1 } END { if (!bad) print s }'
  done
}
printf 'Table 6 over seeds %s (environment steps until convergence, mean ± std):\n' "${seeds[*]}"
printf '  goal-conditioned controller: %s\n' "$(grep '^conditioned,' "$csv" | cut -d, -f3 | grep -v -- - | summary)"
for k in 1 2 4; do printf '  %d option(s): %s\n' "$k" "$(options "$k" | summary)"; done
printf '  never converged: %s\n' "$(grep -c ',-$' "$csv" || true)"
