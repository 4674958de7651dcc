"""Linear controllability of a target stationary ellipse: how fast the controls can settle it.

The task (:mod:`flatbody_env.env.task`) uses this to sample only targets that the controls can reach
within an episode. Physics layer: numpy/scipy only.

Linearisation
-------------
θ is cyclic for J1 = J2 and p_θ is conserved by every control (eq. (46) of [1]), so the
controlled state is x = (s1, s2, s3, p_λ, p_μ, p_ϱ, λ, μ, ϱ) ∈ ℝ⁹ (:data:`REDUCED_STATE`). A
stationary ellipse of branch N (eqs. (50)–(54), s1 = s2 = 0, p = 0) is an equilibrium of
eqs. (44)–(49) (spin bracket per erratum E3/E4 of [2]); linearising there (central differences of
:func:`flatbody_env.physics.equations.rhs`) gives ẋ ≈ A δx + B a, a = u / limits the normalised action.
At linear order the thickness force moves only (ϱ, p_ϱ), τ1, τ2 only (s1, s2), and the in-plane
shape (λ, μ, p_λ, p_μ) — two undamped oscillation modes — is reached *only through s3* (τ3 changes
s3, which enters the centrifugal forces −∂𝒯/∂(λ, μ) through σ± = s3 ± p_θ).

Settling rate
-------------
:func:`settling_rate` is r = −max Re eig(A − B K) for the cheap-control LQR gain K (Q = I,
R = 10⁻⁴ I): the decay rate of the slowest closed-loop mode. More gain does not raise it: as
R → 0 at fixed Q the slow pole converges to a finite limit (the mode is reached through s3 only
weakly), so r is how fast optimal linear feedback with equally weighted state errors can settle
that mode, however cheap the control. Other state weightings move the limit somewhat (placing the
pole much further needs a design aimed at that one weakly controllable mode, with gains limited
in practice by the bounded torque — not measured here). Measured for the default body (limits
τ 0.5, f 1): r changes by < 0.1 % from R = 10⁻⁴ to 10⁻⁸; the LQR of ``agents``
(Q = diag(1, 1, 1, 10, …, 10), R = 0.1 I) settles at 1.01–1.2 r (0.0525 vs 0.0518 s⁻¹ at
λ* = 1.25, λ*/μ* = 1.3; 0.383 vs 0.312 at (1.6, 2.5)); r does not depend on the sign of
(s3, p_θ), and it grows steeply toward the edge of existence of the circulation family
(∂V/∂u → 0, λ*μ* → 1 for V3): 0.002 s⁻¹ at (λ*, λ*/μ*) = (1.6, 1.1), 0.05 at (1.25, 1.3),
0.23 at (1.4, 1.9), 0.31 at (1.6, 2.5) (:func:`settling_rate_map`).

Use as a reachability criterion: an error along the slowest mode shrinks like e^(−r t) under
such feedback, so from a distance d₀ the tolerance tol is reached within T only if
r·T ≥ ln(d₀/tol). Measured: the LQR controller's distance after 20 s correlates with r
(ρ = −0.82 over 30 episodes of the default task) and its residual error lies in the in-plane
shape and its momenta (λ, μ, s3, p_λ, p_μ), the slow mode.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flatbody_env.physics.body import Body

REDUCED_STATE = (0, 1, 2, 4, 5, 6, 7, 8, 9)
"""Indices of x = (s1, s2, s3, p_λ, p_μ, p_ϱ, λ, μ, ϱ) in the packed state (θ cyclic, p_θ conserved)."""

CHEAP_CONTROL_R = 1e-4
"""R = CHEAP_CONTROL_R · I (with Q = I) of the LQR that measures :func:`settling_rate`."""


def linearize(body: Body, y_star: np.ndarray, limits, h: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(A (9, 9), B (9, 4)) of eqs. (44)–(49) of [1] at y_star (11,) in the reduced state.

    Central differences of :func:`flatbody_env.physics.equations.rhs`; B's column j is the response to the
    control u_j = limits_j (a normalised action a_j = 1); limits has shape (4,) (τ1, τ2, τ3, f_ϱ).
    """
    from flatbody_env.physics.equations import rhs

    limits = np.asarray(limits, dtype=np.float64)
    idx = list(REDUCED_STATE)
    n = len(idx)
    A = np.zeros((n, n))
    B = np.zeros((n, 4))
    for j, i in enumerate(idx):
        e = np.zeros(11)
        e[i] = h
        A[:, j] = ((rhs(0.0, y_star + e, None, body) - rhs(0.0, y_star - e, None, body)) / (2 * h))[idx]
    for j in range(4):
        du = np.zeros(4)
        du[j] = h * limits[j]
        B[:, j] = ((rhs(0.0, y_star, du, body) - rhs(0.0, y_star, -du, body)) / (2 * h))[idx]
    return A, B


