"""``FlatBodyTorchVectorEnv`` on the CPU: Gymnasium's vector-env checks, equality with ``FlatBodyVectorEnv`` for
every task, its contract (action shapes and dtypes, reset before step, closed means closed, booleans), and the episode
clocks and partial resets of both vector envs."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gymnasium.utils.env_checker import data_equivalence  # noqa: E402
from gymnasium.utils.passive_env_checker import check_obs  # noqa: E402
from gymnasium.vector import AutoresetMode  # noqa: E402

from flatbody_env.env.env import FlatBodyEnv  # noqa: E402
from flatbody_env.env.registration import TASK_IDS, task_spec  # noqa: E402
from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv  # noqa: E402
from flatbody_env.env.vector_env import FlatBodyVectorEnv  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore:.*out of date:DeprecationWarning")  # the v0 ids' deprecation


def _np(x):
    if isinstance(x, torch.Tensor):
        return x.numpy()
    if isinstance(x, dict):
        return {k: _np(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_np(v) for v in x]
    return x


def _actions(rng, n, k):
    return rng.uniform(-1, 1, (n, k)).astype(np.float32)


def test_gymnasium_vector_checks():
    """What Gymnasium checks of a vector env: spaces, types, seeded determinism of reset and step, no data reused."""
    n = 3
    env = FlatBodyTorchVectorEnv(n, max_episode_steps=4, **task_spec("FlatBody-v1").kwargs)
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert env.observation_space.shape == (n, 16) and env.action_space.shape == (n, 4)
    obs, info = env.reset(seed=5)
    assert isinstance(obs, torch.Tensor) and obs.dtype == torch.float32 and obs.device.type == "cpu"
    check_obs(obs.numpy(), env.observation_space, "reset")
    obs2, info2 = env.reset(seed=5)
    assert data_equivalence(_np(obs), _np(obs2), exact=True) and data_equivalence(_np(info), _np(info2), exact=True)
    rng = np.random.default_rng(0)
    A = [torch.from_numpy(_actions(rng, n, 4)) for _ in range(6)]
    runs = []
    for _ in range(2):
        env.reset(seed=5)
        steps = [env.step(a) for a in A]
        runs.append(steps)
        o, r, te, tr, inf = steps[-1]
        check_obs(o.numpy(), env.observation_space, "step")
        assert r.dtype == torch.float32 and r.shape == (n,)
        assert te.dtype == torch.bool and tr.dtype == torch.bool and te.shape == tr.shape == (n,)
        assert isinstance(inf["distance"], torch.Tensor) and isinstance(inf["reward_terms"]["success"], torch.Tensor)
        assert isinstance(inf["integrator"]["method"], str)
        assert not np.shares_memory(steps[0][0].numpy(), steps[1][0].numpy())  # returned data not reused
    for s1, s2 in zip(*runs):
        assert data_equivalence(_np(s1), _np(s2), exact=True)
    assert any(s[3].any() for s in runs[0])  # truncations happened (and were reset in the same step)
    end = next(s for s in runs[0] if s[3].any())
    assert end[4]["_final_obs"].equal(end[3] | end[2])
    env.close()


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_equals_the_numpy_vector_env_through_resets(env_id):
    """Step for step, bit for bit, through SAME_STEP autoresets, for every task."""
    n, horizon = 2, 3
    kw = task_spec(env_id).kwargs
    ref = FlatBodyVectorEnv(n, max_episode_steps=horizon, autoreset_mode=AutoresetMode.SAME_STEP, **kw)
    env = FlatBodyTorchVectorEnv(n, max_episode_steps=horizon, **kw)
    o_ref, i_ref = ref.reset(seed=11)
    o, i = env.reset(seed=11)
    np.testing.assert_array_equal(o.numpy(), o_ref)
    assert data_equivalence(_np(i), i_ref, exact=True)
    k = env.single_action_space.shape[0]
    rng = np.random.default_rng(1)
    for _ in range(2 * horizon + 1):
        a = _actions(rng, n, k)
        got = env.step(torch.from_numpy(a))
        want = ref.step(a)
        np.testing.assert_array_equal(got[0].numpy(), want[0])
        np.testing.assert_array_equal(got[1].numpy(), want[1].astype(np.float32))
        np.testing.assert_array_equal(got[2].numpy(), want[2])
        np.testing.assert_array_equal(got[3].numpy(), want[3])
        assert data_equivalence(_np(got[4]), want[4], exact=True)
    np.testing.assert_array_equal(env.states.numpy(), ref.states)


def test_next_step_mode_and_bad_devices():
    env = FlatBodyTorchVectorEnv(2, max_episode_steps=2, autoreset_mode=AutoresetMode.NEXT_STEP)
    ref = FlatBodyVectorEnv(2, max_episode_steps=2)
    env.reset(seed=3)
    ref.reset(seed=3)
    for _ in range(4):
        got, want = env.step(torch.zeros(2, 4)), ref.step(np.zeros((2, 4)))
        np.testing.assert_array_equal(got[0].numpy(), want[0])
        np.testing.assert_array_equal(got[3].numpy(), want[3])
    if (
        not torch.cuda.is_available()
    ):  # one clear error without a GPU (docs/gpu.md); with one: tests/env/test_device_env.py
        from flatbody_env.integrators.cuda import CudaUnavailableError

        with pytest.raises(CudaUnavailableError, match="device: 'cuda' needs a CUDA GPU"):
            FlatBodyTorchVectorEnv(2, device="cuda")
    with pytest.raises(ValueError, match="device"):
        FlatBodyTorchVectorEnv(2, device="meta")


@pytest.mark.parametrize("cls", [FlatBodyVectorEnv, FlatBodyTorchVectorEnv])
def test_stagger_spreads_the_clocks_and_keeps_the_draws(cls):
    n, horizon = 64, 10
    env = cls(n, max_episode_steps=horizon)
    o_plain, _ = env.reset(seed=0)
    o, info = env.reset(seed=0, options={"stagger": True})
    np.testing.assert_array_equal(np.asarray(o), np.asarray(o_plain))  # the same episodes
    steps = np.asarray(env.episode_steps)
    assert steps.min() >= 0 and steps.max() < horizon and len(np.unique(steps)) > 5
    np.testing.assert_allclose(np.asarray(info["t"]), steps * env.dt)
    env.reset(seed=0, options={"stagger": True})
    np.testing.assert_array_equal(np.asarray(env.episode_steps), steps)  # seeded
    first = np.full(n, -1)
    for k in range(horizon):
        trunc = np.asarray(env.step(np.zeros((n, 4), np.float32))[3])
        first[(first < 0) & trunc] = k + 1
    np.testing.assert_array_equal(first, horizon - steps)  # each truncates when its own clock runs out
    env.set_episode_steps(np.zeros(n, dtype=np.int64))
    assert not np.asarray(env.episode_steps).any()
    with pytest.raises(ValueError, match="steps"):
        env.set_episode_steps(np.full(n, horizon))


@pytest.mark.parametrize("cls", [FlatBodyVectorEnv, FlatBodyTorchVectorEnv])
def test_reset_mask_resets_those_bodies_only(cls):
    n = 4
    env = cls(n, max_episode_steps=50)
    env.reset(seed=0)
    for _ in range(3):
        obs_before = np.asarray(env.step(np.full((n, 4), 0.3, np.float32))[0]).copy()
    states = np.asarray(env.states).copy()
    mask = np.array([False, True, False, True])
    obs, info = env.reset(
        seed=100, options={"reset_mask": torch.from_numpy(mask) if cls is FlatBodyTorchVectorEnv else mask}
    )
    obs = np.asarray(obs)
    np.testing.assert_array_equal(obs[~mask], obs_before[~mask])
    np.testing.assert_array_equal(np.asarray(env.states)[~mask], states[~mask])
    np.testing.assert_array_equal(np.asarray(env.episode_steps), [3, 0, 3, 0])
    for i in np.flatnonzero(mask).tolist():  # as a single env reset with seed + i
        o, inf = FlatBodyEnv().reset(seed=100 + i)
        np.testing.assert_array_equal(obs[i], o)
        assert float(info["distance"][i]) == inf["distance"]
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": np.ones(n - 1, bool)})


def test_the_torch_env_contract():
    """Exact action shapes (a transposed or reshaped batch is refused, never reinterpreted), real floating dtypes
    (float16 and bfloat16 accepted, integers, booleans and complex refused naming actions), reset before step, closed
    means closed, booleans that are booleans; out-of-range actions are clipped (docs/reliability.md)."""
    env = FlatBodyTorchVectorEnv(4, **task_spec("FlatBody-v1").kwargs)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(torch.zeros(4, 4))
    env.reset(seed=0)
    for bad in (
        torch.zeros(4, 3),
        torch.zeros(3, 4).T.contiguous().T,
        torch.zeros(16),
        torch.zeros(2, 2, 2, 2),
        torch.zeros(4, 1),
    ):
        if tuple(bad.shape) == (4, 4):
            continue
        with pytest.raises(ValueError, match="^actions: must have shape"):
            env.step(bad)
    for dtype in (torch.int64, torch.bool, torch.complex64):
        with pytest.raises(ValueError, match="^actions: must have a real floating dtype"):
            env.step(torch.zeros(4, 4, dtype=dtype))
    ref = FlatBodyTorchVectorEnv(4, **task_spec("FlatBody-v1").kwargs)
    ref.reset(seed=0)
    half = env.step(torch.full((4, 4), 0.5, dtype=torch.bfloat16))
    full = ref.step(torch.full((4, 4), 0.5, dtype=torch.float64))
    np.testing.assert_array_equal(half[0].numpy(), full[0].numpy())  # 0.5 is exact in bfloat16
    big = env.step(torch.full((4, 4), 7.0))  # clipped to 1
    one = ref.step(torch.ones(4, 4))
    np.testing.assert_array_equal(big[0].numpy(), one[0].numpy())
    with pytest.raises(ValueError, match="^actions: must be .*finite"):
        env.step(torch.full((4, 4), float("nan")))
    with pytest.raises(ValueError, match="^options.stagger"):
        env.reset(options={"stagger": "no"})
    env.close()
    for call in (lambda: env.step(torch.zeros(4, 4)), lambda: env.reset(seed=0), lambda: env.states):
        with pytest.raises(RuntimeError, match="closed"):
            call()


def test_make_vec_takes_a_device():
    import gymnasium as gym

    env = gym.make_vec("FlatBody-v1", 2, vectorization_mode="vector_entry_point", device="cpu")
    assert isinstance(env, FlatBodyTorchVectorEnv)
    obs, _ = env.reset(seed=3)
    ref = gym.make_vec("FlatBody-v1", 2, vectorization_mode="vector_entry_point")
    np.testing.assert_array_equal(obs.numpy(), ref.reset(seed=3)[0])
