#!/usr/bin/env bash
# The paper's Fig. 3 / Fig. 12 on Point: SCHRL (`schrl train`), HTLTL and TLTL
# (`schrl baseline train`) on every task and seed, each with its defaults (the same
# 4 M environment-step budget: SCHRL's and HTLTL's 1 M general-controller steps count).
# Each run goes to OUT/<method>/point-<task>-<seed>; its printed evaluation to
# result.txt there. A run without result.txt is resumed from its last checkpoint, so
# the script can be stopped and rerun. Then writes OUT/baselines.csv (one row per
# finished run on SEEDS, any task and method: the 5 × 100 evaluation and the mean
# training spec score over the run's last 100 000 steps) and
# OUT/fig3-point.png / .svg (`schrl plot curves`: spec score against environment
# steps, mean ± std over seeds). METHODS may also name crm and dhrm.
# Usage: [TASKS="seq cover"] [METHODS="schrl htltl tltl"] [JOBS=2] [SCHRL_BIN=path] \
#        scripts/baselines.sh OUT [SEEDS...]
set -euo pipefail
out=$1
shift
seeds=("${@:-0 1 2 3 4}")
read -r -a seeds <<<"${seeds[*]}"
read -r -a tasks <<<"${TASKS:-seq cover branch loop signal}"
read -r -a methods <<<"${METHODS:-schrl htltl tltl}"
export RAYON_NUM_THREADS=1
source "$(dirname "${BASH_SOURCE[0]}")/summary.sh"
schrl_bin
export bin

one() { # method task seed
  local dir="$out/$1/point-$2-$3" cmd again=()
  [[ -f "$dir/result.txt" ]] && return 0
  case $1 in
    schrl) cmd=(train) ;;
    *) cmd=(baseline train --algo "$1") ;;
  esac
  if [[ -f "$dir/manifest.json" ]]; then again=(--resume); else again=(--task "$2" --seed "$3"); fi
  mkdir -p "$(dirname "$dir")"
  # Only a run that finished gets its result.txt: a stopped one is resumed next time.
  if ! "$bin" "${cmd[@]}" "${again[@]}" --out "$dir" >"$dir.out" 2>"$dir.err"; then
    echo "$1 $2 seed $3: stopped or failed (see $dir.err); rerun to resume" >&2
    return 1
  fi
  mv "$dir.out" "$dir/result.txt"
  echo "$1 $2 seed $3: $(grep '^satisfaction:' "$dir/result.txt")"
}
export -f one
export out
for task in "${tasks[@]}"; do
  for seed in "${seeds[@]}"; do
    for method in "${methods[@]}"; do echo "$method $task $seed"; done
  done
done | xargs -P "${JOBS:-2}" -L 1 bash -c 'one "$@"' _

# The table and the figure cover every finished run under OUT on SEEDS, whichever
# invocation made it, in the paper's task and method order.
# Mean spec score of the training episodes logged in the run's last 100 000 steps.
final_score() {
  awk '{
      if (!match($0, /"env_steps":[0-9]+/)) next
      step = substr($0, RSTART + 12, RLENGTH - 12) + 0
      if (!match($0, /"score":-?[0-9.eE+-]+/)) next
      n++; steps[n] = step; score[n] = substr($0, RSTART + 8, RLENGTH - 8) + 0
    } END {
      if (n == 0) { print "-"; exit }
      for (i = 1; i <= n; i++) if (steps[i] > steps[n] - 100000) { s += score[i]; k++ }
      printf "%.3f\n", s / k
    }' "$1/metrics.jsonl"
}
csv="$out/baselines.csv"
echo "task,variant,seed,satisfaction,steps_to_reach,final_score" >"$csv"
runs=()
for task in seq cover branch loop signal; do
  for method in schrl htltl tltl crm dhrm; do
    for seed in "${seeds[@]}"; do
      r="$out/$method/point-$task-$seed/result.txt"
      [[ -f "$r" ]] || continue
      sat=$(grep '^satisfaction:' "$r" | awk '{print $2}')
      steps=$(grep '^steps to reach:' "$r" | awk '{print $4}')
      echo "$task,$method,$seed,$sat,${steps:--},$(final_score "$(dirname "$r")")" >>"$csv"
      runs+=(--run "$task:$method:$out/$method/point-$task-$seed")
    done
  done
done
for task in seq cover branch loop signal; do
  for method in schrl htltl tltl crm dhrm; do
    rows=$(grep "^$task,$method," "$csv" || true)
    [[ -n "$rows" ]] || continue
    printf '%s %s over seeds %s: satisfaction %s (%s), steps to reach %s, final spec score %s\n' \
      "$task" "$method" "$(cut -d, -f3 <<<"$rows" | paste -sd' ')" \
      "$(cut -d, -f4 <<<"$rows" | summary)" "$(cut -d, -f4 <<<"$rows" | paste -sd' ')" \
      "$(cut -d, -f5 <<<"$rows" | grep -vx -- - | summary)" \
      "$(cut -d, -f6 <<<"$rows" | grep -vx -- - | summary)"
  done
done
"$bin" plot curves "${runs[@]}" --out "$out/fig3-point.png" --force
"$bin" plot curves "${runs[@]}" --out "$out/fig3-point.svg" --force
