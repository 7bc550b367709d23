"""schrl.stl against rtamt on the same formulas and traces: the hard robustness at
step 0 of one trace of T steps, per call, both from Python; and the two values side by
side (they agree where every window lies inside the trace, as the STL crate's rtamt
fixtures show).
Needs rtamt (not a dependency of schrl): `.venv/bin/python -m pip install rtamt`.
Run: .venv/bin/python python/benchmarks/vs_rtamt.py [--steps 1000 10000] (BENCHMARKS.md)."""

import argparse
import time

import numpy as np
import rtamt

from schrl.stl import Spec

# (schrl syntax, rtamt syntax)
FORMULAS = [
    ("G[0,50] (x > -2) & F[0,50] (y > 1)", "always[0,50] (x > -2) and eventually[0,50] (y > 1)"),
    ("G[0,100] F[0,20] (x > 0.5)", "always[0,100] eventually[0,20] (x > 0.5)"),
    ("(x > 0) U[3,20] (y > 1)", "(x > 0) until[3,20] (y > 1)"),
]


def best_of(f, repeat):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        value = f()
        times.append(time.perf_counter() - start)
    return min(times), value


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(7)
    for steps in args.steps:
        trace = np.cumsum(rng.normal(0, 0.2, size=(steps, 2)), axis=0)
        for ours, theirs in FORMULAS:
            spec = Spec(ours, signals=["x", "y"])
            t_ours, v_ours = best_of(lambda: spec.robustness(trace), args.repeat)
            monitor = rtamt.StlDiscreteTimeOfflineSpecification()
            monitor.declare_var("x", "float")
            monitor.declare_var("y", "float")
            monitor.spec = theirs
            monitor.parse()
            data = {"time": list(range(steps)), "x": trace[:, 0].tolist(), "y": trace[:, 1].tolist()}
            t_theirs, out = best_of(lambda: monitor.evaluate(data), args.repeat)
            v_theirs = float(out[0][1])
            print(
                f"T={steps} {ours}: schrl {t_ours * 1e3:.3f} ms, rtamt {t_theirs * 1e3:.1f} ms "
                f"({t_theirs / t_ours:.0f}x); rho {v_ours:.6f} vs {v_theirs:.6f}"
            )


if __name__ == "__main__":
    main()
