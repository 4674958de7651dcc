"""Bounded work in the environment: dt, the fixed step and its sub-steps, batch sizes, and the per-step
budget of right-hand-side evaluations (docs/reliability.md, "Bounded work")."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flatbody_env  # noqa: F401 - registers the env ids
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.vector_env import FlatBodyVectorEnv
from flatbody_env.physics import validation


@pytest.mark.parametrize(
    "kw,field",
    [
        (dict(dt=1e6), "dt"),
        (dict(dt=1e9), "dt"),
        (dict(dt=0.0), "dt"),
        (dict(dt=float("nan")), "dt"),
        (dict(integrator="RK4", step=1e-12), "step"),
        (dict(integrator="RK4", step=1e-30), "step"),  # a floor, never replaced by dt
        (dict(integrator="RK4", dt=1.0, step=5e-6), "step"),
        (dict(integrator=7), "integrator"),
        (dict(momentum_bound=1e300), "momentum_bound"),
    ],
)
def test_env_settings_beyond_the_bounds_are_refused(kw, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        gym.make("FlatBody-v0", **kw)


@pytest.mark.parametrize(
    "kw,field", [(dict(num_envs=10**9), "num_envs"), (dict(num_envs=2, max_episode_steps=10**12), "max_episode_steps")]
)
def test_vector_env_sizes_are_bounded_before_allocation(kw, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        FlatBodyVectorEnv(**kw)


def test_env_step_carries_the_per_step_budget():
    env = FlatBodyEnv(integrator="DOP853")
    assert env.tolerances.max_nfev == validation.ENV_STEP_MAX_NFEV
    assert env.tolerances.max_wall_time == validation.ENV_STEP_MAX_SECONDS


def test_compiled_step_past_its_nfev_budget_ends_the_episode_with_the_reason():
    env = FlatBodyEnv()
    env.reset(seed=3)
    from flatbody_env.env import transition as tr

    env.core.CFG[tr.X_MAX_NFEV] = (
        0  # no evaluations left: the compiled DOP853 stops inside the step (checked before each step)
    )
    y0 = env.physics_state.copy()
    obs, reward, terminated, truncated, info = env.step(np.zeros(env.action_space.shape))
    assert terminated and info["status"] == 8 and "budget" in env.end_reason(info)
    assert np.array_equal(env.physics_state, y0) and np.all(np.isfinite(obs))


def test_a_resets_work_is_bounded_before_the_first_reset():
    """A witnessed start simulates at most RESET_MAX_STEPS env steps per body (steps × attempts), refused up front
    naming the keyword; the reversed runs of many bodies are drawn a chunk at a time (bounded memory)."""
    from flatbody_env.env.core import HOST_DRAW_CHUNK

    for kw, field in (
        ({"max_witness_attempts": 10**6}, "max_witness_attempts"),
        ({"witness_steps": 10**6}, "witness_steps"),
        ({"witness_steps": 4000, "max_witness_attempts": 100}, "max_witness_attempts"),
    ):
        with pytest.raises(ValueError, match=f"^{field}"):
            FlatBodyEnv(task="reach-witnessed", control="torque", **kw)
    assert validation.RESET_MAX_STEPS >= 400 * 400  # the registered v0 witness (400 steps, 400 attempts) fits
    assert HOST_DRAW_CHUNK <= 4096
