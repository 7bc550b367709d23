# Shared by the results scripts. `schrl_bin` sets `bin` to $SCHRL_BIN, or builds
# target/release/schrl and uses it (SCHRL_BIN: a copy that stays put while the tree
# changes).
schrl_bin() {
  bin=${SCHRL_BIN:-}
  if [[ -z "$bin" ]]; then
    cargo build --release -q -p schrl-cli
    bin=./target/release/schrl
  fi
}

# `summary` prints the mean ± sample std of the numbers
# on stdin (one per line), or "-" when there are none.
summary() {
  awk '{ s += $1; q += $1 * $1; n++ } END {
    if (n == 0) { print "-"; exit }
    m = s / n; v = n > 1 ? (q - n * m * m) / (n - 1) : 0; if (v < 0) v = 0
    printf "%.3f ± %.3f", m, sqrt(v) }'
}
