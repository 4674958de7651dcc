"""The regular (matrix) formulation of the same body: chart-free, valid through λ = μ (docs/physics.md §7).

The configuration is Φ = [φ1, φ2, ψ] (columns) with the two Kirchhoff–Love constraints
(eqs. (20)–(22) of [1]) written exactly as

.. math:: g_1 = \\psi\\cdot\\varphi_1 = 0, \\qquad g_2 = \\psi\\cdot\\varphi_2 = 0 .

The Lagrangian has a constant mass matrix (eq. (28) of [1] with J = diag(J1, J2, J3))

.. math:: L = \\tfrac12 J_1|\\dot\\varphi_1|^2 + \\tfrac12 J_2|\\dot\\varphi_2|^2
   + \\tfrac12 J_3|\\dot\\psi|^2 - V,

and V is a function of the invariants tr = |φ1|² + |φ2|² = λ² + μ², det = |φ1 × φ2|² = λ²μ²,
ϱ = |ψ| (docs/physics.md §7). The equations of motion are

.. math:: J_1\\ddot\\varphi_1 = F_1 + \\Lambda_1\\psi, \\quad J_2\\ddot\\varphi_2 = F_2 + \\Lambda_2\\psi,
   \\quad J_3\\ddot\\psi = F_\\psi + \\Lambda_1\\varphi_1 + \\Lambda_2\\varphi_2,

with F = −∂V/∂Φ plus the control force, and Λ from g̈ = 0 (index reduction; a 2×2 system
that is positive definite while ϱ > 0).

Regular state layout (packed, shape (18,))

=========  ===========  ==========================================
indices    name         meaning
=========  ===========  ==========================================
0–2        ``phi1``     first column of Φ (laboratory frame)
3–5        ``phi2``     second column of Φ
6–8        ``psi``      third column of Φ (thickness direction, |ψ| = ϱ)
9–11       ``phi1_dot`` dφ1/dt
12–14      ``phi2_dot`` dφ2/dt
15–17      ``psi_dot``  dψ/dt
=========  ===========  ==========================================

Conversions to and from the paper's state are exact (round trip ~1e-15): Φ = R D U⁻¹ and
Φ̇ = R(Ḋ + W D − D ϑ)U⁻¹ (eqs. (23), (27) of [1]); back by the thin SVD of [φ1, φ2]
(:func:`flatbody_env.physics.kinematics.decompose`) and M = RᵀΦ̇U (docs/physics.md §7). Only the way back is
singular at λ = μ, where the paper's chart itself is.

Controls. The paper's co-moving torque τ on s and force f on ϱ are generalised forces of the
two-polar chart (no work on θ, λ, μ). In Φ-space they are the force F_u = R G U⁻¹ with
G₁₂ = τ₁/ϱ, G₀₂ = −τ₂/ϱ, G₀₁ = τ₃ μ/(μ² − λ²), G₁₀ = τ₃ λ/(μ² − λ²), G₂₂ = f — exact, and
singular for τ₃ at λ = μ, where a rotation about e₃ and a change of θ coincide.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]), §5.
"""

from __future__ import annotations

import math

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.hamiltonian import mass_matrix, velocities_from_momenta
from flatbody_env.physics.kinematics import (
    Decomposition,
    column_dot,
    configuration,
    configuration_rate,
    decompose,
    material_rotation,
    stretches_kernel,
)
from flatbody_env.physics.potentials import invariant_gradient_kernel, potential_kernel

REGULAR_SIZE = 18


def regular_from_paper(y: np.ndarray, body: Body, R: np.ndarray | None = None) -> np.ndarray:
    """Paper state (11,) (+ orientation R, default identity) → regular state (18,)."""
    y = np.asarray(y, float)
    lam, mu, rho, theta = y[7], y[8], y[9], y[10]
    vel = velocities_from_momenta(y, body)
    R = np.eye(3) if R is None else np.asarray(R, float)
    Phi = configuration(lam, mu, rho, theta, R)
    Phi_dot = configuration_rate(lam, mu, rho, theta, vel, R)
    return np.concatenate([Phi.T.ravel(), Phi_dot.T.ravel()])


