"""``observe_time``: the episode's elapsed time as the observation's last entry (steps / 400), written by the one
transition, so every face gives it alike: the single env, the vector env (both autoreset modes, staggered clocks,
clocks set from outside), ``gym.make_vec`` and the torch env on the CPU; everything else in the observation, and
every law and planner reading it, unchanged bit for bit. (The CUDA kernels under the simulator:
``tests/env/test_transition.py``.)"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flatbody_env  # noqa: F401  (registers the ids)
from flatbody_env.env.registration import MAX_EPISODE_STEPS, task_spec
from flatbody_env.env.vector_env import FlatBodyVectorEnv

CASES = [("FlatBody-v1", {}), ("FlatBodyAnyBody-v1", {"observe_body": True}), ("FlatBodyHoldUnstable-v1", {})]


def _kw(env_id: str, **extra) -> dict:
    return {**task_spec(env_id).kwargs, **extra}


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
@pytest.mark.parametrize(("env_id", "extra"), CASES)
def test_the_time_entry_counts_the_steps_and_leaves_the_rest_unchanged(env_id, extra, mode):
    n, T = 3, 6
    plain = FlatBodyVectorEnv(n, max_episode_steps=T, autoreset_mode=mode, **_kw(env_id, **extra))
    timed = FlatBodyVectorEnv(n, max_episode_steps=T, autoreset_mode=mode, **_kw(env_id, observe_time=True, **extra))
    assert timed.single_observation_space.shape[0] == plain.single_observation_space.shape[0] + 1
    assert timed.single_observation_space.low[-1] == 0.0
    assert timed.single_observation_space.high[-1] == 1_000_000 / MAX_EPISODE_STEPS
    o0, _ = plain.reset(seed=11)
    o1, _ = timed.reset(seed=11)
    np.testing.assert_array_equal(o1[:, :-1], o0)
    assert (o1[:, -1] == 0).all()
    rng = np.random.default_rng(3)
    seen, finals = set(), set()
    for _ in range(2 * T + 3):  # two truncations and their autoresets
        a = rng.uniform(-0.05, 0.05, (n, plain.single_action_space.shape[0]))  # the hold task lasts a few steps
        o0, r0, te0, tr0, i0 = plain.step(a)
        o1, r1, te1, tr1, i1 = timed.step(a)
        np.testing.assert_array_equal(o1[:, :-1], o0)
        np.testing.assert_array_equal(r1, r0)
        np.testing.assert_array_equal(te1 | tr1, te0 | tr0)
        steps = timed.episode_steps
        np.testing.assert_array_equal(o1[:, -1], (steps / MAX_EPISODE_STEPS).astype(np.float32))
        seen.update(steps.tolist())
        if mode == "SameStep" and (tr1 | te1).any():
            ended = tr1 | te1
            final = np.stack([i1["final_obs"][i] for i in np.flatnonzero(ended)])
            assert (o1[ended, -1] == 0).all()  # the next episode's first observation
            finals.update((final[:, -1] * MAX_EPISODE_STEPS).round().tolist())  # the last one's, with its time
            np.testing.assert_array_equal(final[:, :-1], np.stack([i0["final_obs"][i] for i in np.flatnonzero(ended)]))
    if mode == "NextStep":  # the truncation's observation says T, the reset's 0
        assert {0, T} <= seen
    else:  # the autoreset's observation says 0, the final one (in info) T
        assert 0 in seen and T in finals and T not in seen


def test_staggered_and_externally_set_clocks_are_observed():
    env_id = "FlatBody-v1"
    n = 6
    venv = FlatBodyVectorEnv(n, max_episode_steps=400, **_kw(env_id, observe_time=True))
    obs, _ = venv.reset(seed=2, options={"stagger": True})
    steps = venv.episode_steps
    assert steps.max() > 0
    np.testing.assert_array_equal(obs[:, -1], (steps / MAX_EPISODE_STEPS).astype(np.float32))
    venv.set_episode_steps(np.array([0, 1, 7, 100, 250, 399]))
    np.testing.assert_array_equal(  # observed before the next step (the host writes it with the clocks)
        venv.observations[:, -1], np.array([0, 1, 7, 100, 250, 399], dtype=np.float32) / 400
    )
    obs, *_ = venv.step(np.zeros((n, venv.single_action_space.shape[0])))
    np.testing.assert_array_equal(obs[:, -1], np.array([1, 2, 8, 101, 251, 400], dtype=np.float32) / 400)
    # the torch face sets its observation with its clocks
    import torch

    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv

    tenv = FlatBodyTorchVectorEnv(n, device="cpu", max_episode_steps=400, **_kw(env_id, observe_time=True))
    tenv.reset(seed=2)
    tenv.set_episode_steps(torch.tensor([3, 0, 5, 9, 1, 2]))
    np.testing.assert_array_equal(
        tenv.observations[:, -1].numpy(), np.array([3, 0, 5, 9, 1, 2], dtype=np.float32) / 400
    )
    obs, *_ = tenv.step(torch.zeros((n, tenv.single_action_space.shape[0])))
    np.testing.assert_array_equal(obs[:, -1].numpy(), np.array([4, 1, 6, 10, 2, 3], dtype=np.float32) / 400)
    # rsl_rl's adapter: its init_at_random_ep_len sets the clocks, and the policy's first observation says them
    from agents.rsl import RslVecEnv

    adapter = RslVecEnv(
        FlatBodyTorchVectorEnv(n, device="cpu", max_episode_steps=400, **_kw(env_id, observe_time=True))
    )
    adapter.episode_length_buf = torch.tensor([3, 0, 5, 9, 1, 2])
    np.testing.assert_array_equal(
        adapter.get_observations()["policy"][:, -1].numpy(), np.array([3, 0, 5, 9, 1, 2], dtype=np.float32) / 400
    )


@pytest.mark.parametrize(("env_id", "extra"), CASES[:2])
def test_every_face_observes_the_same_time(env_id, extra):
    import torch

    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv

    n, steps = 3, 5
    kw = _kw(env_id, observe_time=True, **extra)
    venv = FlatBodyVectorEnv(n, max_episode_steps=400, **kw)
    made = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point", observe_time=True, **extra)
    tenv = FlatBodyTorchVectorEnv(n, device="cpu", max_episode_steps=400, **kw)
    singles = [gym.make(env_id, observe_time=True, **extra) for _ in range(n)]
    A = np.random.default_rng(0).uniform(-1, 1, (steps, n, venv.single_action_space.shape[0]))
    outs = [np.asarray(e.reset(seed=40)[0]) for e in (venv, made, tenv)]
    outs.append(np.stack([s.reset(seed=40 + i)[0] for i, s in enumerate(singles)]))
    for k in range(steps):
        got = [venv.step(A[k])[0], made.step(A[k])[0], tenv.step(torch.as_tensor(A[k]))[0].numpy()]
        got.append(np.stack([s.step(A[k, i])[0] for i, s in enumerate(singles)]))
        for g in got[1:]:
            np.testing.assert_array_equal(g, got[0])
        np.testing.assert_array_equal(got[0][:, -1], np.float32((k + 1) / 400))
    for s in singles:
        assert s.observation_space.shape == venv.single_observation_space.shape


def test_the_laws_and_the_planner_ignore_the_time():
    from agents.evaluate import run_episodes
    from agents.heuristic import LAWS

    env_id = "FlatBodyAnyBody-v1"
    for extra in ({}, {"observe_body": True}):
        plain = FlatBodyVectorEnv(4, max_episode_steps=400, **_kw(env_id, **extra))
        timed = FlatBodyVectorEnv(4, max_episode_steps=400, **_kw(env_id, observe_time=True, **extra))
        o0, _ = plain.reset(seed=5)
        o1, _ = timed.reset(seed=5, options={"stagger": True})  # another clock, the same states
        proto = gym.make(env_id, **extra).unwrapped
        for name, law in LAWS.items():
            ctl = law(proto.body, proto.control, proto.limits)
            np.testing.assert_array_equal(ctl.act(o1), ctl.act(o0), err_msg=name)
            np.testing.assert_array_equal(ctl.predict(o1[0])[0], ctl.predict(o0[0])[0], err_msg=name)
    settings = {"horizon": 10, "samples": 8, "knots": 2}
    a = run_episodes("planner", episodes=2, seed=10000, env_id="FlatBody-v1", planner=settings)
    b = run_episodes(
        "planner", episodes=2, seed=10000, env_id="FlatBody-v1", planner=settings, env_kwargs={"observe_time": True}
    )
    assert [(x["return"], x["final_distance"]) for x in a] == [(y["return"], y["final_distance"]) for y in b]


def test_observe_time_must_be_a_boolean():
    with pytest.raises(ValueError, match="observe_time"):
        gym.make("FlatBody-v1", observe_time="yes")
    with pytest.raises(ValueError, match="observe_time"):
        FlatBodyVectorEnv(2, **_kw("FlatBody-v1", observe_time=1.5))
