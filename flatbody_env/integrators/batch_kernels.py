"""One fused DOP853 environment step for N bodies in structure-of-arrays layout.

Plain-Python kernels over arrays, compiled with :func:`flatbody_env.integrators.jit.jit_copy`
(:data:`dop853_batch_env_step` is the compiled driver): no numpy allocation inside, no
``np.nextafter``, no per-lane branch in the stage loops — the same source can later be given a GPU
target. The physics is the physics layer's scalar right-hand side for J1 = J2,
:func:`flatbody_env.physics.equations.rhs_iso` (eqs. (44)–(49) of the paper; :func:`rhs_core` calls
it too), called per lane on scalars: with the body's parameters read once into scalars the lane loop
has no memory dependence, and numba (LLVM) turns it into SIMD instructions (``error_model="numpy"``:
no division checks; no fastmath, so each lane's arithmetic is the scalar kernel's, bit for bit).

The step. Every lane takes one DOP853 step of size h = dt (Hairer's coefficients, the same
arithmetic in the same order as :func:`flatbody_env.integrators.twopolar_kernels.dop853_env_step`
with the first step guessed as dt): 13 right-hand sides, the stages combined lane by lane for each
state component. Then each lane's embedded error estimate (scipy's 5th/3rd-order blend) and its
state are checked. A lane whose step stands but whose state ends the episode (non-finite, out of the
chart: λ, μ, ϱ ≤ 0, λ − μ changing sign where it may not) gets the scalar kernel's status at once. The
lanes whose step is rejected (error ≥ 1) go on together (:func:`dop853_redo_lanes`): fused attempts
with a step size per lane, decided lane by lane by the scalar kernel's step control, starting from the
rejection; a lane whose step would collapse goes to the scalar kernel. So every lane's result,
status and function count are bit for bit the scalar kernel's (compiled with the same options,
:data:`JIT_OPTIONS`): the vector env equals N single envs step for step.

Lanes are stepped in blocks of :data:`BLOCK` so that the stage array stays in the caches.

Arrays: ``Y``, ``OUT`` (11, N); ``U`` (4, N); ``STATUS``, ``NFEV`` (N,) int64 (outputs); ``ERR`` (N,)
the error norms; work: ``KS`` (13, 11, B), ``YT`` (11, B), ``E3S``, ``ACC``, ``A5``, ``A3``, ``HB`` (B,) for
blocks of B lanes, ``LANES`` (N,) int64, ``W`` (9, B) and the scalar kernel's work arrays — allocated
once by the caller (:class:`DOP853Batch`).
"""

from __future__ import annotations

import math

import numpy as np

from flatbody_env.integrators import twopolar_kernels as _tk
from flatbody_env.integrators import jit as _jit
from flatbody_env.integrators.dop853_tableau import dop as _dop
from flatbody_env.integrators.jit import jit_copy
from flatbody_env.physics.equations import rhs_iso
from flatbody_env.physics.potentials import potential_kernel

N = 11
BLOCK = 64
"""Lanes per block of the fused step (a compile-time constant: the block arrays are addressed at
constant offsets, and the stage array, 13 × 11 × BLOCK doubles, stays in the CPU caches)."""
A = np.ascontiguousarray(_dop.A[: _dop.N_STAGES, : _dop.N_STAGES])
B = np.ascontiguousarray(_dop.B)
E3 = np.ascontiguousarray(_dop.E3)
E5 = np.ascontiguousarray(_dop.E5)


