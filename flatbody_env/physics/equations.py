"""Equations of motion of the flat body in the two-polar chart (eqs. (42)–(49) of [1]).

With ω = ∂H/∂s and the corrected Lie–Poisson bracket {s_i, s_j} = +ε_ijk s_k (erratum E3 of
[2]; it follows from eq. (25) and eq. (28) of [1]),

.. math::
    \\dot s = \\omega \\times s + \\tau, \\qquad
    \\dot q = \\partial H/\\partial p, \\qquad
    \\dot p = -\\partial H/\\partial q + f \\quad (q = \\theta, \\lambda, \\mu, \\varrho),

which for J1 = J2 are eqs. (44)–(49) of [1] with the overall sign of (44)–(46) reversed
(erratum E4) and ``ρ`` read as ``ϱ`` in (46) (E5). The option ``spin_convention="paper"`` of
:class:`~flatbody_env.physics.body.Body` integrates the printed eqs. (44)–(46), ṡ = s × ω, instead.

Controls enter as a co-moving torque τ = (τ1, τ2, τ3) on the spin and a generalised force
f on ϱ ("dilatation"), ``u = (τ1, τ2, τ3, f)``, held constant by the caller over a step.

Orientation (only when a scene needs it): Ṙ = R W(ω) with W(ω) of eq. (25) of [1], the
*negative* of the usual hat map (docs/physics.md §1).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import math

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.hamiltonian import kinetic_general, kinetic_iso, store_kinetic
from flatbody_env.physics.potentials import potential_kernel

CONTROL_NAMES: tuple[str, ...] = ("tau1", "tau2", "tau3", "f_rho")
"""Control inputs: co-moving torque on s (3) and generalised force on ϱ."""
NO_CONTROL = np.zeros(4)
NO_CONTROL.setflags(write=False)


def rhs_core(y, u, P, gl, gm, gr, out, vel, force):
    """Right-hand side given the potential gradient (scalar kernel, no numpy calls).

    Parameters
    ----------
    y : array (11,)
        Packed state.
    u : array (4,)
        Controls (τ1, τ2, τ3, f_ϱ).
    P : array (9,)
        Kernel parameters (:meth:`Body.kernel_params`).
    gl, gm, gr : float
        ∂V/∂λ, ∂V/∂μ, ∂V/∂ϱ.
    out : array (11,), output
        dy/dt.
    vel, force : arrays (7,), (4,)
        Work space; on return the velocities and kinetic forces of
        :func:`~flatbody_env.physics.hamiltonian.kinetic_kernel`.
    """
    if P[0] == P[1]:
        (d0, d1, d2, d3, d4, d5, d6, d7, d8, d9, d10, w1, w2, w3, thd, ld, md, rd, f1, f2, f3) = rhs_iso(
            y[0],
            y[1],
            y[2],
            y[3],
            y[4],
            y[5],
            y[6],
            y[7],
            y[8],
            y[9],
            u[0],
            u[1],
            u[2],
            u[3],
            P[0],
            P[2],
            P[8],
            gl,
            gm,
            gr,
        )
        f0 = 0.0  # θ is cyclic: ṗ_θ = 0 (eq. (46) of [1])
    else:
        _, w1, w2, w3, thd, ld, md, rd, f0, f1, f2, f3 = kinetic_general(
            y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7], y[8], y[9], y[10], P[0], P[1], P[2]
        )
        conv = P[8]
        s1 = y[0]
        s2 = y[1]
        s3 = y[2]
        # ṡ = ±ω × s (eqs. (44)–(46) of [1]; sign per erratum E3/E4 of docs/physics.md)
        d0 = conv * (w2 * s3 - w3 * s2) + u[0]
        d1 = conv * (w3 * s1 - w1 * s3) + u[1]
        d2 = conv * (w1 * s2 - w2 * s1) + u[2]
        d3 = f0  # ṗ_θ (eq. (46))
        d4 = f1 - gl  # eq. (47)
        d5 = f2 - gm  # eq. (48)
        d6 = f3 - gr + u[3]  # eq. (49) + dilatation force
        d7 = ld  # λ̇ = p_λ / J
        d8 = md  # μ̇ = p_μ / J
        d9 = rd  # ϱ̇ = p_ϱ / J3
        d10 = thd  # θ̇
    out[0] = d0
    out[1] = d1
    out[2] = d2
    out[3] = d3
    out[4] = d4
    out[5] = d5
    out[6] = d6
    out[7] = d7
    out[8] = d8
    out[9] = d9
    out[10] = d10
    store_kinetic(vel, force, w1, w2, w3, thd, ld, md, rd, f0, f1, f2, f3)


def rhs_iso(s1, s2, s3, pt, pl, pm, pr, lam, mu, rho, u0, u1, u2, u3, J, J3, conv, gl, gm, gr):
    """dy/dt for J1 = J2 = J on scalars (eqs. (44)–(49) of [1], bracket per errata E3/E4), the form
    a compiled loop over N bodies inlines and vectorises (:func:`rhs_core` calls it).

    Returns the eleven components of dy/dt, then (ω1, ω2, ω3, θ̇, λ̇, μ̇, ϱ̇) and
    (−∂𝒯/∂λ, −∂𝒯/∂μ, −∂𝒯/∂ϱ) of :func:`~flatbody_env.physics.hamiltonian.kinetic_iso`.
    """
    T, w1, w2, w3, thd, ld, md, rd, f1, f2, f3 = kinetic_iso(s1, s2, s3, pt, pl, pm, pr, lam, mu, rho, J, J3)
    j3r2 = J3 * rho * rho
    # ṡ = ±ω × s (eqs. (44)–(46) of [1]; sign per erratum E3/E4 of docs/physics.md);
    # ds3/dt = J(λ² − μ²) s1 s2 / (I1 I2), cancellation-free (docs/physics.md §4)
    d0 = conv * (w2 * s3 - w3 * s2) + u0
    d1 = conv * (w3 * s1 - w1 * s3) + u1
    d2 = conv * J * (lam - mu) * (lam + mu) * s1 * s2 / ((J * mu * mu + j3r2) * (J * lam * lam + j3r2)) + u2
    return (
        d0,
        d1,
        d2,
        0.0,
        f1 - gl,
        f2 - gm,
        f3 - gr + u3,
        ld,
        md,
        rd,
        thd,  # eqs. (46)–(49) + dilatation force; q̇ = ∂𝒯/∂p
        w1,
        w2,
        w3,
        thd,
        ld,
        md,
        rd,
        f1,
        f2,
        f3,
    )


def rhs_kernel(y, u, P, out, vel, force):
    """:func:`rhs_core` with a built-in potential (P[3] ∈ {1, 2, 3}); scalar kernel."""
    v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], y[7], y[8], y[9])
    rhs_core(y, u, P, gl, gm, gr, out, vel, force)


def rhs(t: float, y: np.ndarray, u: np.ndarray | None, params: Body) -> np.ndarray:
    """dy/dt of the packed state (eqs. (44)–(49) of [1], corrected bracket by default).

    Parameters
    ----------
    t : float
        Time (the system is autonomous; kept for the ``solve_ivp`` signature).
    y : ndarray, shape (11,)
        Packed state, layout in :mod:`flatbody_env.physics.state`.
    u : ndarray, shape (4,) or None
        Controls (τ1, τ2, τ3, f_ϱ), constant over the step; None for none.
    params : Body
        Inertia, potential and spin convention.

    Returns
    -------
    ndarray, shape (11,)
    """
    out = np.empty(11)
    _, gl, gm, gr = params.potential_terms(y[7], y[8], y[9])
    rhs_core(y, NO_CONTROL if u is None else u, params.kernel_params(), gl, gm, gr, out, np.empty(7), np.empty(4))
    return out


def hat_paper(omega: np.ndarray) -> np.ndarray:
    """W(ω) of eq. (25) of [1]: [[0, ω3, −ω2], [−ω3, 0, ω1], [ω2, −ω1, 0]] (= −hat(ω))."""
    w1, w2, w3 = omega
    return np.array([[0.0, w3, -w2], [-w3, 0.0, w1], [w2, -w1, 0.0]])


ROTATED_STATE_SIZE = 20
"""Size of the state z = (y, vec(R)) that carries the orientation: the eleven paper entries, then R
row by row (z[11 + 3i + j] = R[i, j])."""


def rotation_rate_kernel(z, vel, out):
    """Ṙ = R W(ω) (eq. (25) of [1]) of z = (y, vec(R)) (20,) into out[11:20]; ω = vel[0:3] (scalar kernel).

    W(ω) = [[0, ω3, −ω2], [−ω3, 0, ω1], [ω2, −ω1, 0]], so row i of Ṙ is
    (−ω3 R_i1 + ω2 R_i2, ω3 R_i0 − ω1 R_i2, −ω2 R_i0 + ω1 R_i1).
    """
    w1 = vel[0]
    w2 = vel[1]
    w3 = vel[2]
    for i in range(3):
        r0 = z[11 + 3 * i]
        r1 = z[12 + 3 * i]
        r2 = z[13 + 3 * i]
        out[11 + 3 * i] = w2 * r2 - w3 * r1
        out[12 + 3 * i] = w3 * r0 - w1 * r2
        out[13 + 3 * i] = w1 * r1 - w2 * r0


def rhs_rotation_kernel(z, u, P, out, vel, force):
    """dz/dt of z = (y, vec(R)) (20,): :func:`rhs_kernel` on y and :func:`rotation_rate_kernel` (scalar kernel)."""
    rhs_kernel(z, u, P, out, vel, force)
    rotation_rate_kernel(z, vel, out)


def turn_rotation_kernel(z, axis, angle):
    """R ← R exp(angle · W(e_axis)) in z[11:20]: the exact flow of Ṙ = R W(ω) for ω = (angle/h) e_axis
    held constant over h (a rotation of R's columns j, k about material axis ``axis``; scalar kernel)."""
    j = (axis + 1) % 3
    k = (axis + 2) % 3
    c = math.cos(angle)
    s = math.sin(angle)
    for i in range(3):
        a = z[11 + 3 * i + j]
        b = z[11 + 3 * i + k]
        z[11 + 3 * i + j] = c * a - s * b
        z[11 + 3 * i + k] = s * a + c * b


def rhs_with_rotation(t: float, z: np.ndarray, u: np.ndarray | None, params: Body) -> np.ndarray:
    """dz/dt for z = (y, vec(R)) of shape (20,): eqs. (44)–(49) plus Ṙ = R W(ω) (eq. (25) of [1])."""
    y = z[:11]
    out = np.empty(ROTATED_STATE_SIZE)
    vel = np.empty(7)
    _, gl, gm, gr = params.potential_terms(y[7], y[8], y[9])
    rhs_core(y, NO_CONTROL if u is None else u, params.kernel_params(), gl, gm, gr, out, vel, np.empty(4))
    rotation_rate_kernel(z, vel, out)
    return out
