"""Per-body drivers that allocate nothing, and the compiled CPU batch kernels built on them.

One kernel source, two targets: every function here is plain Python compiled by numba for the
CPU (``@njit``, :mod:`.jit`'s options) and, through :mod:`.cuda`, re-compiled from the same
``.py_func`` as a CUDA device function (with the functions it calls re-bound to their device
twins). So nothing here allocates: work arrays come in as arguments, which the CPU kernels
allocate with ``np.empty`` (once per chunk of bodies) and the CUDA kernels with
``cuda.local.array`` (once per thread).

Method kinds (:data:`KIND`, derived from :data:`~.specs.SPECS`): 0 RK4, 1 a splitting with coefficients
``coeffs`` (:mod:`.compositions`), 2 DOP853.

* :func:`~.twopolar_kernels.fixed_solve_into` / :func:`~.twopolar_kernels.dop853_solve_into` (imported
  from there): the drivers behind ``simulate`` with their work arrays passed in
  (:func:`~.twopolar_kernels.fixed_solve` / :func:`~.twopolar_kernels.dop853_solve` allocate them and
  call these). ``fail`` (3,) gets a third entry here: the index of the output row at which a failure
  was detected.
* :func:`solve_body`: one body's trajectory into ``Y`` (11, T); rows from the failing one on are NaN.
* :func:`env_step_body`: one body's environment step; :func:`batch_env_step_serial` loops it (the
  environment's batch, ``env_stepper(NAME).batch``). Its parallel twin, which only ``flatbody bench gpu``
  runs, lives with that benchmark (:func:`flatbody_env.bench.kernels.batch_env_step_parallel`).
* :func:`batch_solve` / :func:`batch_energy`: the CPU batch kernels of ``simulate_batch``, parallel over chunks of
  bodies (``numba.prange``).

Layouts: the CPU trajectory kernel writes ``OUT`` (N, T, 11) (one body's rows contiguous); the
environment step takes ``Y``, ``OUT`` (11, N) and ``U`` (4, N) structure-of-arrays, as the env's
kernels do; ``STATUS`` (N,) int64 holds :mod:`.failure`'s codes.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from flatbody_env.integrators.failure import OK
from flatbody_env.integrators.jit import njit, energy_kernel
from flatbody_env.integrators.specs import BATCH_METHODS, BY_NAME, DOP853_KIND, RK4_KIND, SPLIT_KIND
from flatbody_env.integrators.twopolar_kernels import (
    CARRY_K,
    CARRY_Y,
    N,
    STRANG,
    dop853_solve_into,
    env_step_into,
    fixed_solve_into,
)


KIND = {name: (BY_NAME[name].code, BY_NAME[name].coeffs) for name in BATCH_METHODS}
"""Batch methods: name → (kind, composition coefficients), from the method table (:mod:`.specs`)."""

CHUNK = 32
"""Bodies per task of the parallel CPU kernels (work arrays are allocated once per chunk)."""


# --------------------------------------------------------------------------------------------- drivers
@njit
def solve_body(
    b,
    kind,
    coeffs,
    y0,
    times,
    u,
    P,
    h,
    rtol,
    atol,
    energy_tol,
    max_nfev,
    Y,
    STATUS,
    NFEV,
    TFAIL,
    y,
    f,
    K,
    ynew,
    ytmp,
    vel,
    force,
    counters,
    fail,
    carry,
):
    """Body ``b``'s trajectory from ``y0`` (11,) through ``times`` into ``Y`` (11, T) (a view of the batch
    output); STATUS[b], NFEV[b], TFAIL[b] (t of the failure, NaN on success) receive its outcome.
    Rows from the failing one on are NaN: a failed body's state is never returned as physics.
    DOP853: ``carry`` is where the body stands (:func:`~.twopolar_kernels.dop853_solve_into`): zeros start it, a
    body its budget stopped continues with the larger ``max_nfev``, a finished one is left as it is."""
    if kind == DOP853_KIND and carry[CARRY_K] < 0.0:
        return
    counters[0] = 0
    counters[1] = 0
    counters[2] = 0
    counters[3] = max_nfev
    fail[0] = 0.0
    fail[1] = 0.0
    fail[2] = 0.0
    if kind == DOP853_KIND:
        st = dop853_solve_into(
            y0, times, u, P, rtol, atol, energy_tol, Y, counters, fail, y, f, K, ynew, ytmp, vel, force, carry
        )
    else:
        st = fixed_solve_into(kind, coeffs, y0, times, u, P, h, energy_tol, Y, counters, fail, y, K, vel, force)
    STATUS[b] = st
    NFEV[b] = counters[0]
    if st == OK:
        TFAIL[b] = math.nan
    else:
        TFAIL[b] = fail[0]
        for k in range(int(fail[2]), times.size):
            for i in range(N):
                Y[i, k] = math.nan


@njit
def env_step_body(
    b,
    kind,
    coeffs,
    Y,
    U,
    P,
    dt,
    h,
    rtol,
    atol,
    energy_tol,
    OUT,
    STATUS,
    NFEV,
    y,
    u,
    out,
    K,
    ynew,
    ytmp,
    vel,
    force,
    f,
    counters,
):
    """Body ``b``'s environment step: column b of Y (11, N) and U (4, N) → column b of OUT, STATUS[b],
    NFEV[b]; the env step of :func:`~.twopolar_kernels.env_step_into`. ``counters`` (3,) or (4,): the
    first three are reset here; a fourth entry is the step's budget of RHS evaluations (DOP853)."""
    for i in range(N):
        y[i] = Y[i, b]
    for i in range(4):
        u[i] = U[i, b]
    counters[0] = 0
    counters[1] = 0
    counters[2] = 0
    STATUS[b] = env_step_into(
        kind, coeffs, y, u, P, dt, h, rtol, atol, energy_tol, out, K, ynew, ytmp, vel, force, f, counters
    )
    NFEV[b] = counters[0]
    for i in range(N):
        OUT[i, b] = out[i]


