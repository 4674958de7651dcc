"""flatbody_env.integrators.libm: exp, log, expm1 and arctan2 are the C library's (``math``'s), bit for bit, whatever
vector code NumPy would take on this processor — so the planner, the observed angle and exported policies steer alike on
every x86-64 machine."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatbody_env.integrators import libm


@pytest.mark.parametrize(
    ("name", "low", "high"),
    [("exp", -700.0, 700.0), ("exp", -30.0, 5.0), ("log", 1e-300, 1e300), ("log", 1e-6, 20.0), ("expm1", -40.0, 5.0)],
)
def test_each_function_is_the_c_librarys_bit_for_bit(name, low, high):
    rng = np.random.default_rng(len(name) + int(high))
    x = rng.uniform(low, high, 50_000) if high < 1e3 else np.exp(rng.uniform(math.log(low), math.log(high), 50_000))
    x = np.concatenate([x, [0.0, -0.0, 1.0, 1e-320, 709.7, -745.0]]) if name != "log" else x
    got = getattr(libm, name)(x)
    want = np.array([getattr(math, name)(v) for v in x])
    assert got.dtype == np.float64 and got.tobytes() == want.tobytes()


def test_arctan2_is_the_c_librarys_bit_for_bit_and_the_observed_angle_uses_it():
    from flatbody_env.env.task import state_from_observation

    rng = np.random.default_rng(5)
    y, x = rng.uniform(-1.0, 1.0, (2, 50_000)).astype(np.float32).astype(np.float64)  # as an observation holds them
    y[:4], x[:4] = [0.0, -0.0, 1.0, -1.0], [-1.0, -1.0, 0.0, -0.0]
    want = np.array([math.atan2(a, b) for a, b in zip(y, x)])
    assert libm.arctan2(y, x).tobytes() == want.tobytes()
    obs = np.zeros((y.size, 16))
    obs[:, 10], obs[:, 11] = y, x
    assert state_from_observation(obs)[0][10].tobytes() == want.tobytes()
    assert state_from_observation(obs[7])[0][10] == want[7]


def test_edges_follow_the_c_library():
    assert libm.log(np.array([0.0]))[0] == -math.inf
    assert np.isnan(libm.log(np.array([-1.0, np.nan]))).all()
    assert libm.exp(np.array([1e4]))[0] == math.inf and libm.exp(np.array([-1e4]))[0] == 0.0
    assert np.isnan(libm.exp(np.array([np.nan])))[0]
    assert libm.expm1(np.array([-1e4]))[0] == -1.0
