"""Compiled kernels that only a benchmark reaches: the parallel CPU env step of ``flatbody bench gpu``.

:func:`batch_env_step_parallel` is the ``cpu-parallel`` row of :mod:`.gpu`: the environment's batch step,
:func:`~flatbody_env.integrators.batch_solve.batch_env_step_serial`, with its loop over bodies spread by
``numba.prange`` over chunks of :data:`~flatbody_env.integrators.batch_solve.CHUNK` bodies. The library
steps its bodies in one thread (the env's batch) or on the GPU (:mod:`flatbody_env.integrators.cuda`), and
nothing below the bench calls the parallel step, so it lives here, with the benchmark that measures it. It is
compiled as the integrators' kernels are (:func:`flatbody_env.integrators.jit.njit`: their options, the on-disk
cache keyed by the callees' code) and equals the serial step bit for bit (``tests/bench/test_kernels.py``).
"""

from __future__ import annotations

import numba
import numpy as np

from flatbody_env.integrators.batch_solve import CHUNK, NO_BUDGET, env_step_body
from flatbody_env.integrators.jit import njit
from flatbody_env.integrators.twopolar_kernels import N


@njit(parallel=True)
def batch_env_step_parallel(
    kind, coeffs, Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS, NFEV, max_nfev=NO_BUDGET
):
    """One environment step of N bodies: Y, OUT (11, N), U (4, N), STATUS, NFEV (N,) int64; parallel
    over chunks of :data:`~flatbody_env.integrators.batch_solve.CHUNK` bodies. Equal, bit for bit, to
    :func:`~flatbody_env.integrators.batch_solve.batch_env_step_serial`.
    ``max_nfev``: each body's budget of RHS evaluations in the step (DOP853; past it the body's status is
    the ``budget`` failure, as the scalar env step's)."""
    n = Y.shape[1]
    for c in numba.prange((n + CHUNK - 1) // CHUNK):
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
        counters[3] = max_nfev  # each body's budget of RHS evaluations in this step
        for b in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
            env_step_body(
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
            )


__all__ = ["batch_env_step_parallel"]
