"""Kinetic energy, Legendre transform and Hamiltonian of the flat body (eqs. (28)–(32), (41) of [1]).

Velocities are ordered as in :data:`VELOCITY_NAMES` = (ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇). The
Lagrangian kinetic energy is the quadratic form

.. math:: T = \\tfrac12 \\operatorname{Tr}(J \\dot\\Phi^T \\dot\\Phi) = \\tfrac12 v^T M(\\lambda,\\mu,\\varrho,\\theta)\\, v

with the mass matrix :func:`mass_matrix` read off eq. (30) of [1] corrected by erratum E1 of
[2]: every ``(J1 − J2) sin 2θ`` of the printed eq. (30) and of its Legendre transform is
``(J1 − J2) sin θ cos θ``. For J1 = J2 = J it reduces to eq. (31).

In momenta, the isotropic kinetic energy is eq. (32) of [1], written cancellation-free
(docs/physics.md §4) with σ± = s3 ± p_θ, u = λ + μ, v = λ − μ, I1 = Jμ² + J3ϱ², I2 = Jλ² + J3ϱ²:

.. math:: \\mathcal T = \\frac{s_1^2}{2I_1} + \\frac{s_2^2}{2I_2} + \\frac{\\sigma_+^2}{4Ju^2}
   + \\frac{\\sigma_-^2}{4Jv^2} + \\frac{p_\\lambda^2+p_\\mu^2}{2J} + \\frac{p_\\varrho^2}{2J_3}.

For J1 ≠ J2 the closed form of docs/physics.md §4 is used: with
K = [[J1c²+J2s², (J2−J1)sc], [(J2−J1)sc, J1s²+J2c²]],
N = [[K22μ²+J3ϱ², −K12λμ], [−K12λμ, K11λ²+J3ϱ²]], P_a = ½(σ₊/u + σ₋/v), P_b = ½(σ₊/u − σ₋/v),

.. math:: \\mathcal T = \\tfrac12 (s_1,s_2) N^{-1} (s_1,s_2)^T + \\tfrac12 (p_\\lambda, P_b) K^{-1}
   (p_\\lambda, P_b)^T + \\tfrac12 (P_a, -p_\\mu) K^{-1} (P_a, -p_\\mu)^T + \\frac{p_\\varrho^2}{2J_3}.

:func:`kinetic_kernel` returns 𝒯, the velocities ∂𝒯/∂(s, p) and the forces −∂𝒯/∂q in one
pass of plain float arithmetic (no numpy), so compiled integrators can use it as is.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.state import LAMBDA, MU, RHO, STATE_SIZE, pack

VELOCITY_NAMES: tuple[str, ...] = ("omega1", "omega2", "omega3", "theta_dot", "lambda_dot", "mu_dot", "rho_dot")
"""Generalised velocities, conjugate in order to (s1, s2, s3, p_θ, p_λ, p_μ, p_ϱ)."""


def kinetic_iso(s1, s2, s3, pt, pl, pm, pr, lam, mu, rho, J, J3):
    """:func:`kinetic_kernel` for J1 = J2 = J on scalars, returning a tuple (the form a compiled loop
    over N bodies inlines and vectorises; :func:`kinetic_kernel` calls it).

    Returns
    -------
    (𝒯, ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇, −∂𝒯/∂λ, −∂𝒯/∂μ, −∂𝒯/∂ϱ) — eq. (32) of [1], cancellation-free
    (docs/physics.md §4); −∂𝒯/∂θ = 0 (θ is cyclic).
    """
    u = lam + mu
    v = lam - mu
    iu = 1.0 / u
    iv = 1.0 / v
    sp = s3 + pt
    sm = s3 - pt
    j3r2 = J3 * rho * rho
    I1 = J * mu * mu + j3r2
    I2 = J * lam * lam + j3r2
    w1 = s1 / I1
    w2 = s2 / I2
    iJ = 1.0 / J  # body constants: a loop over bodies computes them once
    iJ3 = 1.0 / J3
    A = 0.5 * sp * iu * iu * iJ
    B = 0.5 * sm * iv * iv * iJ
    cp = 0.5 * sp * sp * iu * iu * iu * iJ
    cm = 0.5 * sm * sm * iv * iv * iv * iJ
    T = (
        0.5 * (s1 * w1 + s2 * w2)
        + 0.5 * sp * sp * iu * iu / (2.0 * J)
        + 0.5 * sm * sm * iv * iv / (2.0 * J)
        + 0.5 * (pl * pl + pm * pm) / J
        + 0.5 * pr * pr / J3
    )
    return (
        T,
        w1,
        w2,
        A + B,  # ω3, eq. after (31) of [1] / docs/physics.md §4
        A - B,  # θ̇
        pl * iJ,
        pm * iJ,
        pr * iJ3,
        J * lam * w2 * w2 + cp + cm,  # eq. (47) of [1], cancellation-free (docs/physics.md §4)
        J * mu * w1 * w1 + cp - cm,  # eq. (48)
        J3 * rho * (w1 * w1 + w2 * w2),  # eq. (49)
    )


def kinetic_kernel(y, P, vel, force):
    """Kinetic energy in momenta, its momentum gradient and its configuration gradient.

    Parameters
    ----------
    y : array of shape (11,)
        Packed state (layout in :mod:`flatbody_env.physics.state`).
    P : array of shape (9,)
        Kernel parameters (layout in :mod:`flatbody_env.physics.body`); only J1, J2, J3 are read.
    vel : array of shape (7,), output
        (ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇) = ∂𝒯/∂(s1, s2, s3, p_θ, p_λ, p_μ, p_ϱ).
    force : array of shape (4,), output
        (−∂𝒯/∂θ, −∂𝒯/∂λ, −∂𝒯/∂μ, −∂𝒯/∂ϱ).

    Returns
    -------
    float
        𝒯 (eq. (32) of [1]; for J1 ≠ J2 the closed form of docs/physics.md §4).
    """
    J1 = P[0]
    J2 = P[1]
    J3 = P[2]
    s1 = y[0]
    s2 = y[1]
    s3 = y[2]
    pt = y[3]
    pl = y[4]
    pm = y[5]
    pr = y[6]
    lam = y[7]
    mu = y[8]
    rho = y[9]
    if J1 == J2:
        T, w1, w2, w3, thd, ld, md, rd, f1, f2, f3 = kinetic_iso(s1, s2, s3, pt, pl, pm, pr, lam, mu, rho, J1, J3)
        f0 = 0.0  # θ is cyclic: ṗ_θ = 0 (eq. (46) of [1])
    else:
        T, w1, w2, w3, thd, ld, md, rd, f0, f1, f2, f3 = kinetic_general(
            s1, s2, s3, pt, pl, pm, pr, lam, mu, rho, y[10], J1, J2, J3
        )
    store_kinetic(vel, force, w1, w2, w3, thd, ld, md, rd, f0, f1, f2, f3)
    return T


def store_kinetic(vel, force, w1, w2, w3, thd, ld, md, rd, f0, f1, f2, f3):
    """Write the velocities (ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇) into ``vel`` (7,) and the kinetic forces (−∂𝒯/∂θ, −∂𝒯/∂λ,
    −∂𝒯/∂μ, −∂𝒯/∂ϱ) into ``force`` (4,) (:func:`kinetic_kernel`'s outputs)."""
    vel[0] = w1
    vel[1] = w2
    vel[2] = w3
    vel[3] = thd
    vel[4] = ld
    vel[5] = md
    vel[6] = rd
    force[0] = f0
    force[1] = f1
    force[2] = f2
    force[3] = f3


def kinetic_general(s1, s2, s3, pt, pl, pm, pr, lam, mu, rho, th, J1, J2, J3):
    """:func:`kinetic_kernel` for any J1, J2 (the closed form of docs/physics.md §4) on scalars, returning a tuple
    (a call without arrays: no reference counting).

    Returns
    -------
    (𝒯, ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇, −∂𝒯/∂θ, −∂𝒯/∂λ, −∂𝒯/∂μ, −∂𝒯/∂ϱ)
        𝒯 of eq. (32) of [1] (with erratum E1 of docs/physics.md for J1 ≠ J2), its momentum gradient (the velocities)
        and minus its configuration gradient (the kinetic forces of eqs. (46)–(49)).
    """
    u = lam + mu
    v = lam - mu
    iu = 1.0 / u
    iv = 1.0 / v
    sp = s3 + pt
    sm = s3 - pt
    j3r2 = J3 * rho * rho
    c = math.cos(th)
    s = math.sin(th)
    s2t = 2.0 * s * c
    c2t = c * c - s * s
    K11 = J1 * c * c + J2 * s * s
    K22 = J1 * s * s + J2 * c * c
    K12 = (J2 - J1) * s * c
    iJ1 = 1.0 / J1
    iJ2 = 1.0 / J2
    Ki11 = c * c * iJ1 + s * s * iJ2
    Ki22 = s * s * iJ1 + c * c * iJ2
    Ki12 = (iJ2 - iJ1) * s * c
    N11 = K22 * mu * mu + j3r2
    N22 = K11 * lam * lam + j3r2
    N12 = -K12 * lam * mu
    detN = N11 * N22 - N12 * N12
    w1 = (N22 * s1 - N12 * s2) / detN
    w2 = (N11 * s2 - N12 * s1) / detN
    Pa = 0.5 * (sp * iu + sm * iv)
    Pb = 0.5 * (sp * iu - sm * iv)
    al1 = Ki11 * pl + Ki12 * Pb
    al2 = Ki12 * pl + Ki22 * Pb
    be1 = Ki11 * Pa - Ki12 * pm
    be2 = Ki12 * Pa - Ki22 * pm
    w3 = 0.5 * (al2 * (iu - iv) + be1 * (iu + iv))
    thd = 0.5 * (al2 * (iu + iv) + be1 * (iu - iv))
    rd = pr / J3
    # derivatives of P_a, P_b with respect to λ and μ
    du = sp * iu * iu
    dv = sm * iv * iv
    dPa_dl = -0.5 * (du + dv)
    dPa_dm = -0.5 * (du - dv)
    dPb_dl = -0.5 * (du - dv)
    dPb_dm = -0.5 * (du + dv)
    dT_dl = -0.5 * (2.0 * w1 * w2 * (-K12 * mu) + w2 * w2 * 2.0 * K11 * lam) + al2 * dPb_dl + be1 * dPa_dl
    dT_dm = -0.5 * (w1 * w1 * 2.0 * K22 * mu + 2.0 * w1 * w2 * (-K12 * lam)) + al2 * dPb_dm + be1 * dPa_dm
    dT_dr = -J3 * rho * (w1 * w1 + w2 * w2)
    dK11 = (J2 - J1) * s2t
    dK22 = (J1 - J2) * s2t
    dK12 = (J2 - J1) * c2t
    dKi11 = (iJ2 - iJ1) * s2t
    dKi22 = (iJ1 - iJ2) * s2t
    dKi12 = (iJ2 - iJ1) * c2t
    dT_dth = -0.5 * (w1 * w1 * dK22 * mu * mu - 2.0 * w1 * w2 * dK12 * lam * mu + w2 * w2 * dK11 * lam * lam) + 0.5 * (
        dKi11 * (pl * pl + Pa * Pa) + 2.0 * dKi12 * (pl * Pb - Pa * pm) + dKi22 * (Pb * Pb + pm * pm)
    )
    T = 0.5 * (s1 * w1 + s2 * w2) + 0.5 * (pl * al1 + Pb * al2) + 0.5 * (Pa * be1 - pm * be2) + 0.5 * pr * pr / J3
    return T, w1, w2, w3, thd, al1, -be2, rd, -dT_dth, -dT_dl, -dT_dm, -dT_dr


def mass_matrix(lam: float, mu: float, rho: float, theta: float, inertia: Inertia) -> np.ndarray:
    """Mass matrix M of T = ½ vᵀ M v, v = (ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇), shape (7, 7).

    Read off eq. (30) of [1] with erratum E1 of [2] (``(J1−J2) sin θ cos θ`` for the printed
    ``(J1−J2) sin 2θ``). With A = J1c² + J2s², B = J1s² + J2c², E = (J1 − J2) sc:

    .. math::
        T = \\tfrac A2\\dot\\lambda^2 + \\tfrac B2\\dot\\mu^2 + \\tfrac{J_3}2\\dot\\varrho^2
        + \\tfrac{B\\mu^2+J_3\\varrho^2}{2}\\omega_1^2 + \\tfrac{A\\lambda^2+J_3\\varrho^2}{2}\\omega_2^2
        + (J_1+J_2)\\lambda\\mu\\,\\omega_3\\dot\\theta
        + E[(\\mu\\dot\\mu-\\lambda\\dot\\lambda)\\dot\\theta + (\\lambda\\dot\\mu-\\mu\\dot\\lambda)\\omega_3
        + \\lambda\\mu\\,\\omega_1\\omega_2]
        + \\tfrac{A\\lambda^2+B\\mu^2}{2}\\omega_3^2 + \\tfrac{B\\lambda^2+A\\mu^2}{2}\\dot\\theta^2
    """
    J1, J2, J3 = inertia.J1, inertia.J2, inertia.J3
    c, s = math.cos(theta), math.sin(theta)
    A = J1 * c * c + J2 * s * s
    B = J1 * s * s + J2 * c * c
    E = (J1 - J2) * s * c
    M = np.zeros((7, 7))
    M[0, 0] = B * mu * mu + J3 * rho * rho
    M[1, 1] = A * lam * lam + J3 * rho * rho
    M[0, 1] = M[1, 0] = E * lam * mu
    M[2, 2] = A * lam * lam + B * mu * mu
    M[3, 3] = B * lam * lam + A * mu * mu
    M[2, 3] = M[3, 2] = (J1 + J2) * lam * mu
    M[2, 4] = M[4, 2] = -E * mu
    M[2, 5] = M[5, 2] = E * lam
    M[3, 4] = M[4, 3] = -E * lam
    M[3, 5] = M[5, 3] = E * mu
    M[4, 4] = A
    M[5, 5] = B
    M[6, 6] = J3
    return M


def momenta_from_velocities(
    velocities: Mapping[str, float], *, lam: float, mu: float, rho: float, theta: float, inertia: Inertia
) -> dict[str, float]:
    """Legendre transform v → p = M v (eq. (30) of [1] corrected by E1; eq. (31) when J1 = J2).

    Parameters
    ----------
    velocities : mapping
        The seven names of :data:`VELOCITY_NAMES`.

    Returns
    -------
    dict
        ``s1, s2, s3, p_theta, p_lambda, p_mu, p_rho``.
    """
    v = np.array([float(velocities[name]) for name in VELOCITY_NAMES])
    p = mass_matrix(lam, mu, rho, theta, inertia) @ v
    return dict(zip(("s1", "s2", "s3", "p_theta", "p_lambda", "p_mu", "p_rho"), map(float, p)))


def velocities_from_momenta(state: Mapping[str, float] | np.ndarray, body: Body) -> dict[str, float]:
    """Inverse Legendre transform p → v = ∂𝒯/∂p (inverse of eq. (31) of [1]; docs/physics.md §4 for J1 ≠ J2)."""
    y = _as_array(state)
    vel = np.empty(7)
    force = np.empty(4)
    kinetic_kernel(y, body.kernel_params(), vel, force)
    return dict(zip(VELOCITY_NAMES, map(float, vel)))


def kinetic_energy(state: Mapping[str, float] | np.ndarray, body: Body) -> float:
    """𝒯 in canonical variables (eq. (32) of [1])."""
    y = _as_array(state)
    return float(kinetic_kernel(y, body.kernel_params(), np.empty(7), np.empty(4)))


def hamiltonian(state: Mapping[str, float] | np.ndarray, body: Body) -> float:
    """H = 𝒯 + V_λμ + V_ϱ (eq. (41) of [1])."""
    y = _as_array(state)
    return kinetic_energy(y, body) + body.potential_terms(y[LAMBDA], y[MU], y[RHO])[0]


def hamiltonian_series(Y: np.ndarray, body: Body) -> np.ndarray:
    """H along a packed trajectory ``Y`` of shape (11, n).

    An isotropic body (J1 = J2) with a built-in potential is evaluated on whole columns with
    :func:`kinetic_iso` and :func:`~flatbody_env.physics.potentials.potential_kernel`, the same
    float operations as :func:`hamiltonian` (so the same values, bit for bit); other bodies, and
    columns where that gives a non-finite H, step by step.
    """
    Y = np.asarray(Y, dtype=np.float64)
    P = body.kernel_params()
    if P[0] == P[1] and body.compiled and Y.ndim == 2 and Y.shape[0] == STATE_SIZE:
        from flatbody_env.physics.potentials import potential_kernel

        J, J3 = float(P[0]), float(P[2])
        with np.errstate(all="ignore"):
            T = kinetic_iso(*(Y[i] for i in range(10)), J, J3)[0]
            V = potential_kernel(
                int(P[3]), float(P[4]), float(P[5]), float(P[6]), float(P[7]), Y[LAMBDA], Y[MU], Y[RHO]
            )[0]
            out = np.asarray(T + V, dtype=np.float64)
        if out.shape == (Y.shape[1],) and np.all(np.isfinite(out)):
            return out
    vel = np.empty(7)
    force = np.empty(4)
    out = np.empty(Y.shape[1])
    for k in range(Y.shape[1]):
        y = Y[:, k]
        out[k] = kinetic_kernel(y, P, vel, force) + body.potential_terms(y[LAMBDA], y[MU], y[RHO])[0]
    return out


def _as_array(state) -> np.ndarray:
    if isinstance(state, Mapping):
        return pack(state, validate=False)
    y = np.asarray(state, dtype=np.float64)
    if y.shape != (STATE_SIZE,):
        raise ValueError(f"state array: expected shape ({STATE_SIZE},), got {y.shape}")
    return y


__all__ = [
    "VELOCITY_NAMES",
    "kinetic_kernel",
    "mass_matrix",
    "momenta_from_velocities",
    "velocities_from_momenta",
    "kinetic_energy",
    "hamiltonian",
    "hamiltonian_series",
]
