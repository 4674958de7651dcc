"""Compiled RATTLE on the regular φψ formulation (docs/physics.md §7 of [2], :mod:`flatbody_env.physics.regular`).

Configuration q = (φ1, φ2, ψ) ∈ ℝ⁹ (columns of Φ), velocity v = q̇, constant mass
diag(J1, J1, J1, J2, J2, J2, J3, J3, J3), holonomic Kirchhoff–Love constraints (eq. (21) of [1])
g1 = ψ·φ1 = 0, g2 = ψ·φ2 = 0 with ∂g1 = (ψ, 0, φ1), ∂g2 = (0, ψ, φ2). One RATTLE step of size h
(Andersen 1983; Hairer–Lubich–Wanner VII.1):

.. math::
    q_{n+1} = q_n + h v_n + \\tfrac{h^2}{2} M^{-1}(F(q_n) - G(q_n)^T\\Lambda), \\quad g(q_{n+1}) = 0,

    v_{n+1} = \\frac{q_{n+1}-q_n}{h} + \\tfrac h2 M^{-1}(F(q_{n+1}) - G(q_{n+1})^T\\mu), \\quad
    G(q_{n+1}) v_{n+1} = 0,

Λ by Newton's method on the two quadratic constraints, μ from a 2×2 linear system (the matrix
of :func:`flatbody_env.physics.regular.regular_rhs`). RATTLE is symmetric and symplectic (order 2); it
conserves the spatial angular momentum and p_θ exactly. Suzuki's 5-stage composition
(:data:`~.compositions.SUZUKI4`) raises it to order 4, Kahan–Li's 9-stage one
(:data:`~.compositions.KAHAN_LI6`) to order 6; forces are re-used across stages.

Forces and energy are the physics layer's plain-float kernels, compiled here by
:func:`~.jit.retarget` (no formula is restated): :func:`forces` is
:func:`flatbody_env.physics.regular.regular_forces_kernel` (F = −∂V/∂q + f_ϱ ψ/ϱ with V a function of
tr, det and ϱ, docs/physics.md §7; (V_tr, V_det) from
:func:`flatbody_env.physics.potentials.invariant_gradient_kernel`: V1, V2 with c = d, V3);
:func:`regular_energy_kernel` (H, docs/physics.md §7), :func:`invariant_gradient_kernel`, :func:`stretches`
(:func:`flatbody_env.physics.kinematics.stretches_kernel`) and :func:`column_dot` are the compiled twins
of the physics kernels. V2 with c ≠ d is no function of the invariants (erratum E9) and
is refused by the method layer. Stated here: the RATTLE step itself (the position update, the Newton
solve for Λ, the 2×2 multiplier system for μ), the compositions and the chart following.

Chart following. The paper's state needs the two-polar decomposition Φ = R D U(θ)⁻¹ chosen by
continuity (docs/physics.md §7). :func:`decompose_kernel` (compiled
:func:`flatbody_env.physics.kinematics.decompose_kernel`: the rule of
:func:`~flatbody_env.physics.kinematics.decompose` in closed form, never raising inside the step loop;
equal to it to round-off, not bit for bit) continues it for the Kirchhoff–Love Φ. After every step the
decomposition is continued from the previous one; when the chart frame jumps by more than
:data:`~flatbody_env.physics.regular.MAX_CHART_JUMP` (near λ = μ it turns by ±π/2 within a tiny time) the
step is re-walked on the cubic Hermite interpolant of Φ with adaptive sub-intervals. At output
times the method layer converts to the paper's state with
:func:`flatbody_env.physics.regular.paper_from_regular` given that decomposition.

Only the dilatation force f_ϱ = u[3] is applied; non-zero torques return status 9
(``"unsupported"``): in Φ-space they depend on the chart's frame (singular at λ = μ for τ3). The environment
steps these methods through ``integrate`` (:mod:`.steppers`), which converts to and from the paper state.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
.. [3] H. C. Andersen, RATTLE, J. Comput. Phys. 52 (1983); E. Hairer, C. Lubich, G. Wanner,
   *Geometric Numerical Integration*, §VII.1; M. Suzuki, Phys. Lett. A 146 (1990).
"""

from __future__ import annotations

import math

import numpy as np

from flatbody_env.physics import kinematics as _kinematics
from flatbody_env.physics import potentials as _potentials
from flatbody_env.physics import regular as _regular
from flatbody_env.physics.regular import MAX_CHART_JUMP
from flatbody_env.integrators.failure import CHART_SINGULARITY, CONSTRAINT, DOMAIN, ENERGY, NON_FINITE, OK, UNSUPPORTED
from flatbody_env.integrators.jit import njit, retarget


