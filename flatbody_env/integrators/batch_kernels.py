"""One fused DOP853 environment step for N bodies in structure-of-arrays layout.

Plain-Python kernels over arrays, compiled with :func:`flatbody_env.integrators.jit.jit_copy`
(:data:`dop853_batch_env_step` is the compiled driver): no numpy allocation inside, no
``np.nextafter``, no per-lane branch in the stage loops — the same source can later be given a GPU
target. The physics is the one scalar right-hand side
:func:`flatbody_env.physics.equations.rhs_kernel` (eqs. (44)–(49) of the paper), called per lane.

The step. Every lane takes one DOP853 step of size h = dt (Hairer's coefficients, the same
arithmetic in the same order as :func:`flatbody_env.integrators.twopolar_kernels.dop853_env_step`
with the first step guessed as dt): 13 right-hand sides, the stages combined lane by lane for each
state component. Then each lane's embedded error estimate (scipy's 5th/3rd-order blend) and its
state are checked; a lane whose step would be rejected (error ≥ 1), whose state is non-finite or
out of the chart (λ, μ, ϱ ≤ 0, λ − μ changing sign where it may not) is redone from its start by the
scalar kernel, which handles rejections, step-size control and failure codes. So every lane's
result is bit for bit the scalar kernel's (compiled with the same options, :data:`JIT_OPTIONS`): the
vector env equals N single envs step for step.

Arrays: ``Y``, ``OUT`` (11, N); ``U`` (4, N); ``STATUS``, ``NFEV`` (N,) int64 (outputs);
work: ``KS`` (13, 11, N), ``YT`` (11, N), ``E5S``, ``E3S``, ``ACC`` (N,), ``yl``, ``fl`` (11,), ``ul`` (4,),
``vel`` (7,), ``force`` (4,) — allocated once by the caller (:class:`DOP853Batch`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate._ivp import dop853_coefficients as _dop

from flatbody_env.integrators import twopolar_kernels as _tk
from flatbody_env.integrators.jit import jit_copy, rhs_kernel

N = 11
A = np.ascontiguousarray(_dop.A[: _dop.N_STAGES, : _dop.N_STAGES])
B = np.ascontiguousarray(_dop.B)
E3 = np.ascontiguousarray(_dop.E3)
E5 = np.ascontiguousarray(_dop.E5)


def rhs_lanes(X, U, P, F, yl, ul, fl, vel, force):
    """F[:, k] = dy/dt of lane k of X (11, N) with controls U[:, k] (the scalar physics kernel per lane)."""
    for k in range(X.shape[1]):
        for i in range(11):
            yl[i] = X[i, k]
        for i in range(4):
            ul[i] = U[i, k]
        rhs_kernel(yl, ul, P, fl, vel, force)
        for i in range(11):
            F[i, k] = fl[i]


def dop853_lanes(Y, U, P, h, rtol, atol, OUT, KS, YT, E5S, E3S, ACC, yl, ul, fl, vel, force):
    """One DOP853 step of size ``h`` for every lane; OUT receives y + h Σ b_j k_j, E5S the error norm
    (scipy's ``_estimate_error_norm``) of each lane. The lane index is the innermost loop (each
    lane's sums keep the scalar kernel's order)."""
    n = Y.shape[1]
    rhs_lanes(Y, U, P, KS[0], yl, ul, fl, vel, force)
    for s in range(1, 12):
        for i in range(11):
            for k in range(n):
                ACC[k] = 0.0
            for j in range(s):
                c = A[s, j]
                for k in range(n):
                    ACC[k] += KS[j, i, k] * c
            for k in range(n):
                YT[i, k] = Y[i, k] + h * ACC[k]
        rhs_lanes(YT, U, P, KS[s], yl, ul, fl, vel, force)
    for i in range(11):
        for k in range(n):
            ACC[k] = 0.0
        for j in range(12):
            c = B[j]
            for k in range(n):
                ACC[k] += KS[j, i, k] * c
        for k in range(n):
            OUT[i, k] = Y[i, k] + h * ACC[k]
    rhs_lanes(OUT, U, P, KS[12], yl, ul, fl, vel, force)
    for k in range(n):
        E5S[k] = 0.0
        E3S[k] = 0.0
    for i in range(11):
        for k in range(n):
            ACC[k] = atol + max(abs(Y[i, k]), abs(OUT[i, k])) * rtol
        for k in range(n):
            a5 = 0.0
            a3 = 0.0
            for j in range(13):
                a5 += KS[j, i, k] * E5[j]
                a3 += KS[j, i, k] * E3[j]
            a5 /= ACC[k]
            a3 /= ACC[k]
            E5S[k] += a5 * a5
            E3S[k] += a3 * a3
    for k in range(n):
        e5 = E5S[k]
        e3 = E3S[k]
        if e5 == 0.0 and e3 == 0.0:
            E5S[k] = 0.0
        else:
            E5S[k] = abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * 11)


def lane_accepted(Y, U, P, OUT, err, k):
    """Whether lane k's single step stands as the scalar kernel would take it: error < 1, finite
    state, λ, μ, ϱ > 0 and no sign change of λ − μ unless the chart may cross (``may_cross``)."""
    if not err < 1.0:
        return False
    for i in range(11):
        if not math.isfinite(OUT[i, k]):
            return False
    if OUT[7, k] <= 0.0 or OUT[8, k] <= 0.0 or OUT[9, k] <= 0.0:
        return False
    crossable = P[0] == P[1] and Y[2, k] == Y[3, k] and U[2, k] == 0.0
    if not crossable:
        gap_sign = 1.0 if Y[7, k] > Y[8, k] else -1.0
        if (OUT[7, k] - OUT[8, k]) * gap_sign <= 0.0:
            return False
    return True


def dop853_batch_env_step(Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, KS, YT, E5S, E3S, ACC, yl, ul, fl, vel, force,
                          K1, ynew, ytmp, f, out1, counters):
    """One env step of DOP853 (first step guess dt) for N lanes: the fused step, then the scalar
    kernel for the lanes it cannot accept (module docstring). ``energy_tol`` applies to both."""
    dop853_lanes(Y, U, P, dt, rtol, atol, OUT, KS, YT, E5S, E3S, ACC, yl, ul, fl, vel, force)
    check_energy = energy_tol < np.inf
    for k in range(Y.shape[1]):
        if lane_accepted(Y, U, P, OUT, E5S[k], k) and not check_energy:
            STATUS[k] = 0
            NFEV[k] = 13
            continue
        for i in range(11):
            yl[i] = Y[i, k]
        for i in range(4):
            ul[i] = U[i, k]
        counters[0] = 0
        STATUS[k] = dop853_env(yl, ul, P, dt, dt, rtol, atol, energy_tol, out1, K1, ynew, ytmp, vel, force, f, counters)
        NFEV[k] = counters[0]
        for i in range(11):
            OUT[i, k] = out1[i]


dop853_env = _tk._dop853_env
"""The scalar kernel the rejected lanes are redone with (bound to its compiled version below)."""

_rhs_lanes_c = jit_copy(rhs_lanes, rhs_kernel=rhs_kernel)
_dop853_lanes_c = jit_copy(dop853_lanes, rhs_lanes=_rhs_lanes_c)
_lane_accepted_c = jit_copy(lane_accepted)
dop853_batch_env_step_c = jit_copy(dop853_batch_env_step, dop853_lanes=_dop853_lanes_c, lane_accepted=_lane_accepted_c,
                                   dop853_env=_tk._dop853_env)
"""Compiled :func:`dop853_batch_env_step`."""


class DOP853Batch:
    """Work arrays for :func:`dop853_batch_env_step` at batch size N, and the call (picklable)."""

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self._alloc()

    def _alloc(self) -> None:
        n = self.n
        self.work = (np.empty((13, N, n)), np.empty((N, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(N), np.empty(4), np.empty(N),
                     np.empty(7), np.empty(4), np.empty((13, N)), np.empty(N), np.empty(N), np.empty(N), np.empty(N),
                     np.zeros(3, np.int64))

    def __getstate__(self):
        return {"n": self.n}

    def __setstate__(self, state):
        self.n = state["n"]
        self._alloc()

    def __call__(self, Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV) -> None:
        if Y.shape[1] != self.n:
            self.n = Y.shape[1]
            self._alloc()
        dop853_batch_env_step_c(Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, *self.work)


__all__ = ["DOP853Batch", "dop853_batch_env_step", "dop853_batch_env_step_c", "dop853_lanes", "lane_accepted", "rhs_lanes"]
