"""Compiled kernels that only a benchmark reaches: the parallel CPU env step of ``flatbody bench gpu``.

:func:`batch_env_step_parallel` is the ``cpu-parallel`` row of :mod:`.gpu`: the environment's batch step,
:func:`~flatbody_env.integrators.batch_solve.batch_env_step_serial`, with its loop over bodies spread by
``numba.prange`` over chunks (:func:`~flatbody_env.integrators.batch_solve.batch_env_step_range` each) of :data:`~flatbody_env.integrators.batch_solve.CHUNK` bodies. The library
steps its bodies in one thread (the env's batch) or on the GPU (:mod:`flatbody_env.integrators.cuda`), and
nothing below the bench calls the parallel step, so it lives here, with the benchmark that measures it. It is
compiled as the integrators' kernels are (:func:`flatbody_env.integrators.jit.njit`: their options, the on-disk
cache keyed by the callees' code) and equals the serial step bit for bit (``tests/bench/test_kernels.py``).
"""

from __future__ import annotations

import numba

from flatbody_env.integrators.batch_solve import CHUNK, NO_BUDGET, batch_env_step_range
from flatbody_env.integrators.jit import njit


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
    for c in numba.prange((n + CHUNK - 1) // CHUNK):  # each chunk with work arrays of its own
        batch_env_step_range(
            c * CHUNK, min(n, (c + 1) * CHUNK), kind, coeffs, Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS,
            NFEV, max_nfev,
        )  # fmt: skip


__all__ = ["batch_env_step_parallel"]
