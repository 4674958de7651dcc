"""FlatBody-v1 (and the v0 ids kept bit for bit) and FlatBodyVectorEnv: API checks, reward terms, determinism,
failures, batching."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import flatbody_env  # noqa: F401  (registers the ids)
from flatbody_env.env.core import EnvCore
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.task import CONTROLS
from oracles import documented_reward_terms

pytestmark = pytest.mark.filterwarnings("ignore:.*out of date:DeprecationWarning")  # the v0 ids' deprecation
V1 = {"reward": "tolerance", "draws": "philox"}


def _with_stepper(env: FlatBodyEnv, stepper) -> FlatBodyEnv:
    """``env`` stepping through ``stepper`` (a stepper of the seam's interface) instead of its own."""
    import dataclasses

    env.config = dataclasses.replace(env.config, stepper=stepper)
    env.core = EnvCore(env.config, 1)
    env.core.action_field = "action"
    return env


@pytest.mark.parametrize("control", CONTROLS)
def test_env_checkers_pass_without_warnings(control):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make("FlatBody-v1", control=control).unwrapped, skip_render_check=True)
        sb3_check_env(FlatBodyEnv(control=control, **V1))


def test_render_rgb_array():
    env = gym.make("FlatBody-v1", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.shape == (256, 256, 3) and frame.dtype == np.uint8
    assert frame.std() > 5  # something is drawn
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make("FlatBody-v1", render_mode="rgb_array").unwrapped)


def test_registered_through_module_prefix():
    env = gym.make("flatbody_env:FlatBody-v1")
    assert env.spec.max_episode_steps == 400
    assert isinstance(env.unwrapped, FlatBodyEnv)


def _rollout(env, seed, n=60):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [obs]
    rewards = []
    u = env.unwrapped
    for _ in range(n):
        a = env.action_space.sample()
        obs, r, term, trunc, info = env.step(a)
        out.append(obs)
        rewards.append(r)
        # each term and the reward from docs/env.md's formulas on the state after the step (tests/oracles.py, not the env's kernels)
        expect = {
            k: float(v[0])
            for k, v in documented_reward_terms(u.physics_state, u.target_vector, a, term, u.body).items()
        }
        assert list(info["reward_terms"]) == list(expect)
        for name, value in expect.items():
            assert info["reward_terms"][name] == pytest.approx(value, rel=1e-11, abs=1e-12), name
        assert r == pytest.approx(sum(expect.values()), rel=1e-11, abs=1e-12)
        if term or trunc:
            break
    return np.array(out), np.array(rewards)


def test_identical_rollouts_under_identical_seeds():
    a = _rollout(gym.make("FlatBody-v0"), 5)
    b = _rollout(gym.make("FlatBody-v0"), 5)
    c = _rollout(gym.make("FlatBody-v0"), 6)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0][0], c[0][0])