def rhs_lanes(X, U, P, F):
    """F[i·BLOCK + k] = component i of dy/dt of lane k of the block X (component i of lane k at
    X[i·BLOCK + k]) with controls U[j·BLOCK + k], for J1 = J2 (the caller checks).

    The physics is :func:`flatbody_env.physics.equations.rhs_iso` and
    :func:`flatbody_env.physics.potentials.potential_kernel` on scalars. The parameters are read once
    into scalars and each array is addressed at constant offsets from its own start (``F`` is a
    view of the stage array, not an array and a run-time offset: with an offset of unknown sign
    numba's negative-index wrap-around makes the store addresses non-affine and LLVM gives up
    vectorising), so the lane loop has no memory dependence and numba (LLVM) compiles it to SIMD
    instructions (4 lanes per AVX2 instruction; about twice the speed of the scalar loop).
    """
    J = P[0]
    J3 = P[2]
    kind = P[3]
    c1 = P[4]
    c2 = P[5]
    a = P[6]
    b = P[7]
    conv = P[8]
    for k in range(BLOCK):
        lam = X[7 * BLOCK + k]
        mu = X[8 * BLOCK + k]
        rho = X[9 * BLOCK + k]
        v, gl, gm, gr = potential_kernel(kind, c1, c2, a, b, lam, mu, rho)
        (d0, d1, d2, d3, d4, d5, d6, d7, d8, d9, d10, w1, w2, w3, thd, ld, md, rd, f1, f2, f3) = rhs_iso(
            X[k], X[BLOCK + k], X[2 * BLOCK + k], X[3 * BLOCK + k], X[4 * BLOCK + k], X[5 * BLOCK + k], X[6 * BLOCK + k], lam, mu, rho,
            U[k], U[BLOCK + k], U[2 * BLOCK + k], U[3 * BLOCK + k], J, J3, conv, gl, gm, gr)
        F[k] = d0
        F[BLOCK + k] = d1
        F[2 * BLOCK + k] = d2
        F[3 * BLOCK + k] = d3
        F[4 * BLOCK + k] = d4
        F[5 * BLOCK + k] = d5
        F[6 * BLOCK + k] = d6
        F[7 * BLOCK + k] = d7
        F[8 * BLOCK + k] = d8
        F[9 * BLOCK + k] = d9
        F[10 * BLOCK + k] = d10


def dop853_lanes(Y, U, P, H, rtol, atol, OUT, KS, YT, E5S, E3S, ACC, A5, A3):
    """One DOP853 step of size ``H[k]`` for each lane k of a block; OUT receives y + h Σ b_j k_j,
    E5S the error norm (scipy's ``_estimate_error_norm``) of each lane. Flat block arrays: component
    i of lane k at [i·BLOCK + k], stage j's component i at KS[(j·11 + i)·BLOCK + k]. The lane index is
    the innermost loop; each lane's sums keep the scalar kernel's order. ``A5``, ``A3`` (BLOCK,): work."""
    S = 11 * BLOCK
    rhs_lanes(Y, U, P, KS[0:S])
    for s in range(1, 12):
        for i in range(11):
            for k in range(BLOCK):
                ACC[k] = 0.0
            for j in range(s):
                c = A[s, j]
                o = (j * 11 + i) * BLOCK
                for k in range(BLOCK):
                    ACC[k] += KS[o + k] * c
            for k in range(BLOCK):
                YT[i * BLOCK + k] = Y[i * BLOCK + k] + H[k] * ACC[k]
        rhs_lanes(YT, U, P, KS[s * S:(s + 1) * S])
    for i in range(11):
        for k in range(BLOCK):
            ACC[k] = 0.0
        for j in range(12):
            c = B[j]
            o = (j * 11 + i) * BLOCK
            for k in range(BLOCK):
                ACC[k] += KS[o + k] * c
        for k in range(BLOCK):
            OUT[i * BLOCK + k] = Y[i * BLOCK + k] + H[k] * ACC[k]
    rhs_lanes(OUT, U, P, KS[12 * S:13 * S])
    for k in range(BLOCK):
        E5S[k] = 0.0
        E3S[k] = 0.0
    for i in range(11):
        for k in range(BLOCK):
            A5[k] = 0.0
            A3[k] = 0.0
        for j in range(13):  # lanes innermost (vectorised); each lane's sum over j in the scalar kernel's order
            c5 = E5[j]
            c3 = E3[j]
            o = (j * 11 + i) * BLOCK
            for k in range(BLOCK):
                kj = KS[o + k]
                A5[k] += kj * c5
                A3[k] += kj * c3
        for k in range(BLOCK):
            sc = atol + max(abs(Y[i * BLOCK + k]), abs(OUT[i * BLOCK + k])) * rtol
            a5 = A5[k] / sc
            a3 = A3[k] / sc
            E5S[k] += a5 * a5
            E3S[k] += a3 * a3
    for k in range(BLOCK):
        e5 = E5S[k]
        e3 = E3S[k]
        E5S[k] = 0.0 if (e5 == 0.0 and e3 == 0.0) else abs(H[k]) * e5 / math.sqrt((e5 + 0.01 * e3) * 11)


