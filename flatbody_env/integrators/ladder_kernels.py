"""Compiled (numba) integrator of the small systems of the planar rung of the model ladder.

On the planar set s1 = s2 = 0 (J1 = J2, no torques τ1, τ2, τ3) the two-polar equations
(eqs. (44)–(49) of [1], with the bracket corrected as in [2]) split into two systems that share
no variable (:mod:`.ladder`):

* the in-plane system x = (λ, μ, p_λ, p_μ, θ, α) with the constants s3, p_θ: λ̇ = p_λ/J,
  μ̇ = p_μ/J, ṗ_λ, ṗ_μ of eqs. (47)–(48) at s1 = s2 = 0, θ̇ (the inverse Legendre transform
  after eq. (31)) and α̇ = ω3 (the angle of R = R₀·exp(α W(e3)) about the normal, eq. (25));
* the thickness oscillator x = (ϱ, p_ϱ): ϱ̇ = p_ϱ/J3, ṗ_ϱ = −V_ϱ′(ϱ) + f_ϱ (eqs. (40), (49) at
  s1 = s2 = 0).

Neither right-hand side is written here: :func:`subsystem_rhs` writes the system's variables into a
full packed state (the template, which holds the constants), calls the physics layer's
:func:`~flatbody_env.physics.equations.rhs_kernel` (its jitted copy, :mod:`.jit`) and reads the
system's rates back through two index maps. That the rates it reads do not depend on the
other system's variables at s1 = s2 = 0 is checked in ``tests/integrators/test_ladder.py``.

:data:`dop853_inplane` and :data:`dop853_thickness` are the two-polar DOP853 itself (scipy's
coefficients, initial step and step control: :func:`~.twopolar_kernels.dop853_initial_step_into`,
:func:`~.twopolar_kernels.dop853_advance`) compiled by :func:`~.jit.retarget` for each system, with
``N`` (6 or 2), the right-hand side (:func:`subsystem_rhs`) and the status rule re-bound; each system runs
with its own steps, stepping exactly onto every output time.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata).
"""

from __future__ import annotations

import numpy as np

from flatbody_env.integrators import twopolar_kernels as _tk
from flatbody_env.integrators.failure import MAX_STEPS, OK
from flatbody_env.integrators.jit import njit, retarget, rhs_kernel
from flatbody_env.integrators.twopolar_kernels import (
    CARRY_COUNTERS,
    CARRY_GAP_SIGN,
    CARRY_H,
    CARRY_K,
    CARRY_REJECTED,
    CARRY_T,
    CARRY_Y,
)

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
def subsystem_rhs(x, u, PT, dx, W, force):
    """dx/dt of a sub-system through the full right-hand side (module docstring), with the signature of
    :func:`~flatbody_env.physics.equations.rhs_kernel` so that the two-polar DOP853 runs on it unchanged:
    the system's data ride in the arguments the step passes through to its right-hand side.

    Parameters
    ----------
    x : array (n,)
        The sub-system's variables.
    u : array (4,)
        Controls (only f_ϱ is used on the planar set).
    PT : tuple (P, template, state_idx, rate_idx)
        Kernel parameters (9,); the packed state (11,) holding the other entries (constants of the
        planar motion); where each variable sits in the packed state (−1: none) and where its rate
        sits in the extended rate vector (dy/dt, then ω3 at :data:`RATE_OMEGA3`), int64 (n,).
    dx : array (n,), output
    W, force : tuple of arrays (7,), (11,), (12,); array (4,)
        Work space (velocities, the packed state, the extended rates; forces).
    """
    P, template, state_idx, rate_idx = PT
    vel, work, ext = W
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
def sub_rhs(x, template, state_idx, rate_idx, u, P, dx, work, ext, vel, force):
    """:func:`subsystem_rhs` with its data as separate arguments (``work``, ``ext``, ``vel``, ``force``: (11,), (12,), (7,), (4,))."""
    subsystem_rhs(x, u, (P, template, state_idx, rate_idx), dx, (vel, work, ext), force)


# Re-bound for each sub-system by ``retarget`` (:data:`dop853_inplane`, :data:`dop853_thickness`): its size,
# the index maps into the paper state and its rates, and how many leading variables must stay > 0.
N = STATE_IDX = RATE_IDX = POSITIVE = None


def _subsystem_status(x, gap_sign, check_gap):
    """The two-polar status rule (:func:`~.twopolar_kernels.state_code`) on a sub-system: its first
    ``POSITIVE`` variables (λ, μ; ϱ) must stay > 0, x[0] − x[1] (λ − μ) keep its sign where checked."""
    return state_code(_finite(x), x[0], x[1] if POSITIVE > 1 else 1.0, 1.0, gap_sign, check_gap)


