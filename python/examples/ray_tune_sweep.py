"""A sweep over tasks and seeds with Ray Tune, each trial one `schrl.train` run.

    .venv/bin/python -m pip install "ray[tune]"
    .venv/bin/python python/examples/ray_tune_sweep.py --tasks seq,cover --seeds 0-4 --out runs/sweep

Each trial trains Point on its task from its seed into OUT/<task>-<seed> (a general
controller first, unless --controller names one) and reports the joint stage's
satisfaction to Tune every ten iterations, then the evaluation's satisfaction and
steps to reach. Ray runs one trial per CPU here, or spreads them over a Ray cluster
(`ray start --head` on one machine, `ray start --address=…` on the others, then this
script with RAY_ADDRESS set). A trial that is started again (a machine lost, the
sweep restarted) continues its run from the last checkpoint rather than from scratch.
"""

import argparse
import os
from pathlib import Path

from ray import tune

import schrl


# --quick: a first look in a minute or two (a short pre-training of one planner
# candidate, a few joint iterations, one evaluation group); not a result.
QUICK = {"pretrain_updates": 20, "pretrain_candidates": 1}


def seeds(text):
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def trial(config):
    # One thread per trial (Tune runs one trial per CPU); read when schrl first trains.
    os.environ.setdefault("RAYON_NUM_THREADS", "1")
    out = Path(config["out"]) / f"{config['task']}-{config['seed']}"
    settings = {"steps": config["steps"], "eval_groups": config["eval_groups"]}
    new_run = dict(QUICK) if config["quick"] else {}

    def progress(event):
        if event["stage"] == "joint" and event["iteration"] % 10 == 0:
            tune.report({"satisfaction": event["satisfaction"], "env_steps": event["done"]})

    if (out / "manifest.json").exists():
        result = schrl.train(out=str(out), resume=True, progress=progress, **settings)
    else:
        controller = {"controller": config["controller"]} if config["controller"] else {}
        result = schrl.train(task=config["task"], seed=config["seed"], out=str(out), progress=progress,
                             **controller, **settings, **new_run)
    final = {"env_steps": result["env_steps"], "iterations": result["iterations"]}
    evaluation = result["evaluation"]
    if evaluation:
        final["satisfaction"] = evaluation["satisfaction_mean"]
        final["steps_to_reach"] = evaluation.get("steps_to_reach_mean", float("nan"))
    tune.report(final)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default="seq", help="comma-separated: seq, cover, branch, loop, signal")
    parser.add_argument("--seeds", default="0-4", help="a seed or a range, e.g. 0-4")
    parser.add_argument("--steps", type=int, default=3_000_000, help="joint-training steps per trial")
    parser.add_argument("--eval-groups", type=int, default=5, help="evaluation groups of 100 runs")
    parser.add_argument("--controller", default=None, help="a `schrl control train` run to warm-start from")
    parser.add_argument("--out", default="runs/sweep", help="directory of the trials' runs")
    parser.add_argument("--quick", action="store_true", help="tiny budgets for a first look (not a result)")
    args = parser.parse_args()
    if args.quick:
        args.steps, args.eval_groups = 20_000, 1
    space = {
        "task": tune.grid_search(args.tasks.split(",")),
        "seed": tune.grid_search(seeds(args.seeds)),
        "steps": args.steps,
        "eval_groups": args.eval_groups,
        "controller": os.path.abspath(args.controller) if args.controller else None,
        "out": os.path.abspath(args.out),
        "quick": args.quick,
    }
    tuner = tune.Tuner(tune.with_resources(trial, {"cpu": 1}), param_space=space)
    results = tuner.fit()
    for r in sorted(results, key=lambda r: (r.config["task"], r.config["seed"])):
        m = r.metrics or {}
        print(f"{r.config['task']:>7} seed {r.config['seed']}: satisfaction {m.get('satisfaction', float('nan')):.3f}, "
              f"steps to reach {m.get('steps_to_reach', float('nan')):.1f}")


if __name__ == "__main__":
    main()
