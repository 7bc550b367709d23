#!/usr/bin/env python3
"""Reference values of standard discrete-time STL from rtamt, stored as test fixtures.

Run once (needs `pip install rtamt==0.4.10`); the output is committed, so the tests
do not need Python. Writes crates/stl/tests/fixtures/rtamt_trace.csv (the trace: x, y
per step) and rtamt_expected.csv (formula in schrl's syntax, start step, robustness),
keeping only start steps whose every window lies inside the trace: rtamt and schrl
read the end of a finite trace differently (rtamt: no step, −∞; schrl: the last
state held).
"""
import csv
import pathlib
import random

import rtamt

OUT = pathlib.Path(__file__).resolve().parent.parent / "crates/stl/tests/fixtures"
STEPS = 60
# (schrl syntax, rtamt syntax, horizon in steps)
FORMULAS = [
    ("x > 0 U[3,20] y > 1", "(x > 0) until[3,20] (y > 1)", 20),
    ("x > 0 U[1,3] y > 1", "(x > 0) until[1,3] (y > 1)", 3),
    ("x > 0 U[0,5] y > 1", "(x > 0) until[0,5] (y > 1)", 5),
    ("x > -0.5 U[2,6] y > 0.5", "(x > -0.5) until[2,6] (y > 0.5)", 6),
    ("F[0,4] (x > 0 U[2,5] y > 1)", "eventually[0,4] ((x > 0) until[2,5] (y > 1))", 9),
    ("G[0,3] (x > -1 U[1,2] y > 0)", "always[0,3] ((x > -1) until[1,2] (y > 0))", 5),
]


def main():
    rng = random.Random(7)
    xs = [round(rng.uniform(-1.0, 2.0), 3) for _ in range(STEPS)]
    ys = [round(rng.uniform(-1.0, 2.5), 3) for _ in range(STEPS)]
    OUT.mkdir(parents=True, exist_ok=True)
    with open(OUT / "rtamt_trace.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["x", "y"])
        w.writerows(zip(xs, ys))
    with open(OUT / "rtamt_expected.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["formula", "t", "robustness"])
        for ours, theirs, horizon in FORMULAS:
            spec = rtamt.StlDiscreteTimeOfflineSpecification()
            spec.declare_var("x", "float")
            spec.declare_var("y", "float")
            spec.spec = theirs
            spec.parse()
            out = spec.evaluate({"time": list(range(STEPS)), "x": xs, "y": ys})
            for t, value in out:
                if t + horizon < STEPS:
                    w.writerow([ours, t, repr(float(value))])


if __name__ == "__main__":
    main()