NZ = 18
NEWTON_MAX = 30

column_dot = retarget(_kinematics.column_dot)
decompose_kernel = retarget(_kinematics.decompose_kernel)
invariant_gradient_kernel = retarget(_potentials.invariant_gradient_kernel)
forces = retarget(_regular.regular_forces_kernel)
stretches = retarget(_kinematics.stretches_kernel)
regular_energy_kernel = retarget(_regular.regular_energy_kernel)


@njit
def rattle_step(z, h, P, f_rho, F, qt, Fn):
    """One RATTLE step of size h in place. F (9,) holds the forces at z on entry and at the new
    position on return. Returns the status."""
    J1 = P[0]
    J2 = P[1]
    J3 = P[2]
    c = 0.5 * h * h
    for i in range(3):
        qt[i] = z[i] + h * z[9 + i] + c * F[i] / J1
        qt[3 + i] = z[3 + i] + h * z[12 + i] + c * F[3 + i] / J2
        qt[6 + i] = z[6 + i] + h * z[15 + i] + c * F[6 + i] / J3
    scale = column_dot(z, 6, 6) + column_dot(z, 0, 0) + column_dot(z, 3, 3)
    L1 = 0.0
    L2 = 0.0
    converged = False
    p1 = np.empty(3)
    p2 = np.empty(3)
    ps = np.empty(3)
    for _it in range(NEWTON_MAX):
        for i in range(3):
            p1[i] = qt[i] - c * L1 * z[6 + i] / J1
            p2[i] = qt[3 + i] - c * L2 * z[6 + i] / J2
            ps[i] = qt[6 + i] - c * (L1 * z[i] + L2 * z[3 + i]) / J3
        g1 = ps[0] * p1[0] + ps[1] * p1[1] + ps[2] * p1[2]
        g2 = ps[0] * p2[0] + ps[1] * p2[1] + ps[2] * p2[2]
        if abs(g1) + abs(g2) <= 4e-16 * scale:
            converged = True
            break
        d11 = 0.0
        d12 = 0.0
        d21 = 0.0
        d22 = 0.0
        for i in range(3):
            d11 -= c * (ps[i] * z[6 + i] / J1 + p1[i] * z[i] / J3)
            d12 -= c * p1[i] * z[3 + i] / J3
            d21 -= c * p2[i] * z[i] / J3
            d22 -= c * (ps[i] * z[6 + i] / J2 + p2[i] * z[3 + i] / J3)
        dd = d11 * d22 - d12 * d21
        if not (abs(dd) > 0.0) or not math.isfinite(dd):
            return NON_FINITE if not math.isfinite(dd) else CONSTRAINT
        L1 -= (d22 * g1 - d12 * g2) / dd
        L2 -= (d11 * g2 - d21 * g1) / dd
    if not converged:
        # round-off floor: accept when the last Newton correction no longer changes the iterate
        if not (abs(g1) + abs(g2) <= 1e-12 * scale):
            return CONSTRAINT if math.isfinite(g1 + g2) else NON_FINITE
    for i in range(3):
        z[9 + i] = (p1[i] - z[i]) / h
        z[12 + i] = (p2[i] - z[3 + i]) / h
        z[15 + i] = (ps[i] - z[6 + i]) / h
        z[i] = p1[i]
        z[3 + i] = p2[i]
        z[6 + i] = ps[i]
    det = forces(z, P, f_rho, F)
    if not (det > 0.0):
        return DOMAIN if math.isfinite(det) else NON_FINITE
    k = 0.5 * h
    for i in range(3):
        z[9 + i] += k * F[i] / J1
        z[12 + i] += k * F[3 + i] / J2
        z[15 + i] += k * F[6 + i] / J3
    pp = column_dot(z, 6, 6)
    a11 = pp / J1 + column_dot(z, 0, 0) / J3
    a22 = pp / J2 + column_dot(z, 3, 3) / J3
    a12 = column_dot(z, 0, 3) / J3
    r1 = column_dot(z, 6, 9) + column_dot(z, 0, 15)
    r2 = column_dot(z, 6, 12) + column_dot(z, 3, 15)
    dA = a11 * a22 - a12 * a12
    m1 = (a22 * r1 - a12 * r2) / dA
    m2 = (a11 * r2 - a12 * r1) / dA
    for i in range(3):
        z[9 + i] -= m1 * z[6 + i] / J1
        z[12 + i] -= m2 * z[6 + i] / J2
        z[15 + i] -= (m1 * z[i] + m2 * z[3 + i]) / J3
    for i in range(NZ):
        if not math.isfinite(z[i]):
            return NON_FINITE
    return OK


