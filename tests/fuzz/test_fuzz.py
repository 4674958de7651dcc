"""Fuzzing (hypothesis): hostile scene/body/trajectory JSON, CLI argument vectors and env reset options.

Properties: the CLI exits with 0, 1 or 2, prints no traceback, at most a few lines on error, stops
within a per-case time limit and never prints NaN in a successful JSON output; the Python API
raises ``ValueError`` (or ``IntegrationError``) naming the field, or returns finite numbers.
The default run tries a bounded number of examples; ``pytest -m slow tests/fuzz`` runs more.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))
import hostile  # noqa: E402

from flatbody_env.integrators import IntegrationError  # noqa: E402
from flatbody_env.physics.state import STATE_NAMES  # noqa: E402
from flatbody_env.scene import scene_from_dict  # noqa: E402
from flatbody_env.simulation import Trajectory, simulate  # noqa: E402

FAST = settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
SLOW = settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
LIMIT_S = 30.0

json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**400), max_value=10**400)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8)
    | st.sampled_from([1e308, 1e-308, -1e-308, 5e-324, 1e6, 1e-6, "V1", "V2", "V3"]),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)


@pytest.fixture(scope="module")
def case_list(tmp_path_factory):
    return hostile.cases(tmp_path_factory.mktemp("probe"))


def _check_cli(result):
    assert result["outcome"] == "exit", result
    assert result["code"] in (0, 1, 2), result
    assert not result["nan"], result
    assert result["err_lines"] <= 3, result


@FAST
@given(index=st.integers(min_value=0, max_value=10**6))
def test_cli_hostile_inputs(case_list, index):
    _check_cli(hostile.run_case(case_list[index % len(case_list)], LIMIT_S))


@pytest.mark.slow
@SLOW
@given(index=st.integers(min_value=0, max_value=10**6))
def test_cli_hostile_inputs_long(case_list, index):
    _check_cli(hostile.run_case(case_list[index % len(case_list)], LIMIT_S))


FLAGS = [
    "--t-end",
    "--times",
    "--samples",
    "--rtol",
    "--atol",
    "--step",
    "--method",
    "--model",
    "--max-nfev",
    "--max-seconds",
]


@FAST
@given(flag=st.sampled_from(FLAGS), text=st.text(max_size=12) | st.sampled_from(hostile.BAD_TEXT))
def test_cli_simulate_argument_vectors(flag, text):
    if text.startswith("-"):
        text = " " + text  # argparse reads a leading '-' as a flag; keep the value a value
    _check_cli(hostile.run_case(["simulate", "--scene", "default", "--t-end", "0.3", flag, text], LIMIT_S))


def _scene_with(path, value):
    data = hostile.base_scene()
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return data


def _api_outcome(data):
    try:
        scene = scene_from_dict(data)
    except ValueError as exc:
        assert str(exc).split(":")[0], exc  # names a field
        return
    try:
        traj = simulate(scene, t_end=min(scene.t_end, 0.5), times=[0.25, 0.5], max_wall_time=5.0)
    except (ValueError, IntegrationError):
        return
    assert np.all(np.isfinite(traj.y)) and np.all(np.isfinite(traj.energy))


@FAST
@given(path=st.sampled_from(hostile.SCENE_FIELDS), value=json_values)
def test_scene_and_body_json(path, value):
    _api_outcome(_scene_with(path, value))


@pytest.mark.slow
@SLOW
@given(path=st.sampled_from(hostile.SCENE_FIELDS), value=json_values)
def test_scene_and_body_json_long(path, value):
    _api_outcome(_scene_with(path, value))


def _traj_outcome(change):
    good = {"t": [0.0, 1.0], "state": {n: [1.0, 1.5] for n in STATE_NAMES}, "energy": [1.0, 1.0]}
    data = {**good, **change}
    try:
        traj = Trajectory.from_dict(data)
    except ValueError as exc:
        assert str(exc).startswith("trajectory"), exc
        return
    assert np.all(np.isfinite(traj.t)) and np.all(np.isfinite(traj.y))


@FAST
@given(
    change=st.dictionaries(
        st.sampled_from(["t", "state", "energy", "rotation", "meta", "initial_state", "x"]), json_values, max_size=3
    )
)
def test_trajectory_json(change):
    _traj_outcome(change)


@pytest.fixture(scope="module")
def env():
    import gymnasium as gym

    import flatbody_env  # noqa: F401  (registers FlatBody-v0)

    e = gym.make("FlatBody-v0")
    yield e
    e.close()


option_values = st.dictionaries(
    st.sampled_from(["target", "state", "x"]),
    json_values
    | st.fixed_dictionaries({"lambda": json_values, "mu": json_values})
    | st.fixed_dictionaries({n: st.floats(min_value=-2.0, max_value=2.0) for n in STATE_NAMES}),
    max_size=2,
)


@FAST
@given(options=option_values | json_values)
def test_env_reset_options(env, options):
    try:
        obs, info = env.reset(seed=0, options=options)
    except ValueError as exc:
        assert str(exc).startswith("options"), exc
        return
    assert np.all(np.isfinite(obs)) and env.observation_space.contains(obs)
    assert all(not (isinstance(v, float) and math.isnan(v)) for v in info.values())
    json.dumps({k: v for k, v in info.items() if isinstance(v, (int, float, str, bool))})