def matrices(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Regular state → (Φ, Φ̇), each (3, 3) with columns (φ1, φ2, ψ)."""
    z = np.asarray(z, float)
    return z[:9].reshape(3, 3).T, z[9:].reshape(3, 3).T


def paper_from_regular(
    z: np.ndarray,
    body: Body,
    reference: Decomposition | None = None,
    *,
    kl_tol: float = 1e-9,
    keep_order: bool = False,
    decomposition: Decomposition | None = None,
) -> tuple[np.ndarray, Decomposition]:
    """Regular state (18,) → (paper state (11,), decomposition with R).

    ``reference`` (the previous decomposition along a trajectory) fixes the discrete
    ambiguities of the two-polar chart by continuity (docs/physics.md §7); ``kl_tol`` and
    ``keep_order`` are passed to :func:`~flatbody_env.physics.kinematics.decompose`. A ready
    ``decomposition`` of Φ (e.g. from :func:`follow_chart`) skips that step.

    Raises
    ------
    ValueError
        At λ = μ exactly (the chart's ω3 ± θ̇ split is undefined there) or for a Φ outside
        the constrained set.
    """
    Phi, Phi_dot = matrices(z)
    dec = (
        decomposition if decomposition is not None else decompose(Phi, reference, kl_tol=kl_tol, keep_order=keep_order)
    )
    lam, mu, rho, theta = dec.lam, dec.mu, dec.rho, dec.theta
    if lam == mu:
        raise ValueError("lambda: equals mu — the two-polar chart is singular at λ = μ")
    U = material_rotation(theta)
    M = dec.R.T @ Phi_dot @ U
    a = -M[1, 0]
    b = M[0, 1]
    vel = np.array(
        [
            M[1, 2] / rho,  # ω1
            -M[0, 2] / rho,  # ω2
            0.5 * ((a + b) / (lam + mu) + (a - b) / (lam - mu)),  # ω3
            0.5 * ((a + b) / (lam + mu) - (a - b) / (lam - mu)),  # θ̇
            M[0, 0],
            M[1, 1],
            M[2, 2],
        ]
    )
    p = mass_matrix(lam, mu, rho, theta, body.inertia) @ vel
    y = np.array([p[0], p[1], p[2], p[3], p[4], p[5], p[6], lam, mu, rho, theta])
    return y, dec


MAX_CHART_JUMP = 0.5
"""Largest change of θ (rad) and of R (Frobenius) accepted between two samples by :func:`follow_chart`."""


def follow_chart(
    sample, ta: float, tb: float, ref: Decomposition, *, keep_order: bool, max_depth: int = 60
) -> Decomposition:
    """Decomposition at ``tb`` that continues ``ref`` (at ``ta``) along a smooth Φ(t).

    Near λ = μ the chart's R and θ turn by about ±π/2 within a very short time while Φ(t)
    stays smooth (docs/physics.md §7), so one sample per step of a regular-chart integrator can leave
    the branch ambiguous. This bisects [ta, tb] (``sample(t)`` returns the regular state,
    e.g. a dense output) until consecutive decompositions differ by less than
    :data:`MAX_CHART_JUMP`.

    Raises
    ------
    ValueError
        If ``max_depth`` bisections do not resolve the branch.
    """
    Phi = matrices(sample(tb))[0]
    dec = decompose(Phi, ref, kl_tol=np.inf, keep_order=keep_order)
    jump = abs(dec.theta - ref.theta) + float(np.linalg.norm(dec.R - ref.R))
    if jump <= MAX_CHART_JUMP:
        return dec
    if max_depth == 0:
        raise ValueError(f"the chart's frame turns too fast to follow between t = {ta:.17g} and {tb:.17g} (λ ≈ μ)")
    tm = 0.5 * (ta + tb)
    mid = follow_chart(sample, ta, tm, ref, keep_order=keep_order, max_depth=max_depth - 1)
    return follow_chart(sample, tm, tb, mid, keep_order=keep_order, max_depth=max_depth - 1)


def _in_plane_gradient(phi1, phi2, rho, body: Body, lambda_is_larger: bool):
    """(V, ∂V/∂φ1, ∂V/∂φ2, ∂V/∂ϱ) of the in-plane + thickness potential."""
    n11 = phi1 @ phi1
    n22 = phi2 @ phi2
    n12 = phi1 @ phi2
    tr = n11 + n22
    det = n11 * n22 - n12 * n12
    inv = body.potential.invariant_gradient(tr, det)
    if inv is not None:
        v_tr, v_det = inv
        g1 = 2.0 * v_tr * phi1 + v_det * 2.0 * (n22 * phi1 - n12 * phi2)
        g2 = 2.0 * v_tr * phi2 + v_det * 2.0 * (n11 * phi2 - n12 * phi1)
        disc = np.sqrt(max(0.25 * tr * tr - det, 0.0))
        lam = np.sqrt(0.5 * tr + disc)
        mu = np.sqrt(max(0.5 * tr - disc, 0.0))
        v, _, _, gr = body.potential_terms(lam, max(mu, 1e-300), rho)
        return v, g1, g2, gr
    W, sig, Vt = np.linalg.svd(np.column_stack([phi1, phi2]), full_matrices=False)
    big, small = (0, 1) if lambda_is_larger else (1, 0)
    lam, mu = sig[big], sig[small]
    v, gl, gm, gr = body.potential_terms(lam, mu, rho)
    # ∂σ_i/∂φ = w_i v_iᵀ
    dphi = gl * np.outer(W[:, big], Vt[big]) + gm * np.outer(W[:, small], Vt[small])
    return v, dphi[:, 0], dphi[:, 1], gr


class FrameTracker:
    """Follows the two-polar frame (R, θ and the λ/μ labels) along a regular trajectory.

    The co-moving frame of the chart is defined only up to the discrete symmetries of
    :func:`~flatbody_env.physics.kinematics.decompose` (a half turn flips τ1, τ2); controls given in
    that frame need the branch chosen by continuity from the start of the step.
    """

    def __init__(self, reference: Decomposition | None = None) -> None:
        self.last = reference

    def __call__(self, Phi: np.ndarray) -> Decomposition:
        self.last = decompose(Phi, self.last, kl_tol=np.inf)
        return self.last


def control_force(Phi: np.ndarray, u: np.ndarray, frame: FrameTracker | None = None) -> np.ndarray:
    """Φ-space force F_u = R G U⁻¹ equivalent to the chart's (τ1, τ2, τ3, f_ϱ) (module docstring).

    ``frame`` tracks the chart's co-moving frame by continuity; without it the frame of
    :func:`~flatbody_env.physics.kinematics.decompose` without reference is used.
    """
    dec = frame(Phi) if frame is not None else decompose(Phi, kl_tol=np.inf)
    lam, mu, rho = dec.lam, dec.mu, dec.rho
    G = np.zeros((3, 3))
    G[1, 2] = u[0] / rho
    G[0, 2] = -u[1] / rho
    if u[2] != 0.0:
        G[0, 1] = u[2] * mu / (mu * mu - lam * lam)
        G[1, 0] = u[2] * lam / (mu * mu - lam * lam)
    G[2, 2] = u[3]
    return dec.R @ G @ material_rotation(dec.theta).T


def regular_rhs(
    t: float,
    z: np.ndarray,
    u: np.ndarray | None,
    params: Body,
    lambda_is_larger: bool = True,
    frame: FrameTracker | None = None,
) -> np.ndarray:
    """dz/dt of the regular state (module docstring), shape (18,).

    Parameters
    ----------
    t : float
        Time (autonomous system).
    z : ndarray, shape (18,)
        Regular state.
    u : ndarray, shape (4,) or None
        Controls (τ1, τ2, τ3, f_ϱ) of the two-polar chart, constant over the step.
    params : Body
        Inertia and potential (the spin convention is a property of the chart and is ignored:
        this formulation is the corrected one by construction).
    lambda_is_larger : bool
        For potentials that are not symmetric in λ ↔ μ (V2 with c ≠ d, custom): whether the
        paper's λ is the larger singular value.
    frame : FrameTracker, optional
        Follows the chart's co-moving frame in which the controls are given (needed for
        τ1, τ2 whenever u is non-zero).
    """
    J1, J2, J3 = params.inertia.J1, params.inertia.J2, params.inertia.J3
    phi1, phi2, psi = z[0:3], z[3:6], z[6:9]
    d1, d2, dpsi = z[9:12], z[12:15], z[15:18]
    rho = float(np.sqrt(psi @ psi))
    _, g1, g2, gr = _in_plane_gradient(phi1, phi2, rho, params, lambda_is_larger)
    F1 = -g1
    F2 = -g2
    Fp = -gr * psi / rho
    if u is not None and np.any(u):
        Fu = control_force(np.column_stack([phi1, phi2, psi]), np.asarray(u, float), frame)
        F1 = F1 + Fu[:, 0]
        F2 = F2 + Fu[:, 1]
        Fp = Fp + Fu[:, 2]
    pp = psi @ psi
    a11 = pp / J1 + (phi1 @ phi1) / J3
    a22 = pp / J2 + (phi2 @ phi2) / J3
    a12 = (phi1 @ phi2) / J3
    r1 = -(psi @ F1 / J1 + phi1 @ Fp / J3 + 2.0 * (dpsi @ d1))
    r2 = -(psi @ F2 / J2 + phi2 @ Fp / J3 + 2.0 * (dpsi @ d2))
    det = a11 * a22 - a12 * a12
    L1 = (a22 * r1 - a12 * r2) / det
    L2 = (a11 * r2 - a12 * r1) / det
    out = np.empty(18)
    out[0:9] = z[9:18]
    out[9:12] = (F1 + L1 * psi) / J1
    out[12:15] = (F2 + L2 * psi) / J2
    out[15:18] = (Fp + L1 * phi1 + L2 * phi2) / J3
    return out


# --------------------------------------------------------------------------------------------- kernels
# Plain-float kernels on q = (φ1, φ2, ψ) (9,) or z (18,) with the kernel parameters P (9,) (layout in
# :mod:`flatbody_env.physics.body`), for built-in potentials that are functions of the invariants (V1,
# V2 with c = d, V3): the compiled integrators compile this code (:func:`flatbody_env.integrators.jit.retarget`).


def regular_forces_kernel(q, P, f_rho, F):
    """F = −∂V/∂q plus the dilatation force f_ϱ along ψ, at q (9,), into F (9,) (plain-float kernel).

    With V a function of tr = |φ1|² + |φ2|², det = |φ1|²|φ2|² − (φ1·φ2)² and ϱ = |ψ| (docs/physics.md §7;
    V_λμ of eqs. (37)–(39), V_ϱ of eq. (40) of [1])

    .. math::
        F_{\\varphi_1} = -2V_{tr}\\varphi_1 - 2V_{det}(|\\varphi_2|^2\\varphi_1 - (\\varphi_1\\cdot\\varphi_2)\\varphi_2),
        \\quad F_\\psi = (f_\\varrho - V_\\varrho'(\\varrho))\\,\\psi/\\varrho,

    and F_φ2 symmetrically; (V_tr, V_det) from
    :func:`~flatbody_env.physics.potentials.invariant_gradient_kernel`, V_ϱ′ from
    :func:`~flatbody_env.physics.potentials.potential_kernel`.

    Parameters
    ----------
    q : array of shape (9,)
        (φ1, φ2, ψ), the columns of Φ (a regular state's first 9 entries).
    P : array of shape (9,)
        Kernel parameters; the potential's kind and c1 (P[3], P[4]) and a, b (P[6], P[7]) are read.
    f_rho : float
        The dilatation force f_ϱ.
    F : array of shape (9,), output
        The force on (φ1, φ2, ψ).

    Returns
    -------
    float
        det (> 0 inside the domain λμ > 0).
    """
    n11 = column_dot(q, 0, 0)
    n22 = column_dot(q, 3, 3)
    n12 = column_dot(q, 0, 3)
    tr = n11 + n22
    det = n11 * n22 - n12 * n12
    vt, vd = invariant_gradient_kernel(P[3], P[4], tr, det)
    rho = math.sqrt(column_dot(q, 6, 6))
    v, gl, gm, gr = potential_kernel(0.0, 0.0, 0.0, P[6], P[7], 1.0, 1.0, rho)
    for i in range(3):
        F[i] = -2.0 * vt * q[i] - 2.0 * vd * (n22 * q[i] - n12 * q[3 + i])
        F[3 + i] = -2.0 * vt * q[3 + i] - 2.0 * vd * (n11 * q[3 + i] - n12 * q[i])
        F[6 + i] = (f_rho - gr) * q[6 + i] / rho
    return det


def regular_energy_kernel(z, P):
    """H = ½ Σ J_A |Φ̇_A|² + V of z (18,) (docs/physics.md §7; eq. (41) of [1]), plain-float kernel."""
    T = 0.5 * (P[0] * column_dot(z, 9, 9) + P[1] * column_dot(z, 12, 12) + P[2] * column_dot(z, 15, 15))
    lam, mu, rho = stretches_kernel(z)
    v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], lam, mu, rho)
    return T + v


def regular_energy(z: np.ndarray, body: Body, lambda_is_larger: bool = True) -> float:
    """H = ½ Σ J_A |Φ̇_A|² + V (docs/physics.md §7)."""
    J = (body.inertia.J1, body.inertia.J2, body.inertia.J3)
    T = 0.5 * sum(J[a] * float(z[9 + 3 * a : 12 + 3 * a] @ z[9 + 3 * a : 12 + 3 * a]) for a in range(3))
    psi = z[6:9]
    v, _, _, _ = _in_plane_gradient(z[0:3], z[3:6], float(np.sqrt(psi @ psi)), body, lambda_is_larger)
    return T + v


def constraint_residual(z: np.ndarray) -> np.ndarray:
    """(ψ·φ1, ψ·φ2, d/dt ψ·φ1, d/dt ψ·φ2): zero on the Kirchhoff–Love set (eq. (21) of [1])."""
    phi1, phi2, psi = z[0:3], z[3:6], z[6:9]
    d1, d2, dpsi = z[9:12], z[12:15], z[15:18]
    return np.array([psi @ phi1, psi @ phi2, dpsi @ phi1 + psi @ d1, dpsi @ phi2 + psi @ d2])