def test_pickles_mid_episode():
    env = gym.make("FlatBody-v0")
    env.reset(seed=1)
    for _ in range(5):
        env.step(np.full(4, 0.3, dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(5):
        a = np.array([0.1, -0.2, 0.3, 0.4], dtype=np.float32)
        o1 = env.step(a)[0]
        o2 = clone.step(a)[0]
        np.testing.assert_array_equal(o1, o2)


def test_controls_respect_conservation_laws():
    """Torque only: p_θ conserved, |s| free; dilatation only: p_θ and |s|² conserved (task docstring)."""
    env = FlatBodyEnv(control="torque")
    env.reset(seed=2)
    pt0, c0 = env.state["p_theta"], env.state["s1"] ** 2 + env.state["s2"] ** 2 + env.state["s3"] ** 2
    for _ in range(40):
        _, _, _, _, info = env.step(np.array([0.5, -0.5, 1.0], dtype=np.float32))
    assert info["p_theta"] == pytest.approx(pt0, abs=1e-12)
    assert abs(info["casimir"] - c0) > 1e-2
    env = FlatBodyEnv(control="dilatation")
    env.reset(seed=2)
    pt0 = env.state["p_theta"]
    target_s3 = env.target["s3"]
    c0 = env.state["s1"] ** 2 + env.state["s2"] ** 2 + env.state["s3"] ** 2
    assert c0 == pytest.approx(target_s3**2, rel=1e-12)  # the target lies on the reachable sphere
    for _ in range(40):
        _, _, _, _, info = env.step(np.array([1.0], dtype=np.float32))
    assert info["p_theta"] == pytest.approx(pt0, abs=1e-12)
    assert info["casimir"] == pytest.approx(c0, rel=1e-9)


def test_holding_the_target_is_success():
    env = FlatBodyEnv()
    env.reset(seed=0, options={"target": {"lambda": 1.5, "mu": 0.9}})
    target = env.target
    state = {
        "s1": 0.0,
        "s2": 0.0,
        "s3": target["s3"],
        "p_theta": target["p_theta"],
        "p_lambda": 0.0,
        "p_mu": 0.0,
        "p_rho": 0.0,
        "lambda": target["lambda"],
        "mu": target["mu"],
        "rho": target["rho"],
        "theta": 0.3,
    }
    _, info = env.reset(seed=0, options={"target": {"lambda": 1.5, "mu": 0.9}, "state": state})
    assert info["is_success"] and info["distance"] < 1e-12
    for _ in range(100):
        _, r, term, _, info = env.step(np.zeros(4, dtype=np.float32))
    assert not term and info["is_success"] and info["distance"] < 1e-8 and r > -1e-7


@pytest.mark.parametrize(
    "env_id", ["FlatBody-v1", "FlatBodyHoldUnstable-v1", "FlatBodyTorque-v1", "FlatBodyAnyBody-v1"]
)
def test_a_given_state_keeps_the_seed_s_target_and_body(env_id):
    """reset(seed=s, options={"state": ...}) on a v1 id: the given state, with the target and body of the seed's own
    episode (what reset(seed=s) draws), on the single env and on a body of the vector env alike; a state outside the
    domain is refused before anything is drawn."""
    from flatbody_env.env.registration import task_spec
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    kwargs = task_spec(env_id).kwargs
    env = FlatBodyEnv(**kwargs)
    env.reset(seed=11)
    drawn_target, drawn_body, state = env.target_vector, env.kernel_params, dict(env.state, theta=0.25, p_lambda=0.01)
    env.reset(seed=99)
    obs, _ = env.reset(seed=11, options={"state": state})
    assert env.state == state
    np.testing.assert_array_equal(env.target_vector, drawn_target)
    np.testing.assert_array_equal(env.kernel_params, drawn_body)
    np.testing.assert_array_equal(obs[12:16], drawn_target.astype(np.float32))
    before = env.physics_state
    with pytest.raises(ValueError, match=r"^options\.state: the initial state starts outside the domain"):
        env.reset(seed=12, options={"state": dict(state, rho=0.05)})
    np.testing.assert_array_equal(env.physics_state, before)  # refused before anything was drawn or written
    np.testing.assert_array_equal(env.target_vector, drawn_target)
    venv = FlatBodyVectorEnv(num_envs=3, **kwargs)
    venv.reset(seed=9, options={"state": state})  # body i: seed 9 + i
    np.testing.assert_array_equal(venv.target_vectors[2], drawn_target)
    np.testing.assert_array_equal(venv.states[2], env.physics_state)


def test_leaving_the_domain_terminates_with_a_finite_observation():
    env = FlatBodyEnv()
    env.reset(seed=0)
    state = dict(env.state, rho=0.2, p_rho=-45.0)
    env.reset(seed=0, options={"state": state})
    for _ in range(20):
        obs, r, term, trunc, info = env.step(np.zeros(4, dtype=np.float32))
        if term:
            break
    assert term and info["domain_code"] == 4 and env.end_reason(info) == "rho left the domain" and info["status"] == 0
    assert np.all(np.isfinite(obs)) and env.observation_space.contains(obs)
    assert info["reward_terms"]["failure"] == -env.task.failure_penalty


def test_integrator_failure_is_flagged_not_returned():
    class Failing:  # a stepper through the seam's interface that always reports a step-size collapse
        method, compiled, carries_rotation = "failing", False, False

        def advance_batch(self, Y, U, dt, OUT, STATUS, NFEV):
            OUT[:] = np.nan
            STATUS[:] = 2
            NFEV[:] = 0

        def own(self):
            return self

    env = _with_stepper(FlatBodyEnv(integrator="DOP853"), Failing())  # the generic (seam) path
    obs0, _ = env.reset(seed=0)
    obs, r, term, trunc, info = env.step(np.zeros(4, dtype=np.float32))
    assert term and info["status"] == 2 and env.end_reason(info).startswith("integrator failure (step-collapse")
    np.testing.assert_array_equal(obs, obs0)
    assert not info["is_success"]


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"control": "thrust"}, "control"),
        ({"dt": 0.0}, "dt"),
        ({"integrator": "Euler"}, "method"),
        ({"w_shape": -1.0}, "w_shape"),
        ({"body": {"params": {"J": -1, "J3": 1}, "potential": {"name": "V1", "k": 1}}}, "params.J"),
    ],
)
def test_bad_arguments(kwargs, field):
    with pytest.raises(ValueError, match=field):
        FlatBodyEnv(**kwargs)