@njit
def composed_step(z, h, coeffs, P, f_rho, F, qt, Fn):
    """A composition (coefficients ``coeffs``) of RATTLE steps; returns the status."""
    for c in coeffs:
        st = rattle_step(z, c * h, P, f_rho, F, qt, Fn)
        if st != OK:
            return st
    return OK


# --------------------------------------------------------------------------------------------- chart
@njit
def _hermite(z0, z1, h, s, q):
    s2 = s * s
    s3 = s2 * s
    a = 2.0 * s3 - 3.0 * s2 + 1.0
    b = s3 - 2.0 * s2 + s
    c = -2.0 * s3 + 3.0 * s2
    d = s3 - s2
    for i in range(9):
        q[i] = a * z0[i] + b * h * z0[9 + i] + c * z1[i] + d * h * z1[9 + i]


@njit
def follow_step(z0, z1, h, ref, keep_order, out, q, tmp):
    """Continue the decomposition ``ref`` (at z0) to z1 (one step h later) into ``out``.

    Walks the Hermite interpolant with adaptive sub-intervals whenever the frame jumps by
    more than MAX_CHART_JUMP. Returns False if the frame cannot be followed (interval below
    1e-300 relative)."""
    jump = decompose_kernel(z1, ref, keep_order, out)
    if jump <= MAX_CHART_JUMP:
        return True
    for i in range(13):
        tmp[i] = ref[i]
    s = 0.0
    ds = 0.5
    while s < 1.0:
        sn = min(1.0, s + ds)
        _hermite(z0, z1, h, sn, q)
        jump = decompose_kernel(q, tmp, keep_order, out)
        if jump <= MAX_CHART_JUMP or ds < 1e-15:
            if ds < 1e-15 and jump > MAX_CHART_JUMP:
                return False
            for i in range(13):
                tmp[i] = out[i]
            s = sn
            ds = min(0.5, 2.0 * ds)
        else:
            ds *= 0.5
    decompose_kernel(z1, tmp, keep_order, out)
    return True


# --------------------------------------------------------------------------------------------- drivers
@njit
def _torque_free(u):
    return u[0] == 0.0 and u[1] == 0.0 and u[2] == 0.0


@njit
def rattle_solve(coeffs, z0, dec0, times, u, P, h, keep_order, energy_tol, Z, DEC, counters, fail):
    """Composed RATTLE through every output time.

    Z (18, n) receives the regular states, DEC (13, n) the decompositions followed by
    continuity from dec0 (13,); counters (3,) int64 [force evaluations, steps, chart sub-steps];
    fail (2,) [t of failure, last |H − H₀|]. Returns the status.
    """
    if not _torque_free(u):
        return UNSUPPORTED
    F = np.empty(9)
    qt = np.empty(9)
    Fn = np.empty(9)
    q = np.empty(9)
    tmp = np.empty(13)
    z = z0.copy()
    zp = np.empty(NZ)
    ref = dec0.copy()
    new = np.empty(13)
    f_rho = u[3]
    forces(z, P, f_rho, F)
    counters[0] += 1
    check_energy = energy_tol < np.inf and f_rho == 0.0
    H0 = regular_energy_kernel(z, P)
    for i in range(NZ):
        Z[i, 0] = z[i]
    for i in range(13):
        DEC[i, 0] = ref[i]
    fail[0] = times[0]
    t = times[0]
    for k in range(1, times.size):
        span = times[k] - times[k - 1]
        n = max(1, int(math.ceil(span / h - 1e-9)))
        hs = span / n
        for j in range(n):
            for i in range(NZ):
                zp[i] = z[i]
            st = composed_step(z, hs, coeffs, P, f_rho, F, qt, Fn)
            counters[0] += coeffs.size
            counters[1] += 1
            t = times[k - 1] + (j + 1) * hs
            if st != OK:
                fail[0] = t
                return st
            if not follow_step(zp, z, hs, ref, keep_order, new, q, tmp):
                fail[0] = t
                return CHART_SINGULARITY
            for i in range(13):
                ref[i] = new[i]
        for i in range(NZ):
            Z[i, k] = z[i]
        for i in range(13):
            DEC[i, k] = ref[i]
        fail[0] = times[k]
        if check_energy:
            dH = abs(regular_energy_kernel(z, P) - H0)
            fail[1] = dH
            if dH > energy_tol:
                return ENERGY
    return OK