# --------------------------------------------------------------------------------------------- CPU batch kernels
@njit(parallel=True)
def batch_solve(
    kind, coeffs, Y0, times, u, P, h, rtol, atol, ENERGY_TOL, max_nfev, OUT, STATUS, NFEV, TFAIL, CARRY=None
):
    """Trajectories of N bodies: Y0 (N, 11) → OUT (N, T, 11), STATUS, NFEV (N,) int64, TFAIL (N,);
    one energy tolerance per body (ENERGY_TOL (N,)); parallel over chunks of :data:`CHUNK` bodies.
    DOP853: ``CARRY`` (N, :func:`~.twopolar_kernels.carry_size`), zeros at first, keeps where each body stands, so
    that a call with a larger ``max_nfev`` continues the bodies their budget stopped (:func:`solve_body`)."""
    n = Y0.shape[0]
    for c in numba.prange((n + CHUNK - 1) // CHUNK):
        y = np.empty(N)
        f = np.empty(N)
        K = np.empty((13, N))
        ynew = np.empty(N)
        ytmp = np.empty(N)
        vel = np.empty(7)
        force = np.empty(4)
        counters = np.zeros(4, np.int64)
        fail = np.zeros(3)
        fresh = np.zeros(CARRY_Y + 2 * N)
        for b in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
            if CARRY is None:
                carry = fresh
                carry[CARRY_K] = 0.0
            else:
                carry = CARRY[b]
            solve_body(
                b,
                kind,
                coeffs,
                Y0[b],
                times,
                u,
                P,
                h,
                rtol,
                atol,
                ENERGY_TOL[b],
                max_nfev,
                OUT[b].T,
                STATUS,
                NFEV,
                TFAIL,
                y,
                f,
                K,
                ynew,
                ytmp,
                vel,
                force,
                counters,
                fail,
                carry,
            )


NO_BUDGET = 2**62
"""``max_nfev`` of the batch env steps when none is given: no budget of evaluations (the DOP853 kernel's
step limit, :data:`~.twopolar_kernels.DOP853_MAX_STEPS`, still applies)."""


@njit
def batch_env_step_range(
    b0, b1, kind, coeffs, Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS, NFEV, max_nfev=NO_BUDGET
):
    """One environment step of the bodies ``b0`` … ``b1 - 1`` of a batch, one after another, with work arrays of its
    own: Y, OUT (11, N), U (4, N), STATUS, NFEV (N,) int64. ``max_nfev``: each body's budget of RHS evaluations in the
    step (DOP853; past it the body's status is the ``budget`` failure, as the scalar env step's)."""
    y = np.empty(N)
    u = np.empty(4)
    out = np.empty(N)
    K = np.empty((13, N))
    ynew = np.empty(N)
    ytmp = np.empty(N)
    vel = np.empty(7)
    force = np.empty(4)
    f = np.empty(N)
    counters = np.zeros(4, np.int64)
    counters[3] = max_nfev  # each body's budget of RHS evaluations (the DOP853 kernel checks it before every step)
    for b in range(b0, b1):
        env_step_body(
            b, kind, coeffs, Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS, NFEV, y, u, out, K, ynew, ytmp, vel,
            force, f, counters,
        )  # fmt: skip


@njit
def batch_env_step_serial(kind, coeffs, Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS, NFEV, max_nfev=NO_BUDGET):
    """One environment step of N bodies in one thread (the environment's compiled loop over bodies): Y, OUT (11, N),
    U (4, N), STATUS, NFEV (N,) int64; :func:`batch_env_step_range` over every body."""
    batch_env_step_range(
        0, Y.shape[1], kind, coeffs, Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS, NFEV, max_nfev
    )


@njit(parallel=True)
def batch_energy(Y0, P, H):
    """H (eq. (41)) of each row of Y0 (N, 11) into H (N,)."""
    n = Y0.shape[0]
    for c in numba.prange((n + CHUNK - 1) // CHUNK):
        vel = np.empty(7)
        force = np.empty(4)
        for b in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
            H[b] = energy_kernel(Y0[b], P, vel, force)


__all__ = [
    "BATCH_METHODS",
    "CHUNK",
    "DOP853_KIND",
    "KIND",
    "NO_BUDGET",
    "RK4_KIND",
    "SPLIT_KIND",
    "STRANG",
    "batch_energy",
    "batch_env_step_range",
    "batch_env_step_serial",
    "batch_solve",
    "env_step_body",
    "solve_body",
]
