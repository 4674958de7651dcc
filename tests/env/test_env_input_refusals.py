"""The held-out API cases of every face (``gym.make`` of a v1 and a v0 id, :class:`FlatBodyVectorEnv`,
:class:`FlatBodyTorchVectorEnv` on the CPU): a wrong-shaped, complex or boolean action, bad ``reset`` options and a
negative ``max_episode_steps`` are refused with a one-line ``ValueError`` naming the argument or the field —
never accepted, never another exception."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import flatbody_env  # noqa: F401 - registers the ids
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.vector_env import FlatBodyVectorEnv

N = 3


def _single(env_id: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(env_id)
    env.reset(seed=0)
    return env


def _faces():
    yield "FlatBody-v1", _single("FlatBody-v1")
    yield "FlatBody-v0", _single("FlatBody-v0")
    venv = FlatBodyVectorEnv(num_envs=N)
    venv.reset(seed=0)
    yield "vector", venv
    try:
        from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv
    except ImportError:  # no torch: the torch face's cases are skipped
        return

    tenv = FlatBodyTorchVectorEnv(num_envs=N, device="cpu")
    tenv.reset(seed=0)
    yield "torch", tenv


@pytest.fixture(scope="module")
def faces():
    made = dict(_faces())
    yield made
    for env in made.values():
        env.close()


def _refused(call, field: str) -> str:
    with pytest.raises(ValueError) as info:
        call()
    text = str(info.value)
    assert text.startswith(f"{field}: ") and "\n" not in text, text
    return text


@pytest.mark.parametrize("env_id", ["FlatBody-v1", "FlatBody-v0"])
@pytest.mark.parametrize(
    "make",
    [
        lambda n: np.zeros((n, 1)),
        lambda n: np.zeros((1, n)),  # a batch of one is not the single env's action
        lambda n: np.zeros((1, 1, n)),
        lambda n: np.zeros(n + 1),
        lambda n: np.zeros(n, dtype=complex),
        lambda n: np.full(n, 0.1 + 0.2j),
        lambda n: np.zeros(n, dtype=bool),
        lambda n: [True] * n,
    ],
)
def test_single_env_refuses_wrong_shapes_complex_and_bool_actions(faces, env_id, make):
    env = faces[env_id]
    n = env.action_space.shape[0]
    _refused(lambda: env.step(make(n)), "action")
    env.step(np.zeros(n))  # the env still steps (the refused action moved nothing)


@pytest.mark.parametrize("face", ["vector", "torch"])
@pytest.mark.parametrize(
    "make",
    [
        lambda n: np.zeros((N, n, 1)),
        lambda n: np.zeros((n, N)),  # transposed
        lambda n: np.zeros((1, N, n)),
        lambda n: np.zeros(n),
        lambda n: np.zeros((N, n), dtype=complex),
        lambda n: np.zeros((N, n), dtype=bool),
    ],
)
def test_vector_faces_refuse_wrong_shapes_complex_and_bool_actions(faces, face, make):
    env = faces.get(face)
    if env is None:
        pytest.skip("torch is not installed")
    n = env.single_action_space.shape[0]
    actions = make(n)
    if face == "torch":
        import torch

        actions = torch.as_tensor(actions)
    _refused(lambda: env.step(actions), "actions")


@pytest.mark.parametrize("face", ["FlatBody-v1", "FlatBody-v0", "vector", "torch"])
@pytest.mark.parametrize(
    "options, field",
    [
        ({"target": {"lambda": -1.0, "mu": 0.5}}, "options.target.lambda"),
        ({"target": {"lambda": "x", "mu": 0.5}}, "options.target.lambda"),
        ({"target": {"lambda": 2.0, "mu": float("nan")}}, "options.target.mu"),
        ({"target": {"lambda": 1.5, "mu": 1.5}}, "options.target.mu"),  # λ = μ: no ellipse
        ({"target": {"lambda": 2.0, "mu": 1.0, "rho": "x"}}, "options.target.rho"),  # was ignored silently
        ({"target": {"lambda": 2.0, "mu": 1.0, "s3": float("inf")}}, "options.target.s3"),
        ({"target": {"lambda": 1e5, "mu": 1e-5}}, "options.target"),  # was a ZeroDivisionError
        ({"target": {"lam": 1.0}}, "options.target.lam"),
        ({"target": 5}, "options.target"),
        ("target", "options"),  # was "dictionary update sequence element ..." on the vector faces
    ],
)
def test_bad_reset_options_name_the_field(faces, face, options, field):
    env = faces.get(face)
    if env is None:
        pytest.skip("torch is not installed")
    _refused(lambda: env.reset(seed=0, options=options), field)
    env.reset(seed=0, options={"target": {"lambda": 2.0, "mu": 1.0}})  # a good target still resets


def test_negative_max_episode_steps_is_refused_naming_it():
    pytest.importorskip("torch")
    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv

    _refused(lambda: FlatBodyVectorEnv(num_envs=2, max_episode_steps=-1), "max_episode_steps")
    _refused(lambda: FlatBodyTorchVectorEnv(num_envs=2, device="cpu", max_episode_steps=-1), "max_episode_steps")
    _refused(
        lambda: gym.make_vec("FlatBody-v1", 2, vectorization_mode="vector_entry_point", max_episode_steps=-1),
        "max_episode_steps",
    )
    # the single env has no such keyword (gym.make's TimeLimit holds the episode length): named, with where it goes
    text = _refused(lambda: FlatBodyEnv(max_episode_steps=-1), "max_episode_steps")
    assert "gym.make" in text
    with pytest.raises(ValueError, match=r"max_episode_steps.*positive"):
        gym.make("FlatBody-v1", max_episode_steps=0)  # gymnasium's own check (-1 is its documented "no TimeLimit")
    text = _refused(lambda: FlatBodyEnv(bogus=1), "bogus")
    assert "min_settling_rate" in text  # the allowed fields are listed
