"""The allocation-free drivers and the parallel CPU batch kernels equal the kernels behind simulate, bit for bit;
next_up equals np.nextafter bit for bit (the parallel env step, a benchmark's kernel: tests/bench/test_kernels.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatbody_env.integrators import batch_solve as bs
from flatbody_env.integrators import twopolar_kernels as tk
from flatbody_env.integrators.compiled_methods import kernel_params
from flatbody_env.physics.state import pack
from flatbody_env.scene import load_scene

STEPS = {
    "RK4": 0.02,
    "splitting-strang": 0.01,
    "splitting-suzuki4": 0.04,
    "splitting-yoshida4": 0.02,
    "DOP853-numba": 0.0,
}


def _batch():
    """Close-approach shape: regular orbits, the close approach and a fast spinner (fails under fixed steps); N = 40 > CHUNK."""
    scene = load_scene("close-approach")
    rng = np.random.default_rng(11)
    Y0 = np.tile(pack(scene.state), (40, 1))
    Y0[:, :7] += 0.02 * rng.normal(size=(40, 7))
    Y0[::3, 2] += 0.5
    Y0[5, 2] += 6.0
    return scene.body, Y0


def test_next_up_is_nextafter_bit_for_bit():
    rng = np.random.default_rng(0)
    vals = [
        0.0,
        -0.0,
        5e-324,
        -5e-324,
        1e-310,
        -1e-310,
        2.0**-1022,
        -(2.0**-1022),
        0.5,
        -0.5,
        1.0,
        -1.0,
        0.05,
        1e300,
        1.7976931348623157e308,
        -1.7976931348623157e308,
        math.inf,
        -math.inf,
    ]
    vals += (
        list(rng.uniform(-10, 10, 500))
        + list(np.exp(rng.uniform(-745, 709, 500)))
        + list(-np.exp(rng.uniform(-745, 709, 500)))
    )
    with np.errstate(over="ignore"):
        expected = [np.nextafter(v, np.inf).tobytes() for v in vals]
    for f in (tk.next_up, tk.next_up.py_func):  # compiled and plain Python (what the CUDA target compiles)
        assert [np.float64(f(v)).tobytes() for v in vals] == expected
    assert math.isnan(tk.next_up(math.nan))


def test_initial_step_into_equals_the_allocating_wrapper():
    body, Y0 = _batch()
    P = kernel_params(body)
    u = np.zeros(4)
    for y in Y0[:5]:
        f = np.empty(11)
        tk.rhs_compiled(y, u, P, f)
        c1, c2 = np.zeros(3, np.int64), np.zeros(3, np.int64)
        h1 = tk.dop853_initial_step(y, f, 0.0, 1.0, u, P, 1e-9, 1e-9, np.empty(7), np.empty(4), np.empty(11), c1)
        h2 = tk.dop853_initial_step_into(
            y, f, 0.0, 1.0, u, P, 1e-9, 1e-9, np.empty(7), np.empty(4), np.empty(11), np.empty(11), c2
        )
        assert h1 == h2 and h1 > 0 and (c1 == c2).all()


@pytest.mark.parametrize("name", list(STEPS))
def test_batch_solve_equals_the_solvers_behind_simulate(name):
    """States bit for bit up to a failure, NaN from the failing row on, the same status, nfev and failure time."""
    body, Y0 = _batch()
    P = kernel_params(body)
    kind, coeffs = bs.KIND[name]
    times = np.array([0.0, 0.3, 0.6, 0.9])
    u = np.zeros(4)
    n = Y0.shape[0]
    OUT = np.empty((n, times.size, 11))
    ST, NF, TF = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n)
    bs.batch_solve(kind, coeffs, Y0, times, u, P, STEPS[name], 1e-10, 1e-10, np.full(n, 1e-2), 10**7, OUT, ST, NF, TF)
    failed = 0
    for b in range(n):
        Y = np.empty((11, times.size))
        counters, fail = np.array([0, 0, 0, 10**7], np.int64), np.zeros(2)
        if kind == bs.DOP853_KIND:
            st = tk.dop853_solve(Y0[b], times, u, P, 1e-10, 1e-10, 1e-2, Y, counters, fail)
        else:
            st = tk.fixed_solve(kind, coeffs, Y0[b], times, u, P, STEPS[name], 1e-2, Y, counters, fail)
        assert ST[b] == st and NF[b] == counters[0]
        if st == 0:
            np.testing.assert_array_equal(OUT[b], Y.T)
            assert math.isnan(TF[b])
        else:
            failed += 1
            assert TF[b] == fail[0]
            bad = np.isnan(OUT[b]).all(axis=1)
            k = int(np.argmax(bad))
            assert bad[k:].all() and not bad[:k].any() and k >= 1
            np.testing.assert_array_equal(OUT[b, :k], Y.T[:k])
    if kind != bs.DOP853_KIND:
        assert 0 < failed < n  # both paths ran


def test_batch_energy_equals_the_energy_kernel():
    body, Y0 = _batch()
    P = kernel_params(body)
    H = np.empty(Y0.shape[0])
    bs.batch_energy(Y0, P, H)
    from flatbody_env.integrators.jit import energy_kernel

    assert [energy_kernel(y, P, np.empty(7), np.empty(4)) for y in Y0] == H.tolist()
