"""The benchmark's kernel: the parallel env step of ``flatbody bench gpu`` (``cpu-parallel``) equals the env's batch
step, one thread, bit for bit: states, statuses and RHS counts, with and without a budget of evaluations."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_lanes

from flatbody_env.bench.kernels import batch_env_step_parallel
from flatbody_env.integrators import batch_solve as bs
from flatbody_env.integrators.compiled_methods import env_stepper, kernel_params
from flatbody_env.integrators.failure import KINDS
from flatbody_env.physics import validation
from flatbody_env.physics.body import default_body
from flatbody_env.physics.state import pack
from flatbody_env.scene import load_scene

STEPS = {
    "RK4": 0.02,
    "splitting-strang": 0.01,
    "splitting-suzuki4": 0.04,
    "splitting-yoshida4": 0.02,
    "DOP853-numba": 0.0,
}
BUDGET = KINDS.index("budget")


def _batch():
    """Close-approach shape: regular orbits, the close approach and a fast spinner (fails under fixed steps); N = 40 > CHUNK."""
    scene = load_scene("close-approach")
    rng = np.random.default_rng(11)
    Y0 = np.tile(pack(scene.state), (40, 1))
    Y0[:, :7] += 0.02 * rng.normal(size=(40, 7))
    Y0[::3, 2] += 0.5
    Y0[5, 2] += 6.0
    return scene.body, Y0


def _step(kernel, name, Y, U, P, dt, h, energy_tol, *budget):
    n = Y.shape[1]
    OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
    kernel(*bs.KIND[name], Y, U, P, dt, h, 1e-11, 1e-11, energy_tol, OUT, S, NF, *budget)
    return OUT, S, NF


def _same(a, b):
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("name", list(STEPS))
def test_parallel_env_step_equals_the_env_steppers(name):
    body, Y0 = _batch()
    P = kernel_params(body)
    Ys = np.ascontiguousarray(Y0.T)
    n = Ys.shape[1]
    U = np.zeros((4, n))
    U[:, 1::4] = np.array([0.1, -0.2, 0.05, 0.3])[:, None]
    h = STEPS[name] / 2
    O1, S1, N1 = np.empty_like(Ys), np.zeros(n, np.int64), np.zeros(n, np.int64)
    env_stepper(name).batch_counted(Ys, U, P, 0.05, h, 1e-11, 1e-11, 1e-3, O1, S1, N1)
    O2, S2, N2 = _step(batch_env_step_parallel, name, Ys, U, P, 0.05, h, 1e-3)
    _same((O1, S1, N1), (O2, S2, N2))
    assert (N2 > 0).all()


def test_parallel_env_step_stops_each_body_at_its_budget_as_the_serial():
    """DOP853 with fast lanes (many steps in one env step of 0.5): a budget of 500 evaluations per body stops some."""
    P = kernel_params(default_body())
    Y, U = random_lanes(40, 3)
    Y[4:7, :8] *= 60.0
    Y, U = np.ascontiguousarray(Y), np.ascontiguousarray(U)
    args = ("DOP853-numba", Y, U, P, 0.5, 0.0, np.inf)
    tiny = _step(batch_env_step_parallel, *args, 500)
    _same(tiny, _step(bs.batch_env_step_serial, *args, 500))
    assert (tiny[1] == BUDGET).sum() >= 5 and (tiny[1] == 0).sum() >= 20
    free = _step(batch_env_step_parallel, *args)
    _same(free, _step(bs.batch_env_step_serial, *args))
    assert not (free[1] == BUDGET).any()
    _same(_step(batch_env_step_parallel, *args, validation.ENV_STEP_MAX_NFEV), free)  # an ample budget: bit for bit
