"""The registered tasks (docs/tasks.md): registration and checkers, determinism, the vector env equal to N
single envs (each task's reward terms against their documented formulas: test_reward_oracles.py), and each task's draws against what its docs say (statistics over ≥ 10⁴ draws
where the draws are compiled or batched; the long ones are marked slow)."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import flatbody_env  # noqa: F401  (registers the tasks)
from flatbody_env.env.any_body import BODY_OBSERVATION_NAMES, body_constants
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.task import target_row
from flatbody_env.env.registration import TASK_IDS, TASKS, V1_IDS, task_spec
from flatbody_env.env.vector_env import FlatBodyVectorEnv
from flatbody_env.env.witness import REVERSAL
from flatbody_env.physics.controllability import linearize, settling_rate
from flatbody_env.physics.equations import rhs

N_DRAWS = 10_000
pytestmark = pytest.mark.filterwarnings("ignore:.*out of date:DeprecationWarning")  # the v0 ids' deprecation


def _env(env_id: str, **kw) -> FlatBodyEnv:
    return FlatBodyEnv(**{**task_spec(env_id).kwargs, **kw})


# --- independent formulas (docs/physics.md §3, §7; the task docstrings) ------------------------------------
def _omega12(Y, J, J3):
    return Y[0] / (J * Y[8] ** 2 + J3 * Y[9] ** 2), Y[1] / (J * Y[7] ** 2 + J3 * Y[9] ** 2)


def _distance(Y, tgt, J, J3):
    w1, w2 = _omega12(Y, J, J3)
    e = [Y[7] - tgt[0], Y[8] - tgt[1], Y[9] - tgt[2], Y[2] - tgt[3], w1, w2, Y[4], Y[5], Y[6]]
    return np.sqrt(sum(np.asarray(x) ** 2 for x in e))


def _q(lam, mu, rho, s3, pt, J, J3):
    """The out-of-plane coefficient q = (s3/I2 − ω3)(ω3 − s3/I1) of a branch-N ellipse (unstable iff q > 0)."""
    u, v = lam + mu, lam - mu
    sp, sm = s3 + pt, s3 - pt
    w3 = sp / (2 * J * u * u) + sm / (2 * J * v * v)
    I1, I2 = J * mu * mu + J3 * rho * rho, J * lam * lam + J3 * rho * rho
    return (s3 / I2 - w3) * (w3 - s3 / I1)


def _target_state(tg):
    return np.array([0.0, 0.0, tg[3], tg[4], 0.0, 0.0, 0.0, tg[0], tg[1], tg[2], 0.0])


def _draws(env: FlatBodyEnv, n: int, seed0: int = 0):
    """n of the task's v0 draws (a target, then its start, from the generator seeded seed0 + s): states (11, n),
    targets (n, 6)."""
    Y, TG = np.empty((11, n)), np.empty((n, 6))
    for s in range(n):
        rng = np.random.default_rng(seed0 + s)
        target = env.task.sample_target(rng, env.body, limits=env.limits, control=env.control)
        Y[:, s] = env.task.start_near(rng, target, env.control, body=env.body)
        TG[s] = target_row(target)
    return Y, TG


# --- registration and checkers ----------------------------------------------------------------------------
def test_every_task_is_registered_with_its_spec():
    assert V1_IDS == (
        "FlatBody-v1",
        "FlatBodySlow-v1",
        "FlatBodySlowHard-v1",
        "FlatBodyHoldUnstable-v1",
        "FlatBodyTorque-v1",
        "FlatBodyAnyBody-v1",
    )
    assert {TASKS[TASK_IDS.index(i)].rung for i in V1_IDS} == {"easy", "medium", "hard"}
    assert TASK_IDS[len(V1_IDS) :] == (
        "FlatBody-v0",
        "FlatBodySlow-v0",
        "FlatBodyHoldUnstable-v0",
        "FlatBodyTorque-v0",
        "FlatBodyDilatation-v0",
        "FlatBodyAnyBody-v0",
    )
    for spec in TASKS:
        env = gym.make(spec.env_id)
        assert env.spec.max_episode_steps == spec.max_episode_steps == 400
        assert isinstance(env.unwrapped, FlatBodyEnv)
        assert gym.make(f"flatbody_env:{spec.env_id}").unwrapped.control == spec.kwargs.get(
            "control", "torque+dilatation"
        )
    with pytest.raises(ValueError, match="env: must be one of"):
        task_spec("FlatBody-v9")
    with pytest.raises(ValueError, match="task: must be one of"):
        FlatBodyEnv(task="juggle")
    with pytest.raises(ValueError, match="body: this task draws its own body"):
        FlatBodyEnv(
            task="any-body",
            body={"params": {"J": 1, "J3": 1}, "potential": {"name": "V3", "kappa": 1}, "thickness": {"a": 1, "b": 1}},
        )


def test_rl_zoo_gym_packages_path_registers_every_task():
    """RL Zoo's ``--gym-packages flatbody_env`` imports the package after gymnasium (a fresh process)."""
    import subprocess
    import sys

    code = (
        "import gymnasium as gym, importlib\nimportlib.import_module('flatbody_env')\n"
        f"for i in {TASK_IDS!r}:\n    e = gym.make(i); e.reset(seed=0); print(i, e.observation_space.shape[0])"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == [x for i in TASK_IDS for x in (i, "21" if i == "FlatBodyAnyBody-v0" else "16")]


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_gymnasium_checker_passes_without_warnings(env_id):
    env = gym.make(env_id).unwrapped  # (the v0 ids' one deprecation warning comes from gym.make)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env, skip_render_check=True)


def test_v0_ids_are_deprecated_in_one_line_pointing_to_v1():
    for env_id in TASK_IDS:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            gym.make(env_id)
        messages = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
        if env_id in V1_IDS or env_id == "FlatBodyDilatation-v0":
            assert not [m for m in messages if "out of date" in m], env_id
        else:
            assert len(messages) == 1 and "upgrading to version `v1`" in messages[0], env_id


@pytest.mark.slow
@pytest.mark.parametrize("env_id", TASK_IDS)
def test_sb3_checker_and_make_vec_env(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env
    from stable_baselines3.common.env_util import make_vec_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(_env(env_id))
    venv = make_vec_env(env_id, n_envs=2, seed=0)
    venv.reset()
    venv.step(np.zeros((2,) + venv.action_space.shape))


# --- determinism and the vector env -----------------------------------------------------------------------
def _rollout(env, seed, actions):
    obs, info = env.reset(seed=seed)
    out = [(obs, info["distance"])]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append((obs, r, term, info["distance"], tuple(info["reward_terms"].values())))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_identical_seeds_give_identical_rollouts(env_id):
    a, b = gym.make(env_id), gym.make(env_id)
    actions = np.random.default_rng(1).uniform(-1, 1, (25,) + a.action_space.shape).astype(np.float32)
    ra, rb = _rollout(a, 11, actions), _rollout(b, 11, actions)
    assert len(ra) == len(rb)
    for x, y in zip(ra, rb):
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1:] == y[1:]
    assert not np.array_equal(_rollout(a, 12, actions)[0][0], ra[0][0])


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_vector_env_equals_single_envs_through_an_autoreset(env_id):
    """gym.make_vec's native vector env and N single envs: the same observations, rewards, terms, ends and
    infos step for step, through each body's episode end (short horizon) and the autoreset that follows."""
    n, horizon = 3, 6
    venv = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point", max_episode_steps=horizon)
    assert isinstance(venv, FlatBodyVectorEnv)
    singles = [gym.make(env_id, max_episode_steps=horizon) for _ in range(n)]
    obs, info = venv.reset(seed=30)
    for i, e in enumerate(singles):
        o, inf = e.reset(seed=30 + i)
        np.testing.assert_array_equal(obs[i], o)
        assert info["distance"][i] == inf["distance"] and info["energy"][i] == inf["energy"]
    rng = np.random.default_rng(3)
    done = np.zeros(n, dtype=bool)
    for _ in range(2 * horizon + 1):
        A = rng.uniform(-1, 1, (n,) + venv.single_action_space.shape).astype(np.float32)
        obs, rew, term, trunc, info = venv.step(A)
        for i, e in enumerate(singles):
            if done[i]:  # NEXT_STEP autoreset: the vector env resets this body now; the single env resets itself
                o, _ = e.reset()
                np.testing.assert_array_equal(obs[i], o)
                assert rew[i] == 0.0
                continue
            o, r, te, tr, inf = e.step(A[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rew[i] == r and te == term[i] and tr == trunc[i]
            assert list(inf["reward_terms"]) == list(info["reward_terms"])
            assert [v[i] for v in info["reward_terms"].values()] == list(inf["reward_terms"].values())
            assert info["is_success"][i] == inf["is_success"] and info["domain_code"][i] == inf["domain_code"]
            assert info["status"][i] == inf["status"]
        done = term | trunc


# --- FlatBody-v0 and FlatBodySlow-v0: stable circulation targets, with and without the filter ---------------
def _check_stable_circulation(Y, TG, env):
    J, J3 = env.body.inertia.J1, env.body.inertia.J3
    lam, mu, rho, s3, pt = TG[:, 0], TG[:, 1], TG[:, 2], TG[:, 3], TG[:, 4]
    (l0, l1), (a0, a1) = env.task.target_lambda, env.task.target_aspect
    assert (lam >= l0).all() and (lam <= l1).all()
    assert (lam / mu >= a0 - 1e-12).all() and (lam / mu <= a1 + 1e-12).all()
    assert (np.abs(s3) < np.abs(pt)).all()  # the circulation family
    assert (_q(lam, mu, rho, s3, pt, J, J3) < 0).all()  # out-of-plane stable
    np.testing.assert_allclose(rho, 1.0, rtol=1e-12)  # ϱ* = (a/b)^(1/3) of the default body
    np.testing.assert_array_equal(Y[3], pt)  # every control conserves p_θ: the start has the target's
    # both signs of (s3, p_θ), about equally often
    assert abs(np.mean(TG[:, 5] > 0) - 0.5) < 0.03


def test_flatbody_v0_draws_stable_fast_targets():
    env = _env("FlatBody-v0")
    Y, TG = _draws(env, N_DRAWS)
    _check_stable_circulation(Y, TG, env)
    # the reachability rule on a random subsample, by the exact test (a Riccati solve each)
    for k in np.random.default_rng(0).choice(N_DRAWS, 40, replace=False):
        assert settling_rate(env.body, _target_state(TG[k]), env.limits) >= 0.15 - 1e-9


def test_flatbody_slow_draws_every_stable_target_of_the_ranges():
    slow, fast = _env("FlatBodySlow-v0"), _env("FlatBody-v0")
    Y, TG = _draws(slow, N_DRAWS)
    _check_stable_circulation(Y, TG, slow)
    # no filter: the draws cover the existence region, whose shapes are mostly slow (r < 0.15)
    rates = np.array([settling_rate(slow.body, _target_state(TG[k]), slow.limits) for k in range(60)])
    assert 0.5 < np.mean(rates < 0.15) < 0.95 and rates.min() < 0.05
    # the existence and stability region itself: a shape is drawn iff a stable ellipse exists there (λ*μ* ≥ 1 for V3)
    assert (TG[:, 0] * TG[:, 1] >= 1.0 - 1e-12).all()
    frac_fast = np.mean(
        np.array([settling_rate(fast.body, _target_state(TG[k]), fast.limits) >= 0.15 for k in range(60, 120)])
    )
    assert frac_fast < 0.5


# --- FlatBodyHoldUnstable-v0 -------------------------------------------------------------------------------------
def test_hold_unstable_draws_hyperbolic_targets_and_starts_inside_the_ball():
    env = _env("FlatBodyHoldUnstable-v0")
    task = env.task
    Y, TG = _draws(env, N_DRAWS)
    J, J3 = env.body.inertia.J1, env.body.inertia.J3
    lam, mu, rho, s3, pt = TG[:, 0], TG[:, 1], TG[:, 2], TG[:, 3], TG[:, 4]
    assert (np.abs(s3) > np.abs(pt)).all()  # the rotation family
    q = _q(lam, mu, rho, s3, pt, J, J3)
    assert (q > 0).all()
    assert (np.sqrt(q) >= task.min_growth_rate).all() and (np.sqrt(q) <= task.max_growth_rate).all()
    # mostly rotation about the intermediate principal axis, Jμ*² < J3ϱ*² < Jλ*² (exact for θ̇ = 0, [2] §7; here θ̇ ≠ 0)
    assert np.mean((J * mu**2 < J3 * rho**2) & (J3 * rho**2 < J * lam**2)) > 0.8
    (l0, l1), (a0, a1) = task.target_lambda, task.target_aspect
    assert (lam >= l0).all() and (lam <= l1).all() and (lam / mu >= a0 - 1e-12).all() and (lam / mu <= a1 + 1e-12).all()
    # the start: inside the success ball, at a distance uniform in [0.3, 0.9] × tolerance
    d = _distance(Y, TG[:, :4].T, J, J3)
    tol = task.success_tolerance
    lo, hi = task.start_radius
    assert (d >= lo * tol * (1 - 1e-9)).all() and (d <= hi * tol * (1 + 1e-9)).all()
    counts, _ = np.histogram(d, bins=5, range=(lo * tol, hi * tol))
    assert counts.min() > 0.17 * N_DRAWS  # uniform in R: 0.2 each
    np.testing.assert_array_equal(Y[3], pt)
    # linear stability by the full linearisation: exactly one eigenvalue with positive real part, +√q
    for k in np.random.default_rng(1).choice(N_DRAWS, 12, replace=False):
        y_star = _target_state(TG[k])
        assert np.max(np.abs(rhs(0.0, y_star, None, env.body)[:10])) < 1e-10  # a stationary ellipse
        ev = np.linalg.eigvals(linearize(env.body, y_star, env.limits)[0])
        assert np.sum(ev.real > 1e-4) == 1
        assert ev.real.max() == pytest.approx(math.sqrt(q[k]), rel=1e-4)


def test_hold_unstable_without_control_leaves_and_ends_the_episode():
    env = gym.make("FlatBodyHoldUnstable-v0")
    times = []
    for seed in range(6):
        env.reset(seed=seed)
        for _k in range(400):
            _, r, term, trunc, info = env.step(np.zeros(4, dtype=np.float32))
            if term:
                assert info["domain_code"] == 7 and not info["is_success"]
                assert env.unwrapped.end_reason(info) == "left the target's tolerance"
                assert info["distance"] > 0.05 and info["reward_terms"]["alive"] == 0.0
                times.append(info["t"])
                break
            assert info["distance"] <= 0.05 and info["reward_terms"]["alive"] == 1.0
        assert not trunc
    assert len(times) == 6 and max(times) < 20.0


# --- FlatBodyTorque-v0 and FlatBodyDilatation-v0 ----------------------------------------------------------------
@pytest.mark.parametrize("env_id", ["FlatBodyTorque-v0", "FlatBodyDilatation-v0"])
def test_underactuated_targets_are_stable_circulation_ellipses(env_id):
    env = _env(env_id)
    env.reset(seed=0)
    _, TG = _draws(env, N_DRAWS)
    _check_stable_circulation(np.tile(TG[:, 4], (11, 1)), TG, env)
    # no settling filter: the linear settling rate is 0 for these controls (not linearly controllable)
    for k in range(3):
        assert settling_rate(env.body, _target_state(TG[k]), env.limits, env.mask) < 1e-9


def _witnessed_draws(env_id, n):
    env = _env(env_id)
    env.reset(seed=0)
    rngs = [np.random.default_rng(s) for s in range(n)]
    eps = env.task.draw_batch(rngs, env.body, limits=env.limits, control=env.control, simulator=env.core)
    return env, eps


@pytest.mark.parametrize("env_id,n", [("FlatBodyTorque-v0", 400), ("FlatBodyDilatation-v0", 1000)])
def test_witnessed_starts_are_what_the_docs_say(env_id, n):
    env, eps = _witnessed_draws(env_id, n)
    _check_witnessed(env, eps)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ["FlatBodyTorque-v0", "FlatBodyDilatation-v0"])
def test_witnessed_starts_over_ten_thousand_draws(env_id):
    env, eps = _witnessed_draws(env_id, N_DRAWS)
    _check_witnessed(env, eps)


def _check_witnessed(env, eps):
    task = env.task
    J, J3 = env.body.inertia.J1, env.body.inertia.J3
    Y = np.stack([e.state for e in eps], axis=1)
    TG = np.stack([e.target for e in eps])
    d = _distance(Y, TG[:, :4].T, J, J3)
    assert (d >= task.start_distance[0]).all() and (d <= task.start_distance[1]).all()
    np.testing.assert_array_equal(Y[3], TG[:, 4])  # p_θ conserved by every control
    if "dilatation" not in env.control:  # torque only: the thickness is off by at least the tolerance
        off = np.hypot(Y[9] - TG[:, 2], Y[6])
        assert (off >= 0.05 - 1e-12).all()
    if (
        "torque" not in env.control
    ):  # dilatation only: the shape and spin are off by no more than y_b inside the ball (docs)
        w1, w2 = _omega12(Y, J, J3)
        off = np.sqrt(
            (Y[7] - TG[:, 0]) ** 2
            + (Y[8] - TG[:, 1]) ** 2
            + (Y[2] - TG[:, 3]) ** 2
            + w1**2
            + w2**2
            + Y[4] ** 2
            + Y[5] ** 2
        )
        assert np.percentile(off, 90) < task.success_tolerance
    from flatbody_env.env.witness import witness_actions

    W = np.stack([witness_actions(e.witness_params, env.task.witness_steps, env.action_space.shape[0]) for e in eps])
    assert W.shape[1:] == (400, env.action_space.shape[0]) and np.abs(W).max() <= task.witness_amplitude[1]
    # each witness is a reversed run of square waves: ±α, constant between sign changes
    assert np.all(np.abs(np.abs(W) - np.abs(W[:, :1])) < 1e-15)


@pytest.mark.parametrize("env_id", ["FlatBodyTorque-v0", "FlatBodyDilatation-v0"])
def test_replaying_the_witness_succeeds(env_id):
    """The witness, replayed open loop from the start by the env itself, ends inside the success ball."""
    env = gym.make(env_id)
    for seed in range(4):
        env.reset(seed=seed)
        start = env.unwrapped.physics_state
        witness = env.unwrapped.witness
        for a in witness:
            _, _, term, trunc, info = env.step(a.astype(np.float32))
            assert not term
        assert trunc and info["is_success"] and info["distance"] <= 0.5 * 0.05 + 1e-6
        # time reversal (flatbody_env.env.witness): the reversed run from the end, under the reversed actions, returns to the start
        u = env.unwrapped
        Z, ok = u.core.rollout((REVERSAL * u.physics_state)[:, None], witness[::-1, None, :])
        assert ok[0]
        np.testing.assert_allclose(REVERSAL * Z[:, 0], start, atol=1e-7)


def test_torque_only_lqr_leaves_the_thickness_undamped_and_dilatation_only_has_none():
    from agents.heuristic import LQRWeights, lqr_gain

    for env_id in ("FlatBodyTorque-v0", "FlatBodyDilatation-v0"):
        env = _env(env_id)
        env.reset(seed=0)
        t = env.target
        y = np.array([0, 0, t["s3"], t["p_theta"], 0, 0, 0, t["lambda"], t["mu"], t["rho"], 0.0])
        if env_id == "FlatBodyDilatation-v0":
            with pytest.raises(np.linalg.LinAlgError):
                lqr_gain(env.body, y, env.limits, env.mask, LQRWeights())
        else:
            K = lqr_gain(env.body, y, env.limits, env.mask, LQRWeights())
            A, B = linearize(env.body, y, env.limits)
            assert (
                abs(np.linalg.eigvals(A - B[:, env.mask] @ K).real.max()) < 1e-8
            )  # marginal: the thickness mode stays


# --- FlatBodyAnyBody-v0 ------------------------------------------------------------------------------------------
def test_any_body_draws_bodies_log_uniformly_in_the_documented_ranges():
    env = _env("FlatBodyAnyBody-v0")
    task = env.task
    C = np.array([body_constants(task.sample_body(np.random.default_rng(s))) for s in range(N_DRAWS)])
    lo, hi = task.ranges().T
    assert (lo <= C).all() and (hi >= C).all()
    x = np.log(C / lo) / np.log(hi / lo)  # uniform on [0, 1] for a log-uniform draw
    for j in range(C.shape[1]):
        counts, _ = np.histogram(x[:, j], bins=10, range=(0, 1))
        assert counts.min() > 0.085 * N_DRAWS and counts.max() < 0.115 * N_DRAWS
    assert abs(np.corrcoef(x.T)[np.triu_indices(5, 1)]).max() < 0.05  # independent constants


def test_any_body_targets_are_fast_for_their_own_body_and_the_observation_carries_it():
    env = gym.make("FlatBodyAnyBody-v0")
    u = env.unwrapped
    bodies = set()
    for seed in range(12):
        obs, _ = env.reset(seed=seed)
        assert obs.shape == (16 + len(BODY_OBSERVATION_NAMES),)
        np.testing.assert_allclose(obs[16:], body_constants(u.body), rtol=1e-6)
        t = u.target
        J, J3 = u.body.inertia.J1, u.body.inertia.J3
        rho_star = (u.body.thickness.a / u.body.thickness.b) ** (1 / 3)  # eq. (54)
        assert t["rho"] == pytest.approx(rho_star, rel=1e-9)
        assert abs(t["s3"]) < abs(t["p_theta"]) and _q(t["lambda"], t["mu"], t["rho"], t["s3"], t["p_theta"], J, J3) < 0
        y_star = np.array([0, 0, t["s3"], t["p_theta"], 0, 0, 0, t["lambda"], t["mu"], t["rho"], 0.0])
        assert settling_rate(u.body, y_star, u.limits) >= 0.15 - 1e-9
        bodies.add(tuple(obs[16:]))
        _, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
        assert np.isfinite(info["energy"])
    assert len(bodies) == 12


@pytest.mark.slow
def test_any_body_reachability_rule_over_ten_thousand_draws():
    env = _env("FlatBodyAnyBody-v0")
    rngs = [np.random.default_rng(s) for s in range(N_DRAWS)]
    eps = env.task.draw_batch(rngs, env.body, limits=env.limits, control=env.control)  # each body drawn per episode
    assert len({tuple(body_constants(ep.body)) for ep in eps}) == N_DRAWS
    for ep in eps:
        assert settling_rate(ep.body, _target_state(ep.target), env.limits) >= 0.15 - 1e-9


# --- the LQR baseline on targets outside its gain table ----------------------------------------------------------
def test_lqr_solves_rotation_targets_exactly_instead_of_reading_the_circulation_table():
    from agents.heuristic import HeuristicController

    env = gym.make("FlatBodyHoldUnstable-v0")
    obs, _ = env.reset(seed=2)
    u = env.unwrapped
    table, exact = (
        HeuristicController(u.body, u.control, u.limits),
        HeuristicController(u.body, u.control, u.limits, exact=True),
    )
    np.testing.assert_array_equal(table.act(obs[None]), exact.act(obs[None]))
