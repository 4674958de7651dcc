"""The state of the flat affinely-rigid body with thickness: one layout, defined here only.

The phase space of the two-polar chart (section 3 of [1]) is the spin ``s`` (a co-moving
angular momentum with the Lie–Poisson bracket, eq. (43) of [1] corrected by erratum E3 of
[2]), the canonical pairs :math:`(\\theta, p_\\theta)`, :math:`(\\lambda, p_\\lambda)`,
:math:`(\\mu, p_\\mu)`, :math:`(\\varrho, p_\\varrho)`. The orientation :math:`R \\in SO(3)`
is not part of the state: the Hamiltonian does not depend on it, and it is integrated
alongside only when a scene needs to draw the body.

State layout (the packed array used at the integrator boundary)

=====  ============  =========================================================  =========
index  name          meaning                                                    unit
=====  ============  =========================================================  =========
0      ``s1``        spin, co-moving component 1 (conjugate to ω1)              J·s
1      ``s2``        spin, co-moving component 2 (conjugate to ω2)              J·s
2      ``s3``        spin, co-moving component 3 (conjugate to ω3)              J·s
3      ``p_theta``   momentum conjugate to the material angle θ                 J·s
4      ``p_lambda``  momentum conjugate to λ                                    kg·m·s⁻¹
5      ``p_mu``      momentum conjugate to μ                                    kg·m·s⁻¹
6      ``p_rho``     momentum conjugate to the thickness ϱ                      kg·m·s⁻¹
7      ``lambda``    first in-plane stretch λ > 0 (eq. (24) of [1])             1
8      ``mu``        second in-plane stretch μ > 0                              1
9      ``rho``       thickness ϱ > 0                                            1
10     ``theta``     material rotation angle θ of U(θ) (eq. (24) of [1])        rad
=====  ============  =========================================================  =========

The units are nominal: the model is written in units where the inertia ``J`` carries the
mass and the stretches are dimensionless ratios of lengths.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md``: the verified formulas and the errata of [1].
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

STATE_NAMES: tuple[str, ...] = (
    "s1",
    "s2",
    "s3",
    "p_theta",
    "p_lambda",
    "p_mu",
    "p_rho",
    "lambda",
    "mu",
    "rho",
    "theta",
)
"""Names of the eleven state entries, in packed order."""

STATE_SIZE = len(STATE_NAMES)
S1, S2, S3, P_THETA, P_LAMBDA, P_MU, P_RHO, LAMBDA, MU, RHO, THETA = range(STATE_SIZE)
INDEX: dict[str, int] = {name: i for i, name in enumerate(STATE_NAMES)}

_POSITIVE = ("lambda", "mu", "rho")


def validate_state(state: Mapping[str, Any], *, where: str = "state") -> None:
    """Check a named state: exactly the eleven names, finite numbers, λ, μ, ϱ in
    :data:`~flatbody_env.physics.validation.STRETCH_RANGE`, every other entry within ±
    :data:`~flatbody_env.physics.validation.MOMENTUM_MAX`, λ ≠ μ.

    Raises
    ------
    ValueError
        Naming the offending field and the allowed range.
    """
    if not isinstance(state, Mapping):
        raise ValueError(f"{where}: expected a mapping with the fields {', '.join(STATE_NAMES)}")
    unknown = sorted(set(state) - set(STATE_NAMES))
    if unknown:
        raise ValueError(f"{where}.{unknown[0]}: unknown field (allowed: {', '.join(STATE_NAMES)})")
    from flatbody_env.physics.validation import MOMENTUM_MAX, STRETCH_RANGE, number

    for name in STATE_NAMES:
        if name not in state:
            raise ValueError(f"{where}.{name}: missing field (a finite number is required)")
        if name in _POSITIVE:
            number(f"{where}.{name}", state[name], low=STRETCH_RANGE[0], high=STRETCH_RANGE[1])
        else:
            number(f"{where}.{name}", state[name], low=-MOMENTUM_MAX, high=MOMENTUM_MAX)
    if float(state["lambda"]) == float(state["mu"]):
        raise ValueError(
            f"{where}.lambda: must differ from {where}.mu (λ = μ is the singular set of the "
            "two-polar chart; start the regular model from a nearby state or use model='regular')"
        )


def pack(state: Mapping[str, Any], *, validate: bool = True) -> np.ndarray:
    """Named state → packed float64 array of shape ``(11,)`` in :data:`STATE_NAMES` order."""
    if validate:
        validate_state(state)
    return np.array([float(state[name]) for name in STATE_NAMES], dtype=np.float64)


def unpack(y: np.ndarray) -> dict[str, Any]:
    """Packed array of shape ``(11,)`` or ``(11, n)`` → dict from the eleven names to floats/arrays."""
    y = np.asarray(y, dtype=np.float64)
    if y.shape[0] != STATE_SIZE:
        raise ValueError(f"state array: expected leading dimension {STATE_SIZE}, got shape {y.shape}")
    if y.ndim == 1:
        return {name: float(y[i]) for i, name in enumerate(STATE_NAMES)}
    return {name: y[i].copy() for i, name in enumerate(STATE_NAMES)}
