"""Signal Temporal Logic robustness on NumPy arrays.

A :class:`Spec` is parsed and bound once, then evaluated on a path ``[T, D]`` or a
batch ``[B, T, D]`` (any numeric dtype, any strides; read as float64)::

    import numpy as np
    from schrl.stl import Spec, Ball

    spec = Spec("F[0,9] goal & G[0,9] x > -1", signals=["x", "y"],
                predicates={"goal": Ball([1.0, 0.0], 0.5)})
    path = np.linspace([0.0, 0.0], [1.0, 0.0], 10)
    spec.robustness(path)                        # ρ at step 0 (hard min/max)
    rho, grad = spec.gradient(path, "soft:10")   # ρ and ∂ρ/∂path, shape [10, 2]

Semantics: ``"hard"``, ``"soft:<alpha>"`` (the paper's softmax-weighted mean),
``"lse:<temperature>"``; a smooth one may add ``",until=flat"`` or
``",until=recursive"``. The GIL is released while Rust evaluates. Errors (a spec that
does not parse, with its line and column; an unbound name; a path of the wrong shape)
raise :class:`SpecError`, a ``ValueError``.

Predicates: :class:`Ball` (goal regions), :class:`Halfspace`, :class:`AvoidBoxes`
(staying out of axis-aligned boxes), :class:`AfterStep` (a time trigger).
"""

from ._schrl import AfterStep, AvoidBoxes, Ball, Halfspace, Spec, SpecError

__all__ = ["Spec", "SpecError", "Ball", "Halfspace", "AvoidBoxes", "AfterStep"]