def test_bad_reset_options():
    env = FlatBodyEnv()
    with pytest.raises(ValueError, match="options.bogus"):
        env.reset(options={"bogus": 1})
    with pytest.raises(ValueError, match=r"options\.state\.mu"):
        env.reset(options={"state": dict(env.reset(seed=0)[0] is not None and env.state, mu=-1.0)})
    with pytest.raises(ValueError, match="target"):
        env.reset(options={"target": {"lambda": 1.0}})


def test_vector_env_equals_single_envs_step_for_step():
    n, horizon = 4, 25
    venv = gym.make_vec("FlatBody-v0", n, vectorization_mode="vector_entry_point", max_episode_steps=horizon)
    singles = [gym.make("FlatBody-v0", max_episode_steps=horizon) for _ in range(n)]
    obs, _ = venv.reset(seed=10)
    np.testing.assert_array_equal(obs, np.stack([e.reset(seed=10 + i)[0] for i, e in enumerate(singles)]))
    rng = np.random.default_rng(0)
    pending = np.zeros(n, dtype=bool)
    ended = np.zeros(n, dtype=int)
    for _ in range(2 * horizon + 3):
        actions = rng.uniform(-1, 1, size=(n, 4)).astype(np.float32)
        obs, rew, term, trunc, info = venv.step(actions)
        for i, env in enumerate(singles):
            if pending[i]:  # NEXT_STEP autoreset: this step resets body i
                o, _ = env.reset()
                np.testing.assert_array_equal(obs[i], o)
                assert rew[i] == 0.0 and not term[i] and not trunc[i]
                pending[i] = False
                continue
            o, r, te, tr, inf = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rew[i] == pytest.approx(r, abs=1e-12) and te == term[i] and tr == trunc[i]
            assert info["distance"][i] == pytest.approx(inf["distance"], abs=1e-12)
            pending[i] = te or tr
            ended[i] += int(te or tr)
    assert np.all(ended >= 2)  # every body went through at least two episode ends and autoresets


def test_sb3_adapter_same_step_semantics():
    from agents.vec_env import FlatBodySB3VecEnv

    venv = FlatBodySB3VecEnv(3, seed=0, max_episode_steps=4)
    obs = venv.reset()
    assert obs.shape == (3, 16)
    for _k in range(4):
        obs, rewards, dones, infos = venv.step(np.zeros((3, 4), dtype=np.float32))
    assert dones.all() and all(i["TimeLimit.truncated"] for i in infos)
    assert all("terminal_observation" in i for i in infos)
    assert not np.array_equal(obs, np.stack([i["terminal_observation"] for i in infos]))  # already reset


def test_fixed_step_failure_near_lambda_equals_mu_terminates_cleanly():
    """RK4 at h = dt in the two-polar chart cannot resolve a close approach: flagged, not returned."""
    env = FlatBodyEnv(integrator="RK4")
    env.reset(seed=0)
    state = dict(env.state, s3=env.state["p_theta"] + 1e-4, p_lambda=0.3, p_mu=-0.3, mu=1.0)
    state["lambda"] = 1.2
    obs, _ = env.reset(seed=0, options={"state": state})
    for _ in range(400):
        previous = obs
        obs, r, term, trunc, info = env.step(np.zeros(4, dtype=np.float32))
        if term:
            break
    assert term and info["status"] == 7 and "under-resolved" in env.end_reason(info)
    np.testing.assert_array_equal(obs, previous)  # the last valid state, not the failed one
    assert np.all(np.isfinite(obs)) and info["reward_terms"]["failure"] < 0
    # the default integrator goes through the same approach without failing
    env = FlatBodyEnv()
    env.reset(seed=0, options={"state": state})
    for _ in range(400):
        _, _, term, _, info = env.step(np.zeros(4, dtype=np.float32))
        assert not term, info


def test_generic_stepper_agrees_with_the_compiled_one_for_the_same_method():
    from flatbody_env.integrators.steppers import GenericEnvStep

    fast = FlatBodyEnv()
    slow = _with_stepper(FlatBodyEnv(), GenericEnvStep("DOP853-numba", FlatBodyEnv().body, FlatBodyEnv().tolerances))
    assert fast.stepper.compiled and not slow.stepper.compiled
    o1, _ = fast.reset(seed=4)
    o2, _ = slow.reset(seed=4)
    rng = np.random.default_rng(1)
    for _ in range(50):
        a = rng.uniform(-1, 1, 4).astype(np.float32)
        r1 = fast.step(a)
        r2 = slow.step(a)
        np.testing.assert_allclose(r1[0], r2[0], rtol=0, atol=1e-6)
        assert r1[1] == pytest.approx(r2[1], abs=1e-9)
        assert r1[4]["reward_terms"] == pytest.approx(r2[4]["reward_terms"], abs=1e-9)
        assert r1[4]["integrator"]["method"] == r2[4]["integrator"]["method"] == "DOP853-numba"
