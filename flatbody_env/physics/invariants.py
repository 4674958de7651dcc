"""Conserved quantities of the flat body (docs/physics.md §6 of [2]).

==================  =====================================  ================================
quantity            formula                                conserved when
==================  =====================================  ================================
energy              H = 𝒯 + V (eq. (41) of [1])            always (no control)
Casimir             |s|² = s1² + s2² + s3²                 always (either spin convention)
p_θ                 p_θ                                    J1 = J2 (eq. (46) of [1])
laboratory spin     R s                                    corrected bracket only (E3/E4)
==================  =====================================  ================================

The physical angular momentum Σ_A J_A Φ_A × Φ̇_A equals −R s (the sign comes from eq. (25)
of [1]; docs/physics.md §6); :func:`angular_momentum` computes it from matrices as an independent check.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import numpy as np


def casimir(s1, s2, s3):
    """|s|², the Casimir of the Lie–Poisson bracket on the spin (eq. (43) of [1])."""
    return np.square(s1) + np.square(s2) + np.square(s3)


def laboratory_spin(R, s) -> np.ndarray:
    """R s, shape (..., 3): the co-moving spin carried to the laboratory frame (docs/physics.md §6)."""
    return np.einsum("...ij,...j->...i", np.asarray(R, float), np.asarray(s, float))


def angular_momentum(Phi, Phi_dot, inertia) -> np.ndarray:
    """Σ_A J_A Φ_A × Φ̇_A from matrices (Φ_A the columns), shape (..., 3); equals −R s."""
    Phi = np.asarray(Phi, float)
    Phi_dot = np.asarray(Phi_dot, float)
    J = (inertia.J1, inertia.J2, inertia.J3)
    return sum(J[a] * np.cross(Phi[..., :, a], Phi_dot[..., :, a]) for a in range(3))
