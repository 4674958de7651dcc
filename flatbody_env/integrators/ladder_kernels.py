"""Compiled (numba) integrator of the small systems of the planar rung of the model ladder.

On the planar set s1 = s2 = 0 (J1 = J2, no torques τ1, τ2, τ3) the two-polar equations
(eqs. (44)–(49) of [1], with the bracket corrected as in [2]) split into two systems that share
no variable (:mod:`.ladder`):

* the in-plane system x = (λ, μ, p_λ, p_μ, θ, α) with the constants s3, p_θ: λ̇ = p_λ/J,
  μ̇ = p_μ/J, ṗ_λ, ṗ_μ of eqs. (47)–(48) at s1 = s2 = 0, θ̇ (the inverse Legendre transform
  after eq. (31)) and α̇ = ω3 (the angle of R = R₀·exp(α W(e3)) about the normal, eq. (25));
* the thickness oscillator x = (ϱ, p_ϱ): ϱ̇ = p_ϱ/J3, ṗ_ϱ = −V_ϱ′(ϱ) + f_ϱ (eqs. (40), (49) at
  s1 = s2 = 0).

Neither right-hand side is written here: :func:`sub_rhs` writes the system's variables into a
full packed state (the template, which holds the constants), calls the physics layer's
:func:`~flatbody_env.physics.equations.rhs_kernel` (its jitted copy, :mod:`.jit`) and reads the
system's rates back through two index maps. That the rates it reads do not depend on the
other system's variables at s1 = s2 = 0 is checked in ``tests/integrators/test_ladder.py``.

:func:`dop853_small` is Hairer's DOP853 (scipy's coefficients, initial step and step control, as
in :mod:`.twopolar_kernels`) on such an n-variable system, stepping exactly onto every output time;
each system runs with its own steps.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from flatbody_env.integrators.dop853_tableau import ERROR_E3, ERROR_E5, ERROR_J, STAGE_C, STAGE_J, STAGE_L

from flatbody_env.integrators.failure import CHART_SINGULARITY, DOMAIN, MAX_STEPS, NON_FINITE, OK, STEP_COLLAPSE
from flatbody_env.integrators.jit import JIT_OPTIONS, energy_kernel, rhs_kernel
from flatbody_env.integrators.twopolar_kernels import next_up

njit = numba.njit(**JIT_OPTIONS)

_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_ERROR_EXPONENT = -1.0 / 8.0
MAX_STEPS_SMALL = 50_000_000

RATE_OMEGA3 = 11
"""Index of ω3 in the extended rate vector (dy/dt (11,) followed by ω3)."""

INPLANE_STATE = np.array([7, 8, 4, 5, 10, -1], dtype=np.int64)
"""Packed-state index of each in-plane variable (λ, μ, p_λ, p_μ, θ, α); −1: not a state entry (α)."""
INPLANE_RATE = np.array([7, 8, 4, 5, 10, RATE_OMEGA3], dtype=np.int64)
"""Extended-rate index of the derivative of each in-plane variable (α̇ = ω3)."""
THICKNESS_STATE = np.array([9, 6], dtype=np.int64)
"""Packed-state index of (ϱ, p_ϱ)."""
THICKNESS_RATE = np.array([9, 6], dtype=np.int64)


@njit
def sub_rhs(x, template, state_idx, rate_idx, u, P, dx, work, ext, vel, force):
    """dx/dt of a sub-system through the full right-hand side (module docstring).

    Parameters
    ----------
    x : array (n,)
        The sub-system's variables.
    template : array (11,)
        Packed state holding the other entries (constants of the planar motion).
    state_idx, rate_idx : int64 arrays (n,)
        Where each variable sits in the packed state (−1: none) and where its rate sits in the
        extended rate vector (dy/dt, then ω3 at :data:`RATE_OMEGA3`).
    u : array (4,)
        Controls (only f_ϱ is used on the planar set).
    P : array (9,)
        Kernel parameters.
    dx : array (n,), output
    work, ext, vel, force : arrays (11,), (12,), (7,), (4,)
        Work space.
    """
    for i in range(11):
        work[i] = template[i]
    for j in range(x.size):
        if state_idx[j] >= 0:
            work[state_idx[j]] = x[j]
    rhs_kernel(work, u, P, ext[:11], vel, force)
    ext[RATE_OMEGA3] = vel[2]
    for j in range(x.size):
        dx[j] = ext[rate_idx[j]]


@njit
def _rms(x, scale):
    acc = 0.0
    for i in range(x.size):
        r = x[i] / scale[i]
        acc += r * r
    return math.sqrt(acc / x.size)


@njit
def _status(x, positive, gap_sign, check_gap):
    for i in range(x.size):
        if not math.isfinite(x[i]):
            return NON_FINITE
    for i in range(positive):
        if x[i] <= 0.0:
            return DOMAIN
    if check_gap and (x[0] - x[1]) * gap_sign <= 0.0:
        return CHART_SINGULARITY
    return OK


@njit
def dop853_small(x0, times, template, state_idx, rate_idx, u, P, rtol, atol, positive, check_gap, X, counters, fail):
    """DOP853 on a sub-system from ``times[0]`` through every output time.

    Parameters
    ----------
    x0 : array (n,)
        Initial values.
    times : array (m,)
        Strictly increasing output times.
    template, state_idx, rate_idx, u, P
        As in :func:`sub_rhs`.
    rtol, atol : float
        Tolerances (scipy's error norm).
    positive : int
        The first ``positive`` variables must stay > 0 (λ, μ; ϱ).
    check_gap : bool
        Whether x[0] − x[1] (λ − μ) must keep its sign (the chart's barrier, σ₋ ≠ 0).
    X : array (n, m), output
        The values at the output times.
    counters : int64 array (3,)
        [RHS evaluations, accepted steps, rejected steps] (accumulated).
    fail : array (1,)
        The time reached (the failure time on failure).

    Returns
    -------
    int
        Status (:mod:`.failure`).
    """
    n = x0.size
    work = np.empty(11)
    ext = np.empty(12)
    vel = np.empty(7)
    force = np.empty(4)
    K = np.empty((13, n))
    x = x0.copy()
    xnew = np.empty(n)
    xtmp = np.empty(n)
    f = np.empty(n)
    scale = np.empty(n)
    sub_rhs(x, template, state_idx, rate_idx, u, P, f, work, ext, vel, force)
    counters[0] += 1
    gap_sign = 1.0 if x[0] > x[1] else -1.0
    for i in range(n):
        X[i, 0] = x[i]
    t = times[0]
    fail[0] = t
    t_final = times[times.size - 1]
    # initial step (scipy's select_initial_step, error order 7)
    h_abs = 0.0
    if t_final > t:
        for i in range(n):
            scale[i] = atol + abs(x[i]) * rtol
        d0 = _rms(x, scale)
        d1 = _rms(f, scale)
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        h0 = min(h0, t_final - t)
        for i in range(n):
            xtmp[i] = x[i] + h0 * f[i]
        sub_rhs(xtmp, template, state_idx, rate_idx, u, P, xnew, work, ext, vel, force)
        counters[0] += 1
        for i in range(n):
            xtmp[i] = xnew[i] - f[i]
        d2 = _rms(xtmp, scale) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
        h_abs = min(100.0 * h0, h1, t_final - t)
    for k in range(1, times.size):
        t_bound = times[k]
        while t < t_bound:
            min_step = 10.0 * abs(next_up(t) - t)
            if h_abs < min_step:
                h_abs = min_step
            rejected = False
            while True:
                if h_abs < min_step:
                    fail[0] = t
                    return STEP_COLLAPSE
                if counters[1] + counters[2] > MAX_STEPS_SMALL:
                    fail[0] = t
                    return MAX_STEPS
                t_new = min(t + h_abs, t_bound)
                h = t_new - t
                h_abs = abs(h)
                for i in range(n):
                    K[0, i] = f[i]
                for s in range(1, 12):
                    for i in range(n):
                        acc = 0.0
                        for q in range(STAGE_L[s]):  # the nonzero a_sj, in increasing j
                            acc += K[STAGE_J[s, q], i] * STAGE_C[s, q]
                        xtmp[i] = x[i] + h * acc
                    sub_rhs(xtmp, template, state_idx, rate_idx, u, P, K[s], work, ext, vel, force)
                for i in range(n):
                    acc = 0.0
                    for q in range(STAGE_L[12]):  # the nonzero b_j
                        acc += K[STAGE_J[12, q], i] * STAGE_C[12, q]
                    xnew[i] = x[i] + h * acc
                sub_rhs(xnew, template, state_idx, rate_idx, u, P, K[12], work, ext, vel, force)
                counters[0] += 12
                e5 = 0.0
                e3 = 0.0
                for i in range(n):
                    sc = atol + max(abs(x[i]), abs(xnew[i])) * rtol
                    a5 = 0.0
                    a3 = 0.0
                    for q in range(ERROR_J.shape[0]):
                        kj = K[ERROR_J[q], i]
                        a5 += kj * ERROR_E5[q]
                        a3 += kj * ERROR_E3[q]
                    a5 /= sc
                    a3 /= sc
                    e5 += a5 * a5
                    e3 += a3 * a3
                err = 0.0 if (e5 == 0.0 and e3 == 0.0) else abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * n)
                if err < 1.0:
                    factor = _MAX_FACTOR if err == 0.0 else min(_MAX_FACTOR, _SAFETY * err**_ERROR_EXPONENT)
                    if rejected:
                        factor = min(1.0, factor)
                    h_abs *= factor
                    break
                factor = _SAFETY * err**_ERROR_EXPONENT
                if not factor > _MIN_FACTOR:
                    factor = _MIN_FACTOR
                h_abs *= factor
                rejected = True
                counters[2] += 1
            counters[1] += 1
            t = t_new
            for i in range(n):
                x[i] = xnew[i]
                f[i] = K[12, i]
            st = _status(x, positive, gap_sign, check_gap)
            if st != OK:
                fail[0] = t
                return st
        fail[0] = t
        for i in range(n):
            X[i, k] = x[i]
    return OK


@njit
def energy_series(Y, P, out):
    """H (eq. (41) of [1]) of every column of the packed states ``Y`` (11, m) into ``out`` (m,)."""
    vel = np.empty(7)
    force = np.empty(4)
    y = np.empty(11)
    for k in range(Y.shape[1]):
        for i in range(11):
            y[i] = Y[i, k]
        out[k] = energy_kernel(y, P, vel, force)


__all__ = ["energy_series", "INPLANE_RATE", "INPLANE_STATE", "RATE_OMEGA3", "THICKNESS_RATE", "THICKNESS_STATE", "dop853_small", "sub_rhs"]
