"""Composition coefficients of a symmetric second-order step (Strang splitting, RATTLE): the one home.

A composition of ``coeffs`` takes the step of size c·h for each c in turn; numpy only (no numba), so
the method table (:mod:`.specs`) can name them without compiling anything.
"""

from __future__ import annotations

import numpy as np

STRANG = np.array([1.0])
"""The symmetric step itself (order 2)."""
_P4 = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))
SUZUKI4 = np.array([_P4, _P4, 1.0 - 4.0 * _P4, _P4, _P4])
"""Suzuki's 5-stage fourth-order composition of a symmetric second-order step."""
_W1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
YOSHIDA4 = np.array([_W1, 1.0 - 2.0 * _W1, _W1])
"""Yoshida's (triple-jump) fourth-order composition."""
KAHAN_LI6 = np.array(
    [
        0.39216144400731413928,
        0.33259913678935943860,
        -0.70624617255763935981,
        0.082213596293550800230,
        0.79854399093482996340,
        0.082213596293550800230,
        -0.70624617255763935981,
        0.33259913678935943860,
        0.39216144400731413928,
    ]
)
"""Kahan & Li's 9-stage sixth-order composition s9odr6a (Math. Comp. 66, 1997; HLW Geometric Numerical
Integration §V.3.2) of a symmetric second-order step."""

__all__ = ["KAHAN_LI6", "STRANG", "SUZUKI4", "YOSHIDA4"]
