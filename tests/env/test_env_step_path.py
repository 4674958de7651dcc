"""The env's one step path: identical to the compiled composition it replaced, real work counts in
``info``, one info builder, one formula per score, and the vector env equal to N single envs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flatbody_env.env import compiled
from flatbody_env.env import transition as tr
from flatbody_env.env.core import EnvCore
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.task import OBSERVATION_SIZE, REWARD_TERMS, ReachStationaryEllipse, state_from_observation
from flatbody_env.env.vector_env import FlatBodyVectorEnv
from flatbody_env.integrators.compiled_methods import env_stepper
from flatbody_env.physics.equations import rhs
from oracles import documented_distance, documented_reward_terms


def test_one_step_path_is_bitwise_the_compiled_composition_for_the_default_integrator():
    """Oracle: the raw compiled DOP853 env kernel (first step guess = dt) followed by the compiled
    bookkeeping, called directly — the composition the previous fast path ran."""
    env = FlatBodyEnv()
    obs, _ = env.reset(seed=3)
    y = env.physics_state
    tgt = env.target_vector
    P, cfg = env.kernel_params.copy(), env.kernel_config.copy()
    raw = env_stepper("DOP853-numba")
    tol = env.tolerances
    rng = np.random.default_rng(7)
    for _ in range(80):
        a = rng.uniform(-1.3, 1.3, 4)  # some entries beyond the box: clipped
        a_clip = np.clip(a, -1, 1)
        u = a_clip * env.limits
        ynew = np.empty(11)
        st = raw.step(y, u, P, env.dt, env.dt, tol.rtol, tol.atol, np.inf, ynew)
        y_out, o_ref, terms, sc = np.empty(11), np.empty(16, np.float32), np.empty(6), np.empty(4)
        ended = compiled.post_step(
            y, ynew, st, a_clip, 4, tgt, cfg, P, y_out, o_ref, terms, sc, np.empty(7), np.empty(4)
        )
        o, r, term, trunc, info = env.step(a.astype(np.float64))
        np.testing.assert_array_equal(o, o_ref)
        assert r == sum(terms.tolist())
        assert list(info["reward_terms"].values()) == terms.tolist()
        assert info["distance"] == sc[0] and info["energy"] == sc[1] and term == bool(ended)
        y = y_out
        np.testing.assert_array_equal(env.physics_state, y)
        if term:
            break


def test_info_names_the_integrator_that_ran_and_its_real_nfev():
    env = FlatBodyEnv()
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
    assert info["integrator"]["method"] == "DOP853-numba"
    # DOP853: one derivative at the start plus 12 stages per attempted step
    assert info["integrator"]["nfev"] >= 13 and (info["integrator"]["nfev"] - 1) % 12 == 0

    rk4 = FlatBodyEnv(integrator="RK4", step=0.0125)  # 4 sub-steps × 4 stages
    rk4.reset(seed=0)
    assert rk4.step(np.zeros(4, dtype=np.float32))[4]["integrator"] == {"method": "RK4", "nfev": 16}

    ref = FlatBodyEnv(integrator="DOP853", rtol=1e-9, atol=1e-9)  # the generic stepper (scipy)
    ref.reset(seed=0)
    y0, u = ref.physics_state, ref.controls(np.full(4, 0.2))[1]
    info = ref.step(np.full(4, 0.2, dtype=np.float32))[4]
    # scipy with the domain events the method watches: DOP853 then also evaluates its dense output (3 per step)
    sol = solve_ivp(
        lambda t, y: rhs(t, y, u, ref.body), (0.0, ref.dt), y0, method="DOP853", rtol=1e-9, atol=1e-9, dense_output=True
    )
    assert info["integrator"] == {"method": "DOP853", "nfev": sol.nfev}

    drawn = FlatBodyEnv(render_mode="rgb_array")  # drawing carries R in the compiled method itself
    _, reset_info = drawn.reset(seed=0)
    assert drawn.stepping_integrator == "DOP853-numba" and drawn.stepper.compiled
    assert reset_info["integrator"] == {"method": drawn.stepping_integrator, "nfev": 0}
    assert drawn.step(np.zeros(4, dtype=np.float32))[4]["integrator"]["method"] == drawn.stepping_integrator


def test_reset_and_step_infos_have_the_same_keys_and_values_from_the_same_formulas():
    env = FlatBodyEnv()
    obs, info0 = env.reset(seed=5)
    _, _, _, _, info1 = env.step(np.zeros(4, dtype=np.float32))
    assert set(info1) - set(info0) == {"reward_terms"}
    y, tgt = state_from_observation(obs)
    assert info0["distance"] == pytest.approx(env.task.distance(y, env.body, tgt), abs=1e-6)
    # independent: the distance from its definition (task docstring)
    s = env.physics_state
    J, J3 = env.body.inertia.J1, env.body.inertia.J3
    w1, w2 = s[0] / (J * s[8] ** 2 + J3 * s[9] ** 2), s[1] / (J * s[7] ** 2 + J3 * s[9] ** 2)
    t = env.target_vector
    d = np.linalg.norm([s[7] - t[0], s[8] - t[1], s[9] - t[2], s[2] - t[3], w1, w2, s[4], s[5], s[6]])
    assert info1["distance"] == pytest.approx(d, rel=1e-12)


def test_vectorised_task_scores_and_the_compiled_lanes_follow_the_documented_formulas():
    """The task's vectorised scoring (Python) and the vector env's compiled lanes each against docs/env.md's
    formulas computed independently (tests/oracles.py), not against each other."""
    task = ReachStationaryEllipse()
    venv = FlatBodyVectorEnv(num_envs=6)
    venv.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(5):
        A = rng.uniform(-1.3, 1.3, (6, 4))
        _, _, term, _, info = venv.step(A)
        Y, T = venv.states.T, venv.target_vectors.T
        expect = documented_reward_terms(Y, T, A, term, venv.body)
        d = documented_distance(Y, T, venv.body)
        terms = task.reward_terms(Y, venv.body, T, np.clip(A, -1, 1), term)
        for name in REWARD_TERMS:
            np.testing.assert_allclose(terms[name], expect[name], rtol=1e-11, atol=1e-12, err_msg=name)
            np.testing.assert_allclose(info["reward_terms"][name], expect[name], rtol=1e-11, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(task.distance(Y, venv.body, T), d, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(info["distance"], d, rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("integrator", ["DOP853-numba", "RK4"])
def test_vector_env_equals_single_envs_including_info(integrator):
    n = 3
    venv = FlatBodyVectorEnv(num_envs=n, max_episode_steps=10, integrator=integrator)
    singles = [FlatBodyEnv(integrator=integrator) for _ in range(n)]
    obs, info = venv.reset(seed=20)
    for i, e in enumerate(singles):
        o, inf = e.reset(seed=20 + i)
        np.testing.assert_array_equal(obs[i], o)
        assert info["energy"][i] == inf["energy"] and info["distance"][i] == inf["distance"]
    rng = np.random.default_rng(3)
    for _ in range(10):
        A = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        obs, rew, term, trunc, info = venv.step(A)
        assert info["integrator"]["method"] == integrator
        for i, e in enumerate(singles):
            o, r, te, _, inf = e.step(A[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rew[i] == r and te == term[i]
            assert info["integrator"]["nfev"][i] == inf["integrator"]["nfev"] > 0
            assert info["t"][i] == pytest.approx(inf["t"])
    assert trunc.all()


def test_same_step_autoreset_keeps_the_final_observation():
    from gymnasium.vector import AutoresetMode

    venv = FlatBodyVectorEnv(num_envs=2, max_episode_steps=3, autoreset_mode=AutoresetMode.SAME_STEP)
    venv.reset(seed=0)
    single = FlatBodyEnv()
    single.reset(seed=0)
    for _k in range(3):
        obs, _, _, trunc, info = venv.step(np.zeros((2, 4)))
        o = single.step(np.zeros(4))[0]
    assert trunc.all() and info["_final_obs"].all()
    np.testing.assert_array_equal(info["final_obs"][0], o)
    np.testing.assert_array_equal(
        obs[0], single.reset()[0]
    )  # the next episode's first observation, drawn as a single env would


def test_bad_vector_actions_and_mode():
    venv = FlatBodyVectorEnv(num_envs=2)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="actions"):
        venv.step(np.full((2, 4), np.nan))
    with pytest.raises(ValueError, match="autoreset_mode"):
        FlatBodyVectorEnv(num_envs=2, autoreset_mode="Disabled")


@pytest.mark.parametrize("kernels", ["compiled", "python"])
@pytest.mark.parametrize("bodies", ["one isotropic", "one anisotropic", "each its own"])
def test_lane_bookkeeping_equals_the_per_body_kernel(kernels, bodies):
    """post_step_lanes (loops over bodies, vectorised) is post_step body by body, bit for bit, with
    failed steps, non-finite states and states outside the domain among the lanes — for one body in every lane and
    for a body of its own in each (inertia, potential and thickness constants; J1 ≠ J2 in some lanes)."""
    from flatbody_env.env import kernels as python_kernels

    k = compiled if kernels == "compiled" else python_kernels
    n = 97
    venv = FlatBodyVectorEnv(num_envs=n)
    venv.reset(seed=1)
    p = venv.config
    rng = np.random.default_rng(2)
    P = np.repeat(np.array(p.body.kernel_params())[:, None], n, axis=1)
    if bodies == "one anisotropic":
        P[1] = 1.3
    elif bodies == "each its own":
        P[[0, 2, 4, 6, 7]] *= rng.uniform(0.5, 2.0, (5, n))
        P[1] = np.where(np.arange(n) % 3 == 0, 1.3 * P[0], P[0])
    Y_old = venv.states.T.copy()
    Y_new = Y_old + rng.normal(scale=0.02, size=Y_old.shape)
    Y_new[7, :4] = -1.0  # λ out of the domain
    Y_new[0, 4:7] = np.nan
    Y_new[3, 7:9] = 1e9  # |p| over the momentum bound
    status = np.zeros(n, np.int64)
    status[9:13] = 2  # the integrator failed
    A = rng.uniform(-1, 1, (n, 4))
    T = venv.target_vectors
    Y_out, OBS, TERMS, SC, ENDED = (
        np.empty((11, n)),
        np.empty((n, OBSERVATION_SIZE), np.float32),
        np.empty((len(REWARD_TERMS), n)),
        np.empty((4, n)),
        np.empty(n, np.int64),
    )
    k.post_step_lanes(
        Y_old,
        Y_new,
        status,
        A,
        4,
        T,
        p.kcfg,
        P,
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
    for i in range(n):
        y, obs, terms, sc = (
            np.empty(11),
            np.empty(OBSERVATION_SIZE, np.float32),
            np.empty(len(REWARD_TERMS)),
            np.empty(4),
        )
        ended = k.post_step(
            Y_old[:, i].copy(),
            Y_new[:, i].copy(),
            status[i],
            A[i].copy(),
            4,
            T[i].copy(),
            p.kcfg,
            P[:, i].copy(),
            y,
            obs,
            terms,
            sc,
            np.empty(7),
            np.empty(4),
        )
        assert ENDED[i] == ended
        np.testing.assert_array_equal(Y_out[:, i], y)
        np.testing.assert_array_equal(OBS[i], obs)
        np.testing.assert_array_equal(TERMS[:, i], terms)
        np.testing.assert_array_equal(SC[:, i], sc)
    assert ENDED[:13].all() and not ENDED[13:].any()  # the planted failures end their episodes, nothing else does


@pytest.mark.parametrize("control", ["torque+dilatation", "torque", "dilatation", "none"])
def test_controls_clip_and_scale_each_body_alike(control):
    """The transition's controls of N actions (the step path's compiled loop) equal the Python faces' on each action
    alone (the single env's call) and on the batch (the vector env's), and the clipping and scaling are the documented
    ones; a non-finite action gives its body no controls there and is refused by the faces."""
    env = FlatBodyEnv(control=control)
    n_act = env.action_space.shape[0]
    mask = env.mask.astype(np.uint8)
    rng = np.random.default_rng(0)
    A = rng.uniform(-2, 2, (50, n_act))
    core = EnvCore(env.config, 50)
    A_out, U = np.zeros_like(A), np.empty((4, 50))
    tr.cpu("controls_lanes")(A, core.S, core.K, core.xcfg, A_out, U)
    np.testing.assert_array_equal(env.config.controls(A)[1], U.T)
    for i in range(50):
        a, u = env.controls(A[i])
        np.testing.assert_array_equal(A_out[i], a)
        np.testing.assert_array_equal(U[:, i], u)
        clipped = np.clip(A[i], -1, 1) if mask.any() else np.zeros(n_act)
        np.testing.assert_array_equal(a, clipped)
        np.testing.assert_array_equal(u[mask.astype(bool)], clipped[: mask.sum()] * env.limits[mask.astype(bool)])
        assert not u[~mask.astype(bool)].any()
    A[7, 0] = np.inf
    tr.cpu("controls_lanes")(A, core.S, core.K, core.xcfg, A_out, U)
    assert not U[:, 7].any() and U[:, 8].any() == bool(mask.any())
    with pytest.raises(ValueError, match="action"):
        env.controls(A[7])


def _steps_alike(one, other, *, seed: int, steps: int) -> None:
    """``one`` and ``other`` (vector envs of the same bodies) reset with ``seed`` and stepped with the same random
    actions give the same observations, rewards, flags, energies and evaluation counts, number for number."""
    n = one.num_envs
    np.testing.assert_array_equal(one.reset(seed=seed)[0], other.reset(seed=seed)[0])
    rng = np.random.default_rng(seed + 1)
    for _ in range(steps):
        A = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        ra, rb = one.step(A), other.step(A)
        for x, y in zip(ra[:4], rb[:4]):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(ra[4]["energy"], rb[4]["energy"])
        np.testing.assert_array_equal(ra[4]["integrator"]["nfev"], rb[4]["integrator"]["nfev"])
    np.testing.assert_array_equal(one.states, other.states)


def test_threads_on_the_fused_batch_step_keep_their_own_work_and_every_number():
    """Cores large enough for the fused structure-of-arrays step (which writes its work arrays in place) step in
    threads at once: each has its own work arrays, and the batch steps exactly as in one thread."""
    from flatbody_env.env.core import FUSED_MIN_BODIES

    n = 2 * FUSED_MIN_BODIES + 6
    one = FlatBodyVectorEnv(num_envs=n, num_threads=1)
    two = FlatBodyVectorEnv(num_envs=n, num_threads=2)
    assert [c._mode for c in two.cores] == ["fused", "fused"]
    works = [c._stepper._fused for c in (*one.cores, *two.cores)]
    assert all(w is not None for w in works) and len({id(w) for w in works}) == 3  # none shared
    _steps_alike(one, two, seed=9, steps=25)
    two.close()


def test_a_body_drawn_per_episode_steps_fused_with_every_number_of_the_per_body_loop(monkeypatch):
    """``FlatBodyAnyBody-v1`` (each body's constants drawn per episode): a batch large enough steps through the fused
    DOP853 with each lane's own parameters, and gives what the per-body loop gives, number for number, across
    episode ends and autoresets (new bodies drawn)."""
    import gymnasium as gym

    from flatbody_env.env import core
    from flatbody_env.env import transition as tr
    from flatbody_env.env.core import FUSED_MIN_BODIES

    kwargs = dict(gym.spec("FlatBodyAnyBody-v1").kwargs)
    n = FUSED_MIN_BODIES + 5
    fused = FlatBodyVectorEnv(num_envs=n, max_episode_steps=12, **kwargs)
    monkeypatch.setattr(core, "FUSED_MIN_BODIES", 10**9)
    loop = FlatBodyVectorEnv(num_envs=n, max_episode_steps=12, **kwargs)
    assert [c._mode for c in fused.cores] == ["fused"] and [c._mode for c in loop.cores] == ["lanes"]
    _steps_alike(fused, loop, seed=21, steps=30)
    J = fused.cores[0].S[tr.P0].copy()
    assert np.unique(J).size == n  # a body of its own in every lane
    fused.reset(seed=21)
    assert not np.array_equal(J, fused.cores[0].S[tr.P0])  # the autoresets (every 12 steps) drew other bodies


def test_threads_do_not_change_a_single_number():
    """Bodies split across threads (num_threads) step, score and autoreset exactly as in one thread."""
    n = 11
    one = FlatBodyVectorEnv(num_envs=n, max_episode_steps=6, num_threads=1)
    three = FlatBodyVectorEnv(num_envs=n, max_episode_steps=6, num_threads=3)
    assert three.num_threads == 3 and [s.stop - s.start for s in three._slices] == [4, 3, 4]
    _steps_alike(one, three, seed=4, steps=20)
    three.close()
    assert FlatBodyVectorEnv(num_envs=4, integrator="RK45", num_threads=2).num_threads == 1  # not compiled: one thread
    assert FlatBodyVectorEnv(num_envs=4).num_threads == 1  # the default
    with pytest.raises(ValueError, match="num_threads"):
        FlatBodyVectorEnv(num_envs=4, num_threads=0)
    with pytest.raises(ValueError, match="num_threads"):
        FlatBodyVectorEnv(num_envs=4, num_threads=True)