def _dop853_subsystem(x0, times, template, u, P, rtol, atol, check_gap, X, counters, fail, carry=None):
    """DOP853 on one system of ``N`` variables (:data:`dop853_inplane`, :data:`dop853_thickness`): the two-polar DOP853's
    initial step and step control (:func:`~.twopolar_kernels.dop853_advance`) with ``N``, the index maps
    ``STATE_IDX``, ``RATE_IDX``, the right-hand side (:func:`subsystem_rhs`) and the status rule re-bound. ``carry``
    (optional, :func:`~.twopolar_kernels.carry_size` (N)): where the run stands, so that a run its budget of
    evaluations stopped continues with a larger one, bit for bit (as :func:`~.twopolar_kernels.dop853_solve_into`)."""
    if carry is None:
        where = np.zeros(CARRY_Y + 2 * N)
    else:
        where = carry
    K = np.empty((13, N))
    x = np.empty(N)
    xnew = np.empty(N)
    xtmp = np.empty(N)
    f = np.empty(N)
    force = np.empty(4)
    PT = (P, template, STATE_IDX, RATE_IDX)
    W = (np.empty(7), np.empty(11), np.empty(12))
    k0 = int(where[CARRY_K])
    if k0 == 0:  # a fresh start at times[0]
        for i in range(N):
            x[i] = x0[i]
        rhs_kernel(x, u, PT, f, W, force)
        counters[0] += 1
        gap_sign = 1.0 if x[0] > x[1] else -1.0
        for i in range(N):
            X[i, 0] = x[i]
        t = times[0]
        fail[0] = t
        h_abs = dop853_initial_step_into(
            x, f, t, times[times.size - 1], u, PT, rtol, atol, W, force, xtmp, xnew, counters
        )
        rejected = False
        k0 = 1
    else:  # go on from where the budget stopped the run
        for i in range(N):
            x[i] = where[CARRY_Y + i]
            f[i] = where[CARRY_Y + N + i]
        for i in range(3):
            counters[i] = int(where[CARRY_COUNTERS + i])
        t = where[CARRY_T]
        h_abs = where[CARRY_H]
        rejected = where[CARRY_REJECTED] != 0.0
        gap_sign = where[CARRY_GAP_SIGN]
    where[CARRY_K] = -1.0
    for k in range(k0, times.size):
        st, t, h_abs, rejected = dop853_advance(
            x, f, t, times[k], h_abs, rejected, u, PT, rtol, atol, gap_sign, check_gap, K, xnew, xtmp, W, force,
            counters,
        )  # fmt: skip
        fail[0] = t
        if st == MAX_STEPS:  # where to go on from
            where[CARRY_T] = t
            where[CARRY_H] = h_abs
            where[CARRY_K] = k
            where[CARRY_REJECTED] = 1.0 if rejected else 0.0
            where[CARRY_GAP_SIGN] = gap_sign
            for i in range(3):
                where[CARRY_COUNTERS + i] = counters[i]
            for i in range(N):
                where[CARRY_Y + i] = x[i]
                where[CARRY_Y + N + i] = f[i]
        if st != OK:
            return st
        for i in range(N):
            X[i, k] = x[i]
    return OK


_finite = _tk._finite
state_code = _tk.state_code
dop853_advance = _tk.dop853_advance
dop853_initial_step_into = _tk.dop853_initial_step_into
dop853_inplane = retarget(
    _dop853_subsystem,
    N=6,
    STATE_IDX=INPLANE_STATE,
    RATE_IDX=INPLANE_RATE,
    rhs_kernel=subsystem_rhs,
    _state_status=retarget(_subsystem_status, POSITIVE=2),
)
"""DOP853 on the in-plane system from ``times[0]`` through every output time:
``(x0 (6,), times (m,), template (11,), u, P, rtol, atol, check_gap, X (6, m), counters, fail[, carry]) -> status``.

``template``, ``u``, ``P`` as in :func:`sub_rhs`; ``check_gap``: whether λ − μ must keep its sign (the
chart's barrier, σ₋ ≠ 0); ``counters`` (3,) int64 accumulates [RHS evaluations, accepted steps, rejected
steps]; ``fail`` (1,) receives the time reached (the failure time on failure); ``carry`` (optional,
:func:`~.twopolar_kernels.carry_size` (6)): where the run stands, to continue one its budget stopped; the status
is :mod:`.failure`'s."""
dop853_thickness = retarget(
    _dop853_subsystem,
    N=2,
    STATE_IDX=THICKNESS_STATE,
    RATE_IDX=THICKNESS_RATE,
    rhs_kernel=subsystem_rhs,
    _state_status=retarget(_subsystem_status, POSITIVE=1),
)
"""DOP853 on the thickness oscillator (ϱ, p_ϱ): the arguments of :data:`dop853_inplane` (``check_gap`` False)."""


__all__ = [
    "INPLANE_RATE",
    "INPLANE_STATE",
    "RATE_OMEGA3",
    "THICKNESS_RATE",
    "THICKNESS_STATE",
    "dop853_inplane",
    "dop853_thickness",
    "sub_rhs",
    "subsystem_rhs",
]
