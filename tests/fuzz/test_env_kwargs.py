"""Hostile keywords and actions for every registered task (hypothesis): each keyword of ``gym.make(ID, ...)`` — the
env's own (``FlatBodyEnv``'s signature) and the task's fields (its dataclass) — drawn from hostile JSON-like values,
tuples and arrays, and hostile actions.

Property: ``gym.make`` raises ``ValueError``/``TypeError`` whose message names the keyword, or the env it makes resets
and steps to finite observations in its space and a finite reward (nothing accepted silently and failing later); a
reset that finds no target for settings that are each in range names the settings it depends on. An
action is refused naming ``action``, or steps to finite numbers. The default run draws a few examples per task;
``pytest -m slow tests/fuzz`` draws many.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import flatbody_env  # noqa: F401 - registers the ids
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.registration import TASK_CLASSES, TASK_IDS, task_spec

FAST = settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
SLOW = settings(max_examples=200, deadline=None, suppress_health_check=list(HealthCheck))

numbers = (
    st.floats(allow_nan=True, allow_infinity=True)
    | st.integers(min_value=-(10**400), max_value=10**400)
    | st.sampled_from([0, -1, 1e-300, 1e300, 5e-324, -0.0, 1e6, 1e-6, 2**63])
)
hostile = (
    st.recursive(
        st.none()
        | st.booleans()
        | numbers
        | st.text(max_size=8)
        | st.sampled_from(["V1", "reach", "RK4", "DOP853", "rgb_array", "human"]),
        lambda inner: (
            st.lists(inner, max_size=3)
            | st.tuples(inner, inner)
            | st.dictionaries(st.text(max_size=6), inner, max_size=3)
        ),
        max_leaves=8,
    )
    | st.tuples(numbers, numbers)
    | st.builds(np.array, st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=3))
)


def keywords(env_id: str) -> list[str]:
    """The env's keywords and the fields of the task ``env_id`` makes."""
    own = [p for p in inspect.signature(FlatBodyEnv.__init__).parameters if p not in ("self", "task_kwargs")]
    module, name = TASK_CLASSES[task_spec(env_id).kwargs["task"]].split(":")
    task = getattr(importlib.import_module(module), name)
    return own + [f.name for f in dataclasses.fields(task) if f.init]


def _finite_step(env) -> None:
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs) and np.all(np.isfinite(obs))
    obs, reward, term, trunc, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert env.observation_space.contains(obs) and np.all(np.isfinite(obs)) and math.isfinite(float(reward))


def _make(env_id: str, **kw):
    import gymnasium as gym

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's checker warns about odd spaces; the property is what is asserted
        return gym.make(env_id, **kw)


def _keyword_case(env_id: str, key: str, value) -> None:
    try:
        if (
            key == "render_mode"
        ):  # gym.make reads render_mode itself first (a list ends in its AttributeError): ours is the env's
            env = FlatBodyEnv(**task_spec(env_id).kwargs, render_mode=value)
        else:
            env = _make(env_id, **{key: value})
    except (ValueError, TypeError) as exc:
        assert key in str(exc), (key, repr(value)[:80], str(exc)[:200])
        return
    try:
        _finite_step(env)
    except (ValueError, TypeError) as exc:  # refused at the first reset: settings that together leave no target to draw
        named = [
            k for k in keywords(env_id) if k in str(exc)
        ]  # e.g. a tiny torque_limit: no target settles fast enough
        assert named, (key, repr(value)[:80], str(exc)[:200])
    finally:
        env.close()


@pytest.mark.parametrize("env_id", TASK_IDS)
@FAST
@given(data=st.data())
def test_every_keyword_of_every_task_is_checked(env_id, data):
    key = data.draw(st.sampled_from(keywords(env_id)))
    _keyword_case(env_id, key, data.draw(hostile))


@pytest.mark.slow
@pytest.mark.parametrize("env_id", TASK_IDS)
@SLOW
@given(data=st.data())
def test_every_keyword_of_every_task_is_checked_long(env_id, data):
    key = data.draw(st.sampled_from(keywords(env_id)))
    _keyword_case(env_id, key, data.draw(hostile))


@pytest.fixture(scope="module")
def envs():
    made = {env_id: _make(env_id) for env_id in TASK_IDS}
    yield made
    for env in made.values():
        env.close()


@pytest.mark.parametrize("env_id", TASK_IDS)
@FAST
@given(action=hostile)
def test_hostile_actions_are_refused_or_step_finitely(envs, env_id, action):
    env = envs[env_id]
    env.reset(seed=0)
    try:
        obs, reward, term, trunc, info = env.step(action)
    except (ValueError, TypeError) as exc:
        assert "action" in str(exc), (repr(action)[:80], str(exc)[:200])
        return
    assert np.all(np.isfinite(obs)) and math.isfinite(float(reward))


@FAST
@given(actions=hostile)
def test_hostile_vector_actions_are_refused_or_step_finitely(actions):
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    env = FlatBodyVectorEnv(num_envs=2)
    env.reset(seed=0)
    try:
        obs, reward, term, trunc, info = env.step(actions)
    except ValueError as exc:
        assert str(exc).startswith("actions: "), (repr(actions)[:80], str(exc)[:200])
        return
    finally:
        env.close()
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))


def test_the_keywords_cover_the_signature_and_the_task_fields():
    """The drawn keywords are all of them: a keyword added to the env or a task is drawn too."""
    assert {"dt", "integrator", "stretch_bounds", "gap_min", "render_mode", "body"} <= set(keywords("FlatBody-v0"))
    assert {"target_aspect", "min_settling_rate", "settling_table", "w_shape"} <= set(keywords("FlatBodySlow-v0"))
    assert len(set(keywords("FlatBodyAnyBody-v0"))) > len(set(keywords("FlatBody-v0"))) - 1
