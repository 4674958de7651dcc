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
from flatbody_env.physics import validation
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
    from scipy.optimize import brentq  # imported here: scipy.optimize is slow to import; most users never need it

    return float(brentq(g, lo, hi, xtol=1e-15, rtol=1e-15))


def squared_sigmas_kernel(J, lam, mu, gl, gm):
    """(σ₊², σ₋²) of the inverse problem (eqs. (52)–(53) of [1]) from ∂V/∂λ, ∂V/∂μ at (λ, μ); plain floats
    (:func:`squared_sigmas`, whose docstring gives the formula; compiled by the environment's reset)."""
    u = lam + mu
    v = lam - mu
    return J * (u * u * u) * (gl + gm), J * (v * v * v) * (gl - gm)


def squared_sigmas(body: Body, lam: float, mu: float, rho: float) -> tuple[float, float]:
    """The inverse problem of eqs. (52)–(53) of [1] (docs/physics.md §8 of [2]): (σ₊², σ₋²) that make (λ, μ) stationary.

    .. math:: \\sigma_+^2 = 2Ju^3\\,\\partial V/\\partial u, \\qquad \\sigma_-^2 = 2Jv^3\\,\\partial V/\\partial v,

    with u = λ + μ, v = λ − μ, ∂V/∂u = (V_λ + V_μ)/2, ∂V/∂v = (V_λ − V_μ)/2 (J1 = J2 = J). A negative
    value means no stationary ellipse has this shape.
    """
    _, gl, gm, _ = body.potential_terms(lam, mu, rho)
    return squared_sigmas_kernel(body.inertia.J1, lam, mu, gl, gm)


def stencil_step(lam, mu, rho):
    """Step h of the central differences of :func:`shape_stability_kernel`'s potential stencil."""
    return 1e-5 * max(1.0, lam, mu, rho)


def potential_stencil(body: Body, lam: float, mu: float, rho: float) -> np.ndarray:
    """The potential stencil (7, 4) of :func:`stationary_shape_kernel` for ``body`` (any potential,
    custom ones included): row 0 (V, ∂V/∂λ, ∂V/∂μ, ∂V/∂ϱ) at (λ, μ, ϱ), rows 1 + 2i and 2 + 2i at
    that point moved by +h and −h along coordinate i (h = :func:`stencil_step`)."""
    h = stencil_step(lam, mu, rho)
    x0 = (lam, mu, rho)
    pot = np.empty((7, 4))
    pot[0] = body.potential_terms(lam, mu, rho)
    for i in range(3):
        xp, xm = list(x0), list(x0)
        xp[i] += h
        xm[i] -= h
        pot[1 + 2 * i] = body.potential_terms(*xp)
        pot[2 + 2 * i] = body.potential_terms(*xm)
    return pot


