#!/usr/bin/env python3
"""How far a run's 500-run evaluation falls below the validation that chose its checkpoint.

`schrl train --select-every` deploys the checkpoint with the best validation on 100 runs
of its own (seed 7); the evaluation runs 5 x 100 others. Picking the best of a dozen
noisy validations reads high, so the evaluation reads lower on average. This prints,
for each `schrl train` output given (a log or a docs/results text; in an experiment's
`outputs.txt`, each `== <cell>:` section), the deployed checkpoint's validation, the
first evaluation after it (mean plans) and their difference, then the mean difference.

usage: python3 scripts/selection-optimism.py FILE...
"""
import re
import statistics
import sys

VALIDATED = re.compile(r"validated at satisfaction ([0-9.]+)")
EVALUATED = re.compile(r"^satisfaction: ([0-9.]+)", re.M)


def runs_in(path, text):
    """The runs in one file: its `== <cell>:` sections, or the whole file."""
    parts = re.split(r"^== ([^:\n]+):.*$", text, flags=re.M)
    if len(parts) == 1:
        return [(path, text)]
    return [(f"{path} {parts[i]}", parts[i + 1]) for i in range(1, len(parts) - 1, 2)]


def main(paths):
    diffs = []
    for path in paths:
        with open(path, encoding="utf-8") as f:
            text = f.read()
        for name, run in runs_in(path, text):
            v, e = VALIDATED.search(run), EVALUATED.search(run)
            if not (v and e):
                print(f"{name}: no deployed validation and evaluation; skipped", file=sys.stderr)
                continue
            d = float(e.group(1)) - float(v.group(1))
            diffs.append(d)
            print(f"{name}\tvalidated {v.group(1)}\tevaluated {e.group(1)}\t{d:+.3f}")
    if not diffs:
        sys.exit("no file had both a deployed validation and an evaluation")
    sd = statistics.stdev(diffs) if len(diffs) > 1 else 0.0
    print(f"runs {len(diffs)}\tmean difference {statistics.mean(diffs):+.4f} ± {sd:.4f}\t"
          f"below {sum(d < 0 for d in diffs)}, equal {sum(d == 0 for d in diffs)}, above {sum(d > 0 for d in diffs)}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
