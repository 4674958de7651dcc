"""Episodes that carry R (rendering, recording) run the integrator they asked for, compiled."""

from __future__ import annotations

import numpy as np
import pytest

from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.integrators import Tolerances, get_method


@pytest.mark.parametrize(
    "kwargs", [{}, {"integrator": "RK4", "step": 0.01}, {"integrator": "splitting-suzuki4", "step": 0.01}]
)
def test_tracked_episode_equals_the_untracked_one_and_R_is_the_reference(kwargs):
    tracked = FlatBodyEnv(track_rotation=True, **kwargs)
    plain = FlatBodyEnv(**kwargs)
    assert tracked.stepping_integrator == plain.stepping_integrator == tracked.integrator
    assert tracked.stepper.compiled and tracked.stepper.carries_rotation
    tracked.reset(seed=4)
    plain.reset(seed=4)
    rng = np.random.default_rng(0)
    ref_tol = Tolerances(rtol=1e-13, atol=1e-13)
    worst = 0.0
    for _k in range(60):
        a = rng.uniform(-1, 1, tracked.action_space.shape).astype(np.float32)
        y0, R0 = tracked.physics_state, tracked.rotation
        _, u = tracked.controls(a)
        o1, r1, t1, _, i1 = tracked.step(a)
        o2, r2, t2, _, i2 = plain.step(a)
        assert np.array_equal(o1, o2) and r1 == r2 and t1 == t2 and i1 == i2
        assert np.array_equal(tracked.physics_state, plain.physics_state)
        # R against scipy's DOP853 at 1e-13 on (y, R), restarted from the same state and R
        sol = get_method("DOP853").integrate(
            tracked.body, y0, np.array([0.0, tracked.dt]), tol=ref_tol, u=u, R0=R0, with_rotation=True
        )
        worst = max(worst, float(np.max(np.abs(tracked.rotation - sol.rotation[-1]))))
        if t1:
            break
    assert worst < (1e-10 if not kwargs else 1e-7), worst
    R = tracked.rotation
    assert np.max(np.abs(R @ R.T - np.eye(3))) < 1e-10