def lane_status(Y, U, P, OUT, k, yl):
    """The status the scalar kernel returns for lane k when it accepts the step to ``OUT[:, k]``: its
    :func:`~flatbody_env.integrators.twopolar_kernels._state_status` (non-finite, λ, μ, ϱ ≤ 0, λ − μ
    changing sign unless the chart may cross). ``yl`` (11,) receives the state."""
    for i in range(11):
        yl[i] = OUT[i, k]
    return state_status(yl, 1.0 if Y[7, k] > Y[8, k] else -1.0, not may_cross(Y[:, k], U[:, k], P))


def dop853_batch_env_step(Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, ERR, YB, UB, OB, KS, YT, EB, E3S, ACC, A5, A3, HB,
                          LANES, W, yl, ul, K1, ynew, ytmp, f, out1, vel, force, counters):
    """One env step of DOP853 (first step guess dt) for N lanes: the fused step on blocks of
    :data:`BLOCK` lanes copied into the flat block arrays ``YB``, ``UB``, ``OB`` (the last block
    padded with its first lane), then the lanes it cannot accept redone by :func:`dop853_redo_lanes`
    (module docstring). ``energy_tol`` < inf hands every lane to the scalar kernel."""
    n = Y.shape[1]
    check_energy = energy_tol < np.inf
    if check_energy:
        for k in range(n):
            scalar_lane(Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, k, yl, ul, K1, ynew, ytmp, f, out1, vel, force, counters)
        return
    for j in range(BLOCK):
        HB[j] = dt
    for start in range(0, n, BLOCK):
        m = min(BLOCK, n - start)
        for i in range(11):  # component by component: contiguous copies
            for j in range(m):
                YB[i * BLOCK + j] = Y[i, start + j]
            for j in range(m, BLOCK):
                YB[i * BLOCK + j] = Y[i, start]
        for i in range(4):
            for j in range(m):
                UB[i * BLOCK + j] = U[i, start + j]
            for j in range(m, BLOCK):
                UB[i * BLOCK + j] = U[i, start]
        dop853_lanes(YB, UB, P, HB, rtol, atol, OB, KS, YT, EB, E3S, ACC, A5, A3)
        for i in range(11):
            for j in range(m):
                OUT[i, start + j] = OB[i * BLOCK + j]
        for j in range(m):
            ERR[start + j] = EB[j]
    nl = 0
    for k in range(n):
        if ERR[k] < 1.0:  # the step stands: the scalar kernel accepts it and reports the state it reached
            STATUS[k] = lane_status(Y, U, P, OUT, k, yl)
            NFEV[k] = 13
        else:
            LANES[nl] = k
            nl += 1
    if nl > 0:
        dop853_redo_lanes(Y, U, P, dt, rtol, atol, LANES, nl, ERR, OUT, STATUS, NFEV, YB, UB, OB, KS, YT, EB, E3S, ACC, A5, A3, HB, W, yl,
                          ul, K1, ynew, ytmp, f, out1, vel, force, counters)


def scalar_lane(Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, k, yl, ul, K1, ynew, ytmp, f, out1, vel, force, counters):
    """Lane k by the scalar kernel :data:`dop853_env` from its start (first step guess dt)."""
    for i in range(11):
        yl[i] = Y[i, k]
    for i in range(4):
        ul[i] = U[i, k]
    counters[0] = 0
    counters[1] = 0
    counters[2] = 0
    STATUS[k] = dop853_env(yl, ul, P, dt, dt, rtol, atol, energy_tol, out1, K1, ynew, ytmp, vel, force, f, counters)
    NFEV[k] = counters[0]
    for i in range(11):
        OUT[i, k] = out1[i]


MAX_ROUNDS = 64
"""Fused attempts per block of redone lanes before the lanes still unfinished go to the scalar kernel."""


