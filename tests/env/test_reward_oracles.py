"""Every reward term of every task against its documented formula (docs/env.md, docs/tasks.md), computed in
the test by the oracles of tests/oracles.py from the state, the target, the action and the body — never by the env's
kernels: the documented weights as numbers, ω1, ω2 from the mass matrix, the domain from the docs' table; the v0 ids'
named terms and the v1 ids' tolerance reward.

Over many random states and actions (the plain-float kernels, their compiled twins, the task's vectorised
scoring) and along real episodes (the single env behind Gymnasium's wrappers and the vector env, through
episode ends and autoresets). A changed weight, sign or formula in the env fails these tests."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flatbody_env  # noqa: F401  (registers the tasks)
from flatbody_env.env import compiled
from flatbody_env.env import kernels as python_kernels
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.registration import TASK_IDS, V1_IDS, task_spec
from flatbody_env.integrators import get_method
from oracles import (
    DOCUMENTED_ALIVE,
    DOCUMENTED_DOMAIN,
    DOCUMENTED_TOLERANCE,
    DOCUMENTED_WEIGHTS,
    documented_distance,
    documented_in_domain,
    documented_reward_terms,
    documented_tolerance_terms,
    tumble_rates,
)

pytestmark = pytest.mark.filterwarnings("ignore:.*out of date:DeprecationWarning")  # the v0 ids' deprecation
V0_IDS = tuple(i for i in TASK_IDS if i not in V1_IDS)
HOLD = "FlatBodyHoldUnstable-v0"
HOLDS = (HOLD, "FlatBodyHoldUnstable-v1")
RTOL, ATOL = 1e-11, 1e-12


def _alive(env_id: str):
    return DOCUMENTED_ALIVE if env_id == HOLD else None


def _names(env_id: str) -> list[str]:
    if env_id in V1_IDS:
        return ["success", "proximity"]
    return list(DOCUMENTED_WEIGHTS) + (["alive"] if env_id == HOLD else [])


def _expected(env_id, y, tg, a, ended, body) -> dict:
    """The documented terms of a step (the v0 ids' named terms, the v1 ids' tolerance reward), floats."""
    if env_id in V1_IDS:
        expect = documented_tolerance_terms(y, tg, ended, body)
    else:
        expect = documented_reward_terms(y, tg, a, ended, body, alive=_alive(env_id))
    return {k: float(v[0]) for k, v in expect.items()}


def _check_terms(got: dict, expect: dict, where: str) -> None:
    assert list(got) == list(expect), where
    for name, value in expect.items():
        np.testing.assert_allclose(
            np.asarray(got[name], dtype=np.float64), value, rtol=RTOL, atol=ATOL, err_msg=f"{where}: {name}"
        )


# --- the oracle itself -------------------------------------------------------------------------------------------
def test_the_oracles_tumble_rates_are_the_documented_inverse_legendre_map():
    """ω1 = s1/(Jμ² + J3ϱ²), ω2 = s2/(Jλ² + J3ϱ²) (task docstring, J1 = J2 = J): the mass-matrix route agrees,
    for bodies other than the default too."""
    from dataclasses import replace

    from flatbody_env.physics.body import Inertia, default_body

    rng = np.random.default_rng(0)
    for J, J3 in ((1.0, 1.0), (0.6, 1.7), (1.9, 0.55)):
        body = replace(default_body(), inertia=Inertia.isotropic(J, J3))
        Y = np.vstack([rng.normal(size=(7, 50)), rng.uniform(0.3, 3, (3, 50)), rng.uniform(-np.pi, np.pi, (1, 50))])
        w = tumble_rates(Y, body)
        np.testing.assert_allclose(w[0], Y[0] / (J * Y[8] ** 2 + J3 * Y[9] ** 2), rtol=1e-10)
        np.testing.assert_allclose(w[1], Y[1] / (J * Y[7] ** 2 + J3 * Y[9] ** 2), rtol=1e-10)


# --- random states and actions: the kernels (plain and compiled) and the task's vectorised scoring ------------------
def _random_step(env: FlatBodyEnv, n: int, seed: int):
    """n steps' worth of (old state, new state, integrator status, raw action, target) around the env's target:
    most new states inside the domain, some outside it (each bound, in both directions), non-finite, or after a
    failed integration."""
    rng = np.random.default_rng(seed)
    y0, tg = env.physics_state, env.target_vector
    T = tg + rng.normal(scale=0.05, size=(n, 4))  # each body its own target
    Y_old = y0[:, None] + rng.normal(scale=0.05, size=(11, n))
    Y_old[3] = y0[3]
    scale = rng.choice([0.01, 0.1, 0.4, 1.0], size=n)  # near the target and far from it
    Y_new = Y_old + rng.normal(size=(11, n)) * scale
    lo_s, hi_s = DOCUMENTED_DOMAIN["stretch"]
    lo_r, hi_r = DOCUMENTED_DOMAIN["rho"]
    planted = {7: (lo_s - 0.01, hi_s + 0.01), 8: (lo_s - 0.01, hi_s + 0.01), 9: (lo_r - 0.01, hi_r + 0.01)}
    k = 0
    for i, (below, above) in planted.items():
        Y_new[i, k], Y_new[i, k + 1] = below, above
        k += 2
    for i in range(7):  # one momentum entry beyond the bound, each sign
        Y_new[i, k] = DOCUMENTED_DOMAIN["momentum"] * 1.5 * (-1) ** i
        k += 1
    Y_new[rng.integers(0, 11), k : k + 3] = np.nan
    Y_new[10, k + 3] = np.inf
    k += 4
    Y_new[8, k : k + 2] = Y_new[7, k : k + 2]  # λ = μ: outside for two-polar integrators
    k += 2
    status = np.zeros(n, np.int64)
    status[k : k + 5] = rng.integers(1, 4, 5)  # the integrator failed
    near = slice(n - n // 5, n)  # the last fifth next to their targets (inside and just outside the success ball)
    Y_new[[0, 1, 4, 5, 6], near] = rng.normal(scale=0.012, size=(5, n // 5))
    Y_new[[7, 8, 9, 2], near] = T[near].T + rng.normal(scale=0.012, size=(4, n // 5))
    A = rng.uniform(-1.6, 1.6, (n, env.action_space.shape[0]))  # entries beyond the box: clipped
    return Y_old, Y_new, status, A, T


@pytest.mark.parametrize("kernels", [compiled, python_kernels], ids=["compiled", "python"])
@pytest.mark.parametrize("env_id", V0_IDS)
def test_kernels_score_random_states_as_documented(env_id, kernels):
    """The bookkeeping kernels (``post_step_lanes`` on N bodies, ``post_step`` body by body) and the task's
    vectorised ``reward_terms``/``distance``: each term, the distance, the kept state and the end of the episode
    equal the documented formulas and domain on 400 random steps."""
    env = FlatBodyEnv(**task_spec(env_id).kwargs)
    env.reset(seed=3)
    body, cfg, P = env.body, env.kernel_config, env.kernel_params
    n, m = 400, env.action_space.shape[0]
    Y_old, Y_new, status, A, T = _random_step(env, n, seed=TASK_IDS.index(env_id))
    two_polar = get_method(env.integrator).info.chart == "two-polar"
    assert two_polar  # the default integrator (docs/env.md), so the λ = μ states above must end the episode

    ended = (status != 0) | ~documented_in_domain(Y_new, two_polar=two_polar)
    kept = np.where(ended, Y_old, Y_new)
    expect = documented_reward_terms(kept, T.T, A, ended, body)
    d = documented_distance(kept, T.T, body)
    assert ended.sum() >= 25 and (~ended).sum() >= 300

    A_clip = env.config.controls(A)[0]  # the step path: the actions clipped (and scaled) first, then the bookkeeping
    Y_out, OBS, TERMS, SC, ENDED = (
        np.empty((11, n)),
        np.empty((n, 16), np.float32),
        np.empty((6, n)),
        np.empty((4, n)),
        np.empty(n, np.int64),
    )
    kernels.post_step_lanes(
        Y_old,
        Y_new,
        status,
        A_clip,
        m,
        T,
        cfg,
        np.repeat(np.array(P)[:, None], n, axis=1),  # each body's parameters (here one body's)
        Y_out,
        OBS,
        TERMS,
        SC,
        ENDED,
        np.empty(n),
        np.empty((4, n)),
        np.empty(7),
        np.empty(4),
        np.empty(11),
    )
    np.testing.assert_array_equal(ENDED.astype(bool), ended)
    np.testing.assert_array_equal(Y_out, kept)
    _check_terms(dict(zip(DOCUMENTED_WEIGHTS, TERMS)), expect, f"{env_id} post_step_lanes")
    np.testing.assert_allclose(SC[0], d, rtol=RTOL, atol=ATOL)

    for k in range(0, n, 7):  # the single body's kernel
        y, obs, terms, sc = np.empty(11), np.empty(16, np.float32), np.empty(6), np.empty(4)
        e = kernels.post_step(
            Y_old[:, k].copy(),
            Y_new[:, k].copy(),
            status[k],
            A_clip[k].copy(),
            m,
            T[k].copy(),
            cfg,
            P,
            y,
            obs,
            terms,
            sc,
            np.empty(7),
            np.empty(4),
        )
        assert bool(e) == ended[k]
        _check_terms(
            dict(zip(DOCUMENTED_WEIGHTS, terms)),
            {name: v[k] for name, v in expect.items()},
            f"{env_id} post_step body {k}",
        )
        assert sc[0] == pytest.approx(d[k], rel=RTOL, abs=ATOL)

    if kernels is python_kernels:  # the task's own vectorised API (Python): the same formulas, one call for N bodies
        _check_terms(env.task.reward_terms(kept, body, T.T, A_clip, ended), expect, f"{env_id} task.reward_terms")
        np.testing.assert_allclose(env.task.distance(kept, body, T.T), d, rtol=RTOL, atol=ATOL)


def test_every_weight_is_a_keyword_and_each_one_counts():
    """Other weights through the keywords: the terms follow the documented formulas with those weights."""
    weights = {"shape": 2.5, "spin": 0.3, "tumble": 1.7, "rest": 0.05, "action": 0.9, "failure": 3.0}
    env = FlatBodyEnv(w_shape=2.5, w_spin=0.3, w_tumble=1.7, w_rest=0.05, w_action=0.9, failure_penalty=3.0)
    env.reset(seed=8)
    n = 200
    Y_old, Y_new, status, A, T = _random_step(env, n, seed=8)
    ended = (status != 0) | ~documented_in_domain(Y_new, two_polar=True)
    kept = np.where(ended, Y_old, Y_new)
    TERMS, A_clip = np.empty((6, n)), env.config.controls(A)[0]
    compiled.post_step_lanes(
        Y_old,
        Y_new,
        status,
        A_clip,
        4,
        T,
        env.kernel_config,
        np.repeat(env.kernel_params[:, None], n, axis=1),
        np.empty((11, n)),
        np.empty((n, 16), np.float32),
        TERMS,
        np.empty((4, n)),
        np.empty(n, np.int64),
        np.empty(n),
        np.empty((4, n)),
        np.empty(7),
        np.empty(4),
        np.empty(11),
    )
    _check_terms(
        dict(zip(DOCUMENTED_WEIGHTS, TERMS)),
        documented_reward_terms(kept, T.T, A, ended, env.body, weights=weights),
        "weights",
    )
    hold = gym.make(HOLD, w_alive=0.25).unwrapped
    hold.reset(seed=0)
    _, r, term, _, info = hold.step(np.zeros(4, dtype=np.float32))
    assert info["reward_terms"]["alive"] == (0.0 if term else 0.25)


# --- real episodes: the single env (wrappers included) and the vector env ---------------------------------------
def _single_env_steps(env_id: str, seed: int, actions: np.ndarray, options=None):
    """Step ``gym.make(env_id)`` with ``actions`` from ``reset(seed, options)``; yields per step what the oracle needs."""
    env = gym.make(env_id)
    u = env.unwrapped
    env.reset(seed=seed, options=options)
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        yield a, r, term, trunc, info, u.physics_state.copy(), u.target_vector.copy(), u.body
        if term or trunc:
            return


def _check_step(env_id, a, r, term, trunc, info, y, tg, body, where):
    expect = _expected(env_id, y, tg, a, term, body)
    _check_terms(info["reward_terms"], expect, where)
    assert r == pytest.approx(sum(expect.values()), rel=RTOL, abs=ATOL), where
    d = float(documented_distance(y, tg, body)[0])
    assert info["distance"] == pytest.approx(d, rel=RTOL, abs=ATOL), where
    assert info["is_success"] == (d <= DOCUMENTED_TOLERANCE and not term), where
    if term:  # the failing step: an integrator failure, the domain, or (hold) the ball
        assert info["status"] or info["domain_code"], where
    if env_id in HOLDS and not info["status"]:
        assert term == (d > DOCUMENTED_TOLERANCE), where
    return expect


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_episode_rewards_follow_the_documented_formulas(env_id):
    """Along whole episodes of ``gym.make(env_id)`` (random actions, some beyond the box; one episode to its
    truncation at 400 steps, and one driven out of the domain): each term, the reward, the distance and success
    from the state the env keeps after the step."""
    shape = gym.make(env_id).action_space.shape
    rng = np.random.default_rng(11)
    seen = {name: 0 for name in _names(env_id)}
    ends = []
    for seed, scale in ((1, 0.3), (2, 1.3)):
        actions = rng.uniform(-scale, scale, (400,) + shape).astype(np.float32)
        steps = 0
        for a, r, term, trunc, info, y, tg, body in _single_env_steps(env_id, seed, actions):
            expect = _check_step(env_id, a, r, term, trunc, info, y, tg, body, f"{env_id} seed {seed} step {steps}")
            seen = {k: seen[k] + (expect[k] != 0) for k in seen}
            steps += 1
            last = (term, trunc)
        ends.append((steps, last))
    # a start driven out of the domain: the thickness collapses (docs/env.md's episode end; failure −10)
    env = gym.make(env_id)
    env.reset(seed=0)
    state = dict(env.unwrapped.state, rho=0.2, p_rho=-45.0)
    actions = np.zeros((20,) + shape, dtype=np.float32)
    for k, (a, r, term, trunc, info, y, tg, body) in enumerate(
        _single_env_steps(env_id, 0, actions, options={"state": state})
    ):
        _check_step(env_id, a, r, term, trunc, info, y, tg, body, f"{env_id} domain step {k}")
    assert term and info["domain_code"] in ((4, 7) if env_id in HOLDS else (4,))  # ϱ left (or, holding, the ball)
    if env_id not in V1_IDS:
        assert info["reward_terms"]["failure"] == -DOCUMENTED_WEIGHTS["failure"]
    else:
        assert r == 0.0
    if (
        env_id not in HOLDS
    ):  # the reaching tasks: the gentle episode runs to its truncation, no failure on the last step
        assert ends[0] == (400, (False, True)), ends
    exercised = [k for k in seen if k not in ("failure", "success")] + (["success"] if env_id == HOLDS[1] else [])
    assert all(seen[k] > 0 for k in exercised), seen  # every term was exercised (non-zero)


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_vector_env_rewards_follow_the_documented_formulas(env_id):
    """The vector env (compiled lanes, the task's terms on arrays) over N bodies through episode ends and
    NEXT_STEP autoresets: each body's terms and reward from its state after the step."""
    n, horizon = 6, 12
    venv = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point", max_episode_steps=horizon)
    venv.reset(seed=40)
    rng = np.random.default_rng(5)
    resetting = np.zeros(n, dtype=bool)
    checked = ends = 0
    for step in range(3 * horizon):
        A = rng.uniform(-1.2, 1.2, (n,) + venv.single_action_space.shape).astype(np.float32)
        _, rew, term, trunc, info = venv.step(A)
        Y, T = venv.states.T, venv.target_vectors.T
        bodies = venv.bodies
        for i in np.flatnonzero(~resetting):
            expect = _expected(env_id, Y[:, i], T[:, i], A[i], term[i], bodies[i])
            _check_terms({k: v[i] for k, v in info["reward_terms"].items()}, expect, f"{env_id} step {step} body {i}")
            assert rew[i] == pytest.approx(sum(expect.values()), rel=RTOL, abs=ATOL)
            assert info["distance"][i] == pytest.approx(
                float(documented_distance(Y[:, i], T[:, i], bodies[i])[0]), rel=RTOL, abs=ATOL
            )
            checked += 1
        resetting = term | trunc
        ends += int(resetting.sum())
    assert checked >= n * horizon and ends >= 2 * n  # every body through at least two episode ends and autoresets
