"""schrl from Python.

``schrl.stl``: Signal Temporal Logic robustness and its gradient on NumPy arrays,
computed by schrl's Rust STL library (the same numbers as ``schrl robustness``).
``schrl.envs`` (needs gymnasium): the robots as Gymnasium environments.
``train(task=…, out=…)``: a task trained end to end into a run directory, as
``schrl train`` does (the same library call). ``load_planner(ckpt).plan(start)`` and
``evaluate(ckpt)``: a trained run, through the same library calls as ``schrl eval``.
"""

from . import stl
from ._schrl import Planner, evaluate, load_planner, train

__all__ = ["stl", "Planner", "evaluate", "load_planner", "train"]