def dop853_redo_lanes(Y, U, P, dt, rtol, atol, LANES, nl, ERR, OUT, STATUS, NFEV, YB, UB, OB, KS, YT, EB, E3S, ACC, A5, A3, HB, W, yl,
                      ul, K1, ynew, ytmp, f, out1, vel, force, counters):
    """The lanes ``LANES[:nl]``, whose single step h = dt was rejected with the error norms ``ERR``,
    over one env step with the scalar kernel's step control, fused.

    The scalar kernel (:func:`flatbody_env.integrators.twopolar_kernels.dop853_advance`) takes each
    lane from t = 0 to dt with steps it accepts or rejects by the error norm (factors
    0.9·err^(−1/8) in [0.2, 10], no growth right after a rejection, the last step cut at dt) and checks
    the state after every accepted step. Here up to :data:`BLOCK` lanes follow that same sequence
    together: every round computes one attempt of every unfinished lane (its own step size, one
    :func:`dop853_lanes` call; finished and padding lanes take a zero step that is thrown away), then
    applies the scalar kernel's decisions lane by lane; the first attempt is the fused step's (the
    same arithmetic), so the lanes start from its rejection. Every lane therefore ends with the scalar
    kernel's state, status and function count (1 + 12 per attempt), bit for bit; a lane whose step
    would collapse, or that is still unfinished after :data:`MAX_ROUNDS` rounds, is handed to the
    scalar kernel from its start.

    ``W`` (9, BLOCK) work: t, |h|, rejected, active, attempts, gap sign, check gap, new step, t_new;
    ``yl`` (11,) receives a lane's state for the status check.
    """
    for start in range(0, nl, BLOCK):
        m = min(BLOCK, nl - start)
        for j in range(BLOCK):
            k = LANES[start + j] if j < m else LANES[start]
            for i in range(11):
                YB[i * BLOCK + j] = Y[i, k]
            for i in range(4):
                UB[i * BLOCK + j] = U[i, k]
            # the first attempt (h = dt) was the fused step's, rejected with the error ERR[k]: go on from there
            factor = _SAFETY * ERR[k]**_ERROR_EXPONENT
            if not factor > _MIN_FACTOR:
                factor = _MIN_FACTOR
            W[0, j] = 0.0
            W[1, j] = dt * factor
            W[2, j] = 1.0
            W[3, j] = 1.0 if j < m else 0.0
            W[4, j] = 1.0
            W[5, j] = 1.0 if Y[7, k] > Y[8, k] else -1.0
            W[6, j] = 0.0 if may_cross(Y[:, k], U[:, k], P) else 1.0
            W[7, j] = 0.0
            STATUS[k] = OK
        for _ in range(MAX_ROUNDS):
            active = 0
            for j in range(BLOCK):
                HB[j] = 0.0
                if W[3, j] == 0.0:
                    continue
                t = W[0, j]
                min_step = 10.0 * abs(next_up(t) - t)
                if W[7, j] != 0.0:  # a new step starts at t
                    if W[1, j] < min_step:
                        W[1, j] = min_step
                    W[2, j] = 0.0
                    W[7, j] = 0.0
                if W[1, j] < min_step:  # the step would collapse: the scalar kernel decides
                    W[3, j] = -1.0
                    continue
                t_new = t + W[1, j]
                if t_new > dt:
                    t_new = dt
                h = t_new - t
                W[1, j] = abs(h)
                W[8, j] = t_new
                HB[j] = h
                active += 1
            if active == 0:
                break
            dop853_lanes(YB, UB, P, HB, rtol, atol, OB, KS, YT, EB, E3S, ACC, A5, A3)
            for j in range(BLOCK):
                if W[3, j] != 1.0:
                    continue
                W[4, j] += 1.0
                err = EB[j]
                if err < 1.0:
                    if err == 0.0:
                        factor = _MAX_FACTOR
                    else:
                        factor = min(_MAX_FACTOR, _SAFETY * err**_ERROR_EXPONENT)
                    if W[2, j] != 0.0:
                        factor = min(1.0, factor)
                    W[1, j] *= factor
                    W[0, j] = W[8, j]
                    for i in range(11):
                        YB[i * BLOCK + j] = OB[i * BLOCK + j]
                        yl[i] = OB[i * BLOCK + j]
                    st = state_status(yl, W[5, j], W[6, j] != 0.0)
                    if st != OK:
                        STATUS[LANES[start + j]] = st
                        W[3, j] = 0.0
                    elif W[0, j] >= dt:
                        W[3, j] = 0.0
                    else:
                        W[7, j] = 1.0
                else:
                    factor = _SAFETY * err**_ERROR_EXPONENT
                    if not factor > _MIN_FACTOR:
                        factor = _MIN_FACTOR
                    W[1, j] *= factor
                    W[2, j] = 1.0
        for j in range(m):
            k = LANES[start + j]
            if W[3, j] != 0.0:  # collapsed or unfinished: the scalar kernel from the start
                scalar_lane(Y, U, P, dt, rtol, atol, np.inf, OUT, STATUS, NFEV, k, yl, ul, K1, ynew, ytmp, f, out1, vel, force, counters)
                continue
            for i in range(11):
                OUT[i, k] = YB[i * BLOCK + j]
            NFEV[k] = 1 + 12 * int(W[4, j])