def smallest_eigenvalue_sym3(a00, a01, a02, a11, a12, a22):
    """Smallest eigenvalue of the symmetric 3 × 3 matrix with these entries (closed form,
    trigonometric; O. K. Smith, "Eigenvalues of a symmetric 3 × 3 matrix", Commun. ACM 4, 168 (1961))."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    p2 = (a00 - q) * (a00 - q) + (a11 - q) * (a11 - q) + (a22 - q) * (a22 - q) + 2.0 * p1
    if p2 == 0.0:
        return q
    p = math.sqrt(p2 / 6.0)
    b00 = (a00 - q) / p
    b11 = (a11 - q) / p
    b22 = (a22 - q) / p
    b01 = a01 / p
    b02 = a02 / p
    b12 = a12 / p
    det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
    r = min(1.0, max(-1.0, 0.5 * det))
    return q + 2.0 * p * math.cos(math.acos(r) / 3.0 + 2.0 * math.pi / 3.0)


def stationary_shape_kernel(J, J3, lam, mu, rho, pot, rotation, sign, out):
    """The stationary ellipse of shape (λ, μ) and thickness ϱ (branch N) and its cheap spectral test, on
    plain floats — the one formula behind :func:`stationary_from_shape` and the environment's compiled
    reset.

    Parameters
    ----------
    J, J3 : float
        J1 = J2 = J and J3.
    lam, mu, rho : float
        The shape (λ ≠ μ, both > 0) and ϱ* (eq. (54) of [1]).
    pot : (7, 4)
        The potential stencil (:func:`potential_stencil`) at (λ, μ, ϱ), step :func:`stencil_step`.
    rotation : bool
        The ``"rotation"`` branch (σ₊σ₋ > 0), else ``"circulation"``.
    sign : float
        ±1, the overall sign of (s3, p_θ).
    out : (6,), output
        s3, p_θ, ω3, θ̇, q and the smallest eigenvalue of the Hessian of W in (λ, μ, ϱ).

    Returns
    -------
    bool
        False when no stationary ellipse has this shape (σ₊² < 0 or σ₋² < 0); ``out`` is then unset.

    Notes
    -----
    σ±² from :func:`squared_sigmas_kernel` (eqs. (52)–(53)); s3 = (σ₊ + σ₋)/2, p_θ = (σ₊ − σ₋)/2;
    ω3 = σ₊/(2Ju²) + σ₋/(2Jv²), θ̇ = σ₊/(2Ju²) − σ₋/(2Jv²); q = (s3/I2 − ω3)(ω3 − s3/I1) with
    I1 = Jμ² + J3ϱ², I2 = Jλ² + J3ϱ² (out-of-plane block, unstable iff q > 0); the Hessian of W
    (module docstring): kinetic part diag(3σ₊²/(2Ju⁴), 3σ₋²/(2Jv⁴)) in (u, v), potential part by central
    differences of ∇V over the stencil, symmetrised.
    """
    sp2, sm2 = squared_sigmas_kernel(J, lam, mu, pot[0, 1], pot[0, 2])
    if sp2 < 0 or sm2 < 0:
        return False
    u = lam + mu
    v = lam - mu
    sp = math.copysign(math.sqrt(sp2), sign)
    sm = math.sqrt(sm2) * (1.0 if rotation else -1.0) * math.copysign(1.0, sign)
    s3 = 0.5 * (sp + sm)
    out[0] = s3
    out[1] = 0.5 * (sp - sm)
    omega3 = sp / (2 * J * u * u) + sm / (2 * J * v * v)
    out[2] = omega3
    out[3] = sp / (2 * J * u * u) - sm / (2 * J * v * v)
    I1 = J * mu * mu + J3 * rho * rho
    I2 = J * lam * lam + J3 * rho * rho
    out[4] = (s3 / I2 - omega3) * (omega3 - s3 / I1)
    # Hessian of W: kinetic part in (u, v) is diag(ku, kv); with u = λ + μ, v = λ − μ it is
    # [[ku + kv, ku − kv], [ku − kv, ku + kv]] in (λ, μ)
    ku = 1.5 * sp * sp / (J * (u * u * u * u))
    kv = 1.5 * sm * sm / (J * (v * v * v * v))
    h2 = 2 * stencil_step(lam, mu, rho)
    # potential part: d_rc = ∂²V/∂x_r∂x_c ≈ (∂V/∂x_r(x + h e_c) − ∂V/∂x_r(x − h e_c)) / 2h
    d00 = (pot[1, 1] - pot[2, 1]) / h2
    d01 = (pot[3, 1] - pot[4, 1]) / h2
    d02 = (pot[5, 1] - pot[6, 1]) / h2
    d10 = (pot[1, 2] - pot[2, 2]) / h2
    d11 = (pot[3, 2] - pot[4, 2]) / h2
    d12 = (pot[5, 2] - pot[6, 2]) / h2
    d20 = (pot[1, 3] - pot[2, 3]) / h2
    d21 = (pot[3, 3] - pot[4, 3]) / h2
    d22 = (pot[5, 3] - pot[6, 3]) / h2
    a00 = 0.5 * ((ku + kv + d00) + (ku + kv + d00))
    a11 = 0.5 * ((ku + kv + d11) + (ku + kv + d11))
    a22 = 0.5 * ((0.0 + d22) + (0.0 + d22))
    a01 = 0.5 * ((ku - kv + d01) + (ku - kv + d10))
    a02 = 0.5 * ((0.0 + d02) + (0.0 + d20))
    a12 = 0.5 * ((0.0 + d12) + (0.0 + d21))
    out[5] = smallest_eigenvalue_sym3(a00, a01, a02, a11, a12, a22)
    return True


def stationary_from_shape(
    body: Body, lam: float, mu: float, *, branch: str = "circulation", sign: float = 1.0
) -> StationaryEllipse:
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
    validation.string("branch", branch, choices=BRANCHES)
    if not (lam > 0 and mu > 0) or lam == mu:
        raise ValueError(f"lambda, mu: need λ, μ > 0 and λ ≠ μ, got {lam}, {mu}")
    J = body.inertia.J1
    rho = equilibrium_thickness(body, lam, mu)
    h = stencil_step(lam, mu, rho)
    if not h < min(lam, mu, rho):  # the stencil's points must stay in λ, μ, ϱ > 0 (a far too elongated shape)
        raise ValueError(
            f"lambda, mu: no stationary ellipse can be computed for the shape ({lam:g}, {mu:g}): the smallest of "
            f"lambda, mu, rho = {rho:g} must exceed the difference step {h:g} (1e-5 x the largest)"
        )
    out = np.empty(6)
    if not stationary_shape_kernel(
        J, body.inertia.J3, lam, mu, rho, potential_stencil(body, lam, mu, rho), branch == "rotation", float(sign), out
    ):
        raise ValueError(
            f"lambda, mu: no stationary ellipse with shape ({lam:g}, {mu:g}) for this potential "
            f"(needs dV/du >= 0 and (lambda-mu) dV/dv >= 0)"
        )
    s3, pt, omega3, theta_dot, q, hmin = out.tolist()
    J3 = body.inertia.J3
    y = np.array([0.0, 0.0, s3, pt, 0.0, 0.0, 0.0, lam, mu, rho, 0.0])
    # H (eq. (41)) and the residual of eqs. (43)–(49) from the scalar kernels that hamiltonian() and rhs() run
    v, gl, gm, gr = body.potential_terms(lam, mu, rho)
    conv = float(body.kernel_params()[8])
    dy = rhs_iso(0.0, 0.0, s3, pt, 0.0, 0.0, 0.0, lam, mu, rho, 0.0, 0.0, 0.0, 0.0, J, J3, conv, gl, gm, gr)
    energy = kinetic_iso(0.0, 0.0, s3, pt, 0.0, 0.0, 0.0, lam, mu, rho, J, J3)[0] + v
    return StationaryEllipse(
        branch="N",
        state=unpack(y),
        omega=(0.0, 0.0, omega3),
        theta_dot=theta_dot,
        energy=energy,
        residual=max(abs(d) for d in dy[:10]),
        method="inverse",
        q=q,
        shape_hessian_min=hmin,
    )
