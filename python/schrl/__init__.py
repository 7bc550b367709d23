"""schrl from Python.

``schrl.stl``: Signal Temporal Logic robustness and its gradient on NumPy arrays,
computed by schrl's Rust STL library (the same numbers as ``schrl robustness``).
"""

from . import stl

__all__ = ["stl"]