def target_state(lam: float, mu: float, rho: float, s3: float, p_theta: float) -> np.ndarray:
    """The packed state (11,) of a stationary ellipse (s1 = s2 = 0, p = 0, θ = 0)."""
    return np.array([0.0, 0.0, s3, p_theta, 0.0, 0.0, 0.0, lam, mu, rho, 0.0])


def settling_rate(body: Body, y_star: np.ndarray, limits, mask=None) -> float:
    """r = −max Re eig(A − B K) (s⁻¹) of the cheap-control LQR about y_star (module docstring).

    Parameters
    ----------
    body : Body
    y_star : array (11,)
        The target stationary ellipse as a packed state (:func:`target_state`).
    limits : array (4,)
        Control limits (τ1, τ2, τ3, f_ϱ).
    mask : bool array (4,), optional
        Which controls act (:func:`flatbody_env.env.task.control_mask`); default all.

    Returns
    -------
    float
        The slowest closed-loop decay rate; 0.0 when the controls cannot stabilise the target at
        linear order (e.g. without τ3 the in-plane shape is not controllable).
    """
    from scipy.linalg import solve_continuous_are

    A, B = linearize(body, y_star, limits)
    if mask is not None:
        B = B[:, np.asarray(mask, dtype=bool)]
    if B.shape[1] == 0:
        return 0.0
    R = CHEAP_CONTROL_R * np.eye(B.shape[1])
    try:
        P = solve_continuous_are(A, B, np.eye(A.shape[0]), R)
    except (np.linalg.LinAlgError, ValueError):
        return 0.0
    K = np.linalg.solve(R, B.T @ P)
    rate = -float(np.max(np.linalg.eigvals(A - B @ K).real))
    return rate if np.isfinite(rate) and rate > 0 else 0.0


@dataclass(frozen=True, kw_only=True)
class SettlingRateEntry:
    """One shape of :func:`settling_rate_map`: the target (λ*, λ*/μ*) and its settling rate."""

    lam: float
    aspect: float
    exists: bool
    """A stationary ellipse of the circulation family has this shape."""
    stable: bool
    rate: float
    """:func:`settling_rate` (s⁻¹); NaN where the ellipse does not exist or is unstable."""


def settling_rate_map(body: Body, lambdas, aspects, limits, mask=None, *, sign: float = 1.0) -> list[SettlingRateEntry]:
    """:func:`settling_rate` over a grid of target shapes λ* × λ*/μ* (circulation family).

    The measurement behind the task's reachability filter (:mod:`flatbody_env.env.task`); one
    :class:`SettlingRateEntry` per (λ*, aspect), λ* varying fastest within each aspect.
    """
    from flatbody_env.physics.equilibria import stationary_from_shape

    out = []
    for aspect in aspects:
        for lam in lambdas:
            try:
                t = stationary_from_shape(body, float(lam), float(lam) / float(aspect), branch="circulation", sign=sign)
            except ValueError:
                out.append(
                    SettlingRateEntry(lam=float(lam), aspect=float(aspect), exists=False, stable=False, rate=math.nan)
                )
                continue
            rate = (
                settling_rate(body, target_state(t.lam, t.mu, t.rho, t.s3, t.p_theta), limits, mask)
                if t.stable
                else math.nan
            )
            out.append(SettlingRateEntry(lam=float(lam), aspect=float(aspect), exists=True, stable=t.stable, rate=rate))
    return out
