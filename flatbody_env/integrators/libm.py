"""Elementwise ``exp``, ``log``, ``expm1`` and ``arctan2`` as the C library computes them, on every x86-64 machine alike.

NumPy computes these float64 functions (and ``power``, ``cbrt``, ``arcsin`` and more) with vector code of its own where
the processor has AVX-512, and with the C library's functions elsewhere; the two differ in the last bit (measured with
NumPy 2.4 on an AVX-512 machine, 10⁵ random arguments: ``exp`` 4,572 results differ, ``log`` 191, ``expm1`` 8,515,
``arctan2`` 7,648; with AVX-512 switched off, none). Where such a result steers a motion, one bit becomes another
trajectory within a few hundred steps: the adaptive DOP853 step weighs every component of the state in its error
estimate, the angle θ that :func:`~flatbody_env.env.task.state_from_observation` recovers with ``arctan2`` included.
The planner's reference row of ``FlatBodyAnyBody-v1``, made on an AVX2 machine (83 %), reran at 81 % on an AVX-512
one until the planner's weights and objective (:mod:`agents.planner`), the observed angle and the ELU of an exported
policy (:mod:`agents.numpy_policy`) were computed here: numba ufuncs that call the C library (numba without Intel's
SVML), equal to :mod:`math` bit for bit (``tests/integrators/test_libm.py``). ``tanh`` is not here: NumPy's is the
same code on AVX2 and AVX-512 machines.
"""

from __future__ import annotations

import math

from numba import vectorize


@vectorize(["float64(float64)"], cache=True)
def exp(x):
    """e^x, elementwise (float64), as ``math.exp``."""
    return math.exp(x)


@vectorize(["float64(float64)"], cache=True)
def log(x):
    """ln x, elementwise (float64), as ``math.log`` (−inf at 0 and nan below, where ``math.log`` raises)."""
    return math.log(x) if x > 0.0 else (-math.inf if x == 0.0 else math.nan)


@vectorize(["float64(float64)"], cache=True)
def expm1(x):
    """e^x − 1, elementwise (float64), as ``math.expm1``."""
    return math.expm1(x)


@vectorize(["float64(float64, float64)"], cache=True)
def arctan2(y, x):
    """The angle of (x, y) in (−π, π], elementwise (float64), as ``math.atan2``."""
    return math.atan2(y, x)


__all__ = ["arctan2", "exp", "expm1", "log"]