dop853_env = _tk._dop853_env
"""The scalar kernel a lane falls back to (compiled with the same options)."""
state_status = _tk._state_status
may_cross = _tk.may_cross
next_up = _tk.next_up
OK = _tk.OK
_SAFETY = _tk._SAFETY
_MIN_FACTOR = _tk._MIN_FACTOR
_MAX_FACTOR = _tk._MAX_FACTOR
_ERROR_EXPONENT = _tk._ERROR_EXPONENT


_rhs_lanes_c = jit_copy(rhs_lanes, potential_kernel=_jit.potential_kernel, rhs_iso=_jit.rhs_iso)
_dop853_lanes_c = jit_copy(dop853_lanes, rhs_lanes=_rhs_lanes_c)
_lane_status_c = jit_copy(lane_status, state_status=_tk._state_status, may_cross=_tk.may_cross)
_scalar_lane_c = jit_copy(scalar_lane, dop853_env=_tk._dop853_env)
_redo_lanes_c = jit_copy(dop853_redo_lanes, dop853_lanes=_dop853_lanes_c, scalar_lane=_scalar_lane_c, state_status=_tk._state_status,
                         may_cross=_tk.may_cross, next_up=_tk.next_up)
dop853_batch_env_step_c = jit_copy(dop853_batch_env_step, dop853_lanes=_dop853_lanes_c, lane_status=_lane_status_c,
                                   scalar_lane=_scalar_lane_c, dop853_redo_lanes=_redo_lanes_c)
"""Compiled :func:`dop853_batch_env_step`."""


class DOP853Batch:
    """Work arrays for :func:`dop853_batch_env_step` at batch size N, and the call (picklable)."""

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self._alloc()

    def _alloc(self) -> None:
        self.work = (np.empty(self.n), np.empty(N * BLOCK), np.empty(4 * BLOCK), np.empty(N * BLOCK), np.empty(13 * N * BLOCK),
                     np.empty(N * BLOCK), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK),
                     np.empty(self.n, np.int64), np.empty((9, BLOCK)), np.empty(N), np.empty(4),
                     np.empty((13, N)), np.empty(N), np.empty(N), np.empty(N), np.empty(N), np.empty(7), np.empty(4), np.zeros(3, np.int64))

    def __getstate__(self):
        return {"n": self.n}

    def __setstate__(self, state):
        self.n = state["n"]
        self._alloc()

    def __call__(self, Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV) -> None:
        if P[0] != P[1]:
            raise ValueError("P: the fused batch step needs J1 = J2")
        if Y.shape[1] != self.n:
            self.n = Y.shape[1]
            self._alloc()
        dop853_batch_env_step_c(Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, *self.work)


__all__ = ["BLOCK", "DOP853Batch", "MAX_ROUNDS", "dop853_batch_env_step", "dop853_batch_env_step_c", "dop853_lanes", "dop853_redo_lanes", "lane_status",
           "rhs_lanes", "scalar_lane"]
