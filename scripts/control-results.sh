#!/usr/bin/env bash
# Trains general controllers for Point, Car and Drone over three seeds with the
# default budgets and evaluates each on 500 random goals (README, "Controller
# results"). Usage: [ROBOTS="car"] scripts/control-results.sh [OUT_DIR]
# (default: all three robots, runs/control)
set -euo pipefail
out=${1:-runs/control}
export RAYON_NUM_THREADS=1
cargo build --release -q -p schrl-cli
for robot in ${ROBOTS:-point car drone}; do
  for seed in 0 1 2; do
    dir="$out/$robot-$seed"
    start=$(date +%s.%N)
    ./target/release/schrl control train --robot "$robot" --seed "$seed" --out "$dir" --force --eval-episodes 0 >/dev/null
    end=$(date +%s.%N)
    steps=$(tail -n1 "$dir/metrics.jsonl" | sed 's/.*"steps":\([0-9]*\).*/\1/')
    result=$(./target/release/schrl control eval --ckpt "$dir" --episodes 500 | tr '\n' ' ')
    printf '%s seed %s: %s steps, %.1f s, %s\n' "$robot" "$seed" "$steps" "$(echo "$end - $start" | bc)" "$result"
  done
done
