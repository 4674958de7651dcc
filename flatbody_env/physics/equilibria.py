"""Stationary ellipses from a target shape (the inverse problem of eqs. (52)–(54) of [1]) and their
spectral stability — what the environment's task needs to pick reachable, stable targets.

Branch N of [1] (s1 = s2 = 0, ω1 = ω2 = 0, p_λ = p_μ = p_ϱ = 0, J1 = J2 = J): with u = λ + μ,
v = λ − μ and σ± = s3 ± p_θ, eqs. (52)–(53) are the stationarity of the effective potential
(docs/physics.md §8 of [2])

.. math:: W(\\lambda, \\mu, \\varrho) = \\frac{\\sigma_+^2}{4Ju^2} + \\frac{\\sigma_-^2}{4Jv^2} + V(\\lambda, \\mu, \\varrho),

so a shape (λ, μ) is stationary for σ₊² = 2Ju³ ∂V/∂u and σ₋² = 2Jv³ ∂V/∂v (the inverse problem),
and eq. (54) fixes ϱ* by ∂V/∂ϱ = 0. Then ω3 = σ₊/(2Ju²) + σ₋/(2Jv²) and
θ̇ = σ₊/(2Ju²) − σ₋/(2Jv²) (the inverse Legendre transform after eq. (31) of [1]).

Spectral stability (docs/physics.md §9): the linearisation splits into an out-of-plane block, unstable iff
q = (s3/I2 − ω3)(ω3 − s3/I1) > 0, and a shape block (λ, μ, ϱ with their momenta; s3 and p_θ are
constants of the planar motion) whose frequencies are those of the Hessian of W: stable iff it is
positive definite. The complete Jacobian analysis lives in :mod:`analysis`.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the verified formulas and the errata of [1]), §6–§7.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.equations import rhs_iso
from flatbody_env.physics.hamiltonian import kinetic_iso
from flatbody_env.physics.state import STATE_NAMES, unpack

BRANCHES = ("rotation", "circulation")
"""``rotation``: |s3| > |p_θ| (σ₊σ₋ > 0, ω3 dominant); ``circulation``: |s3| < |p_θ| (θ̇ dominant)."""


@dataclass(frozen=True, kw_only=True)
class StationaryEllipse:
    """One relative equilibrium: λ, μ, ϱ, ω, θ̇ constant (eq. (50) of [1]) — the one record of the package.

    Built by :func:`stationary_from_shape` (the inverse problem, with the cheap spectral test
    ``q``/``shape_hessian_min``) and by :mod:`analysis.stationary` (root finding; branches N, A1,
    A2; full stability lives in :mod:`analysis.stability`).
    """

    branch: str = "N"
    """``"N"`` (s1 = s2 = 0, eqs. (52)–(54) of [1]), ``"A1"`` / ``"A2"`` (steady rotation about material axis 1 / 2)."""
    state: dict[str, float]
    """The full paper state (the eleven :data:`~flatbody_env.physics.state.STATE_NAMES`) at θ = 0."""
    omega: tuple[float, float, float]
    """Co-moving angular velocity (ω1, ω2, ω3)."""
    theta_dot: float
    """Material angular velocity θ̇."""
    energy: float
    """H (eq. (41) of [1])."""
    residual: float
    """max |dy/dt| over the ten reduced components (θ excluded, it is cyclic) of eqs. (43)–(49) of [1]."""
    method: str = "inverse"
    """``"inverse"`` (from a shape), ``"closed-form"`` (V1) or ``"numeric"`` (root finding)."""
    q: float | None = None
    """Out-of-plane coefficient q of the linearisation (s̈1 = q s1; unstable iff q > 0); None when not computed."""
    shape_hessian_min: float | None = None
    """Smallest eigenvalue of the Hessian of W in (λ, μ, ϱ) (shape block stable iff > 0); None when not computed."""

    @property
    def lam(self) -> float:
        return self.state["lambda"]

    @property
    def mu(self) -> float:
        return self.state["mu"]

    @property
    def rho(self) -> float:
        return self.state["rho"]

    @property
    def s3(self) -> float:
        return self.state["s3"]

    @property
    def p_theta(self) -> float:
        return self.state["p_theta"]

    @property
    def omega3(self) -> float:
        return self.omega[2]

    @property
    def y(self) -> np.ndarray:
        """Packed state, shape (11,)."""
        return np.array([self.state[name] for name in STATE_NAMES], dtype=float)

    @property
    def kind(self) -> str:
        """``"rigid"`` when |ω3| ≥ |θ̇| (σ₊σ₋ ≥ 0: the ``"rotation"`` branch of :func:`stationary_from_shape`),
        ``"circulating"`` otherwise (the ``"circulation"`` branch)."""
        return "rigid" if abs(self.omega[2]) >= abs(self.theta_dot) else "circulating"

    @property
    def stable(self) -> bool | None:
        """Spectrally stable (q < 0 and the shape Hessian positive definite); None when not computed."""
        if self.q is None or self.shape_hessian_min is None:
            return None
        return self.q < 0.0 and self.shape_hessian_min > 0.0

    def to_dict(self) -> dict[str, Any]:
        """``{"state", "omega3", "theta_dot", "energy", "residual"}`` (the ``flatbody ellipses --json`` row)."""
        return {
            "state": {name: float(self.state[name]) for name in STATE_NAMES},
            "omega3": float(self.omega[2]),
            "theta_dot": float(self.theta_dot),
            "energy": float(self.energy),
            "residual": float(self.residual),
        }


def equilibrium_thickness(body: Body, lam: float, mu: float) -> float:
    """ϱ* with ∂V/∂ϱ(λ, μ, ϱ*) = 0 (eq. (54) of [1]); (a/b)^{1/3} for eq. (40) alone."""
    if body.potential.kind != 0 and body.thickness is not None:
        return body.thickness.rho_star

    def g(r: float) -> float:
        return body.potential_terms(lam, mu, r)[3]

    lo, hi = 1e-3, 1e3
    if g(lo) * g(hi) > 0:
        raise ValueError("thickness: the potential has no equilibrium thickness (∂V/∂ϱ = 0) in [1e-3, 1e3]")
    from scipy.optimize import brentq  # imported here: scipy.optimize costs ~0.5 s at import, most users never need it

    return float(brentq(g, lo, hi, xtol=1e-15, rtol=1e-15))


def squared_sigmas(body: Body, lam: float, mu: float, rho: float) -> tuple[float, float]:
    """The inverse problem of eqs. (52)–(53) of [1] (docs/physics.md §8 of [2]): (σ₊², σ₋²) that make (λ, μ) stationary.

    .. math:: \\sigma_+^2 = 2Ju^3\\,\\partial V/\\partial u, \\qquad \\sigma_-^2 = 2Jv^3\\,\\partial V/\\partial v,

    with u = λ + μ, v = λ − μ, ∂V/∂u = (V_λ + V_μ)/2, ∂V/∂v = (V_λ − V_μ)/2 (J1 = J2 = J). A negative
    value means no stationary ellipse has this shape.
    """
    J = body.inertia.J1
    _, gl, gm, _ = body.potential_terms(lam, mu, rho)
    u, v = lam + mu, lam - mu
    return J * u**3 * (gl + gm), J * v**3 * (gl - gm)


def _shape_hessian(body: Body, lam: float, mu: float, rho: float, sp: float, sm: float) -> list[list[float]]:
    """Hessian of W in (λ, μ, ϱ), W of the module docstring (plain floats: it runs at every env reset)."""
    J = body.inertia.J1
    u, v = lam + mu, lam - mu
    # kinetic part in (u, v): diag(3σ₊²/(2Ju⁴), 3σ₋²/(2Jv⁴)); λ = (u+v)/2, μ = (u−v)/2 ⇒ u = λ+μ, v = λ−μ,
    # so in (λ, μ): [[ku + kv, ku − kv], [ku − kv, ku + kv]]
    ku = 1.5 * sp * sp / (J * u**4)
    kv = 1.5 * sm * sm / (J * v**4)
    H = [[ku + kv, ku - kv, 0.0], [ku - kv, ku + kv, 0.0], [0.0, 0.0, 0.0]]
    h = 1e-5 * max(1.0, lam, mu, rho)
    x0 = (lam, mu, rho)
    pot = body.potential_terms
    for i in range(3):
        xp = [x0[0], x0[1], x0[2]]
        xm = [x0[0], x0[1], x0[2]]
        xp[i] += h
        xm[i] -= h
        gp = pot(xp[0], xp[1], xp[2])
        gm = pot(xm[0], xm[1], xm[2])
        for r in range(3):
            H[r][i] += (gp[r + 1] - gm[r + 1]) / (2 * h)
    return [[0.5 * (H[r][c] + H[c][r]) for c in range(3)] for r in range(3)]


def _smallest_eigenvalue(H: list[list[float]]) -> float:
    """Smallest eigenvalue of a symmetric 3 × 3 matrix (closed form, trigonometric; O. K. Smith, 1961)."""
    a, b, c = H[0][0], H[1][1], H[2][2]
    p1 = H[0][1] ** 2 + H[0][2] ** 2 + H[1][2] ** 2
    q = (a + b + c) / 3.0
    p2 = (a - q) ** 2 + (b - q) ** 2 + (c - q) ** 2 + 2.0 * p1
    if p2 == 0.0:
        return q
    p = math.sqrt(p2 / 6.0)
    B = [[(H[r][k] - (q if r == k else 0.0)) / p for k in range(3)] for r in range(3)]
    det = (B[0][0] * (B[1][1] * B[2][2] - B[1][2] * B[2][1]) - B[0][1] * (B[1][0] * B[2][2] - B[1][2] * B[2][0])
           + B[0][2] * (B[1][0] * B[2][1] - B[1][1] * B[2][0]))
    r = min(1.0, max(-1.0, 0.5 * det))
    return q + 2.0 * p * math.cos(math.acos(r) / 3.0 + 2.0 * math.pi / 3.0)


def stationary_from_shape(body: Body, lam: float, mu: float, *, branch: str = "circulation", sign: float = 1.0) -> StationaryEllipse:
    """The stationary ellipse with in-plane shape (λ, μ) (inverse problem, docs/physics.md §8).

    Parameters
    ----------
    body : Body
        Isotropic in the plane (J1 = J2).
    lam, mu : float
        Target stretches, λ ≠ μ, both > 0.
    branch : {"rotation", "circulation"}
        Sign of σ₊σ₋ (see :data:`BRANCHES`).
    sign : {+1, −1}
        Overall sign of (s3, p_θ) (time reversal; same stability).

    Raises
    ------
    ValueError
        If no stationary ellipse has this shape (∂V/∂u < 0 or v ∂V/∂v < 0: e.g. V3 needs λμ ≥ 1).
    """
    if not body.inertia.is_isotropic:
        raise ValueError("params: stationary ellipses of branch N need J1 = J2 (isotropic in the plane)")
    if branch not in BRANCHES:
        raise ValueError(f"branch: must be one of {BRANCHES}, got {branch!r}")
    if not (lam > 0 and mu > 0) or lam == mu:
        raise ValueError(f"lambda, mu: need λ, μ > 0 and λ ≠ μ, got {lam}, {mu}")
    J = body.inertia.J1
    rho = equilibrium_thickness(body, lam, mu)
    u, v = lam + mu, lam - mu
    sp2, sm2 = squared_sigmas(body, lam, mu, rho)
    if sp2 < 0 or sm2 < 0:
        raise ValueError(
            f"lambda, mu: no stationary ellipse with shape ({lam:g}, {mu:g}) for this potential "
            f"(needs dV/du >= 0 and (lambda-mu) dV/dv >= 0)"
        )
    sp = math.copysign(math.sqrt(sp2), sign)
    sm = math.sqrt(sm2) * (1.0 if branch == "rotation" else -1.0) * math.copysign(1.0, sign)
    s3, pt = 0.5 * (sp + sm), 0.5 * (sp - sm)
    omega3 = sp / (2 * J * u * u) + sm / (2 * J * v * v)
    theta_dot = sp / (2 * J * u * u) - sm / (2 * J * v * v)
    J3 = body.inertia.J3
    I1, I2 = J * mu * mu + J3 * rho * rho, J * lam * lam + J3 * rho * rho
    q = (s3 / I2 - omega3) * (omega3 - s3 / I1)
    hmin = _smallest_eigenvalue(_shape_hessian(body, lam, mu, rho, sp, sm))
    y = np.array([0.0, 0.0, s3, pt, 0.0, 0.0, 0.0, lam, mu, rho, 0.0])
    # H (eq. (41)) and the residual of eqs. (43)–(49) from the scalar kernels that hamiltonian() and rhs() run
    v, gl, gm, gr = body.potential_terms(lam, mu, rho)
    conv = float(body.kernel_params()[8])
    dy = rhs_iso(0.0, 0.0, s3, pt, 0.0, 0.0, 0.0, lam, mu, rho, 0.0, 0.0, 0.0, 0.0, J, J3, conv, gl, gm, gr)
    energy = kinetic_iso(0.0, 0.0, s3, pt, 0.0, 0.0, 0.0, lam, mu, rho, J, J3)[0] + v
    return StationaryEllipse(
        branch="N", state=unpack(y), omega=(0.0, 0.0, omega3), theta_dot=theta_dot, energy=energy,
        residual=max(abs(d) for d in dy[:10]), method="inverse", q=q, shape_hessian_min=hmin,
    )
