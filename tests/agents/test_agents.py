"""Agents: hand-designed controllers (physics checks), evaluation metrics, train/resume/evaluate/demo commands."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import flatbody_env  # noqa: F401  (registers FlatBody-v0)
from agents.heuristic import (
    REDUCED_STATE,
    HeuristicController,
    HeuristicGains,
    PassivityController,
    linearize,
    state_from_observation,
)
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.hamiltonian import hamiltonian, velocities_from_momenta

ROOT = Path(__file__).resolve().parents[1]


def _cli(*args: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    return subprocess.run(
        [sys.executable, "-m", "flatbody_env.cli", *args],
        capture_output=True,
        text=True,
        cwd=cwd or ROOT,
        env=env,
        timeout=timeout,
    )


def _target_state(env) -> np.ndarray:
    tg = env.unwrapped.target
    return np.array([0.0, 0.0, tg["s3"], tg["p_theta"], 0.0, 0.0, 0.0, tg["lambda"], tg["mu"], tg["rho"], 0.0])


# --- the hand-designed controllers -----------------------------------------------------------------
def test_target_is_an_equilibrium_of_the_reduced_system():
    env = gym.make("FlatBody-v0")
    for seed in range(3):
        env.reset(seed=seed)
        y = _target_state(env)
        dy = rhs(0.0, y, None, env.unwrapped.body)
        np.testing.assert_allclose(dy[list(REDUCED_STATE)], 0.0, atol=1e-9)


def test_linearization_matches_a_small_step_and_lqr_stabilizes_it():
    env = gym.make("FlatBody-v0")
    env.reset(seed=3)
    u = env.unwrapped
    y = _target_state(env)
    A, B = linearize(u.body, y, u.limits)
    # a small perturbation evolves as A dx (independent central-difference check of one direction)
    rng = np.random.default_rng(0)
    dx = rng.normal(size=9) * 1e-6
    yp = y.copy()
    yp[list(REDUCED_STATE)] += dx
    a = rng.uniform(-1, 1, 4) * 1e-6
    lin = A @ dx + B @ a
    full = rhs(0.0, yp, a * u.limits, u.body)[list(REDUCED_STATE)]
    np.testing.assert_allclose(full, lin, atol=1e-10)  # second-order remainder ~ |dx|^2
    # thickness force moves only p_rho; tau_1,2 only s1, s2 (the shape is reached through s3 only)
    assert np.count_nonzero(np.abs(B) > 1e-9) == 4
    K = HeuristicController.for_env(env).gain(y)
    assert np.max(np.linalg.eigvals(A - B @ K).real) < -1e-3
    assert np.max(np.linalg.eigvals(A).real) < 1e-6  # open loop: undamped oscillations (stable target)


def test_lqr_batch_uses_stored_table_gains_close_to_the_exact_ones():
    """One vectorised call acts for the whole batch with per-row gains (interpolated from the shipped
    table of exact gains), equal to the row-by-row law; only rows whose target changed get new gains."""
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    venv = FlatBodyVectorEnv(num_envs=6)
    obs, _ = venv.reset(seed=11)
    ctl = HeuristicController(venv.body, venv.control, venv.limits)
    exact = HeuristicController(venv.body, venv.control, venv.limits, exact=True)
    assert ctl._table is not None and exact._table is None
    a = ctl.act(obs)
    y, target = state_from_observation(obs)
    K_exact = exact.gains(target.T, y[3])
    K_table = ctl._K.copy()
    rel = np.max(np.abs(K_table - K_exact), axis=(1, 2)) / np.max(np.abs(K_exact), axis=(1, 2))
    assert rel.max() < 0.03, rel  # bilinear in (lambda*, 1/(lambda* mu*)); median ~1e-4
    for i in range(6):  # the same law, row by row
        ystar = np.array(
            [0.0, 0.0, target[3, i], y[3, i], 0.0, 0.0, 0.0, target[0, i], target[1, i], target[2, i], 0.0]
        )
        dx = (y[:, i] - ystar)[list(REDUCED_STATE)]
        np.testing.assert_allclose(a[i], np.clip(-K_table[i] @ dx, -1, 1).astype(np.float32), rtol=1e-6, atol=1e-7)
    obs2 = obs.copy()
    obs2[2, 12] += 0.05  # a new target for row 2 only
    ctl.act(obs2)
    np.testing.assert_array_equal(np.delete(ctl._K, 2, axis=0), np.delete(K_table, 2, axis=0))
    assert not np.array_equal(ctl._K[2], K_table[2])
    # the closed loop with the table gain is stable, as with the exact one
    A, B = linearize(
        venv.body, np.array([0.0, 0.0, target[3, 0], y[3, 0], 0.0, 0.0, 0.0, *target[:3, 0], 0.0]), venv.limits
    )
    assert np.max(np.linalg.eigvals(A - B @ K_table[0]).real) < -1e-3
    # another control mode: the table does not apply, exact gains
    torque = HeuristicController(venv.body, "torque", venv.limits)
    assert torque._table is None and torque.act(obs).shape == (6, 3)


def test_passivity_controller_decreases_its_lyapunov_function():
    env = gym.make("FlatBody-v0", integrator="DOP853")
    obs, _ = env.reset(seed=11)
    u = env.unwrapped
    g = HeuristicGains()
    ctl = PassivityController.for_env(env, g)
    tg = u.target

    def lyap(y):
        return (
            hamiltonian(y, u.body)
            - tg["omega3"] * y[2]
            + 0.5 * g.c_s3 * (y[2] - tg["s3"]) ** 2
            + 0.5 * g.k_rho * (y[9] - tg["rho"]) ** 2
        )

    # the target's omega3 is what the controller regulates to
    y_star = _target_state(env)
    assert velocities_from_momenta(y_star, u.body)["omega3"] == pytest.approx(tg["omega3"], rel=1e-9)
    values = [lyap(u.physics_state)]
    for _ in range(40):
        obs, *_ = env.step(ctl.action(obs))
        values.append(lyap(u.physics_state))
    assert np.all(np.diff(values) <= 1e-9)
    assert values[-1] < values[0] - 1e-3


def test_residual_actions_keep_the_target_an_equilibrium():
    from agents.heuristic import ResidualAction

    env = gym.make("FlatBody-v0")
    env.reset(seed=5)
    u = env.unwrapped
    tg = u.target
    at_target = {
        "s1": 0.0,
        "s2": 0.0,
        "s3": tg["s3"],
        "p_theta": tg["p_theta"],
        "p_lambda": 0.0,
        "p_mu": 0.0,
        "p_rho": 0.0,
        "lambda": tg["lambda"],
        "mu": tg["mu"],
        "rho": tg["rho"],
        "theta": 0.4,
    }
    obs_star, _ = env.reset(
        seed=5,
        options={
            "target": {"lambda": tg["lambda"], "mu": tg["mu"], "sign": float(np.sign(tg["p_theta"]))},
            "state": at_target,
        },
    )
    obs_off, _ = env.reset(seed=5)
    obs = np.stack([obs_star, obs_off])
    rng = np.random.default_rng(0)
    policy = rng.uniform(-1, 1, (2, 4))
    lqr, _ = HeuristicController.for_env(env).predict(obs)
    gain = ResidualAction(scale=1.0, mode="gain")(obs, policy)
    np.testing.assert_allclose(gain[0], 0.0, atol=1e-6)  # a_LQR = 0 at the target, whatever the policy says
    np.testing.assert_allclose(gain[1], np.clip(lqr[1] * (1 + policy[1]), -1, 1), rtol=1e-6)
    add = ResidualAction(scale=0.3)(obs, policy)
    np.testing.assert_allclose(add[0], 0.3 * policy[0], rtol=1e-6)  # an ungated residual biases the target
    gated = ResidualAction(scale=0.3, gate=0.1)(obs, policy)
    np.testing.assert_allclose(gated[0], 0.0, atol=1e-6)
    d_off = u.task.distance(u.physics_state, u.body, np.array([tg[k] for k in ("lambda", "mu", "rho", "s3")]))
    assert d_off > 0.1  # far from the target the gated residual acts in full
    np.testing.assert_allclose(gated[1], np.clip(lqr[1] + 0.3 * policy[1], -1, 1), rtol=1e-6)
    with pytest.raises(ValueError, match="residual_mode"):
        ResidualAction(mode="other")


def test_state_from_observation_roundtrip():
    env = gym.make("FlatBody-v0")
    obs, _ = env.reset(seed=4)
    y, target = state_from_observation(obs)
    np.testing.assert_allclose(y, env.unwrapped.physics_state, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(target, [env.unwrapped.target[k] for k in ("lambda", "mu", "rho", "s3")], rtol=1e-6)


# --- evaluation -----------------------------------------------------------------------------------
def test_baseline_metrics_are_physical_and_seeded():
    from agents.evaluate import run_episodes, summarize

    zero = run_episodes("zero", episodes=3, seed=100)
    # no control: H is conserved (eq. (41)), zero effort
    assert all(abs(r["energy_change"]) < 1e-6 for r in zero)
    assert all(r["action_effort"] == 0.0 for r in zero)
    rnd = summarize(run_episodes("random", episodes=3, seed=100))
    assert rnd["action_effort"] == pytest.approx(4 / 3, rel=0.1)  # E‖a‖² for a ~ U[-1, 1]^4
    h1 = run_episodes("heuristic", episodes=3, seed=100)
    h2 = run_episodes("heuristic", episodes=3, seed=100)
    assert h1 == h2
    # the hand-designed controller does better than doing nothing
    assert np.mean([r["final_distance"] for r in h1]) < np.mean([r["final_distance"] for r in zero])
    # the default task samples only targets reachable within the episode (settling rate >= 0.15/s):
    # the LQR about the target reaches every one of them
    assert all(r["success"] for r in h1)
    for r in h1:
        if r["success"]:
            assert r["final_distance"] <= 0.05 and r["time_to_reach"] is not None


# --- commands -------------------------------------------------------------------------------------
def test_cli_errors_are_one_line(tmp_path):
    for args in (
        ["evaluate", "--episodes", "0"],
        ["evaluate", str(tmp_path / "nothing")],
        ["train", "--algo", "ppo", "--hyperparams", "oops", "--out", str(tmp_path / "x")],
        ["train", "--algo", "ppo", "--resume", "--out", str(tmp_path / "none")],
    ):
        p = _cli(*args)
        assert p.returncode == 2, (args, p.stderr)
        assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr


@pytest.mark.slow  # a long equality/training check (pytest -m slow); shorter ones of the same path run by default
def test_train_resume_evaluate_smoke(tmp_path):
    out = tmp_path / "run"
    common = [
        "train",
        "--algo",
        "ppo",
        "--n-envs",
        "4",
        "--out",
        str(out),
        "--checkpoint-freq",
        "256",
        "--keep-checkpoints",
        "--no-progress",
        "--hyperparams",
        "n_steps=64",
        "batch_size=64",
        "n_epochs=2",
    ]
    p = _cli(*common, "--n-timesteps", "512")
    assert p.returncode == 0, p.stderr
    for name in ("model.zip", "vecnormalize.pkl", "config.yml", "run.json"):
        assert (out / name).exists(), name
    run = json.loads((out / "run.json").read_text())
    assert run["n_timesteps"] == 512 and run["torch_threads"] == 1
    assert run["command_line"].startswith("flatbody train --algo ppo")
    assert run["git_hash"] == "unknown" or len(run["git_hash"]) == 40
    cfg = yaml.safe_load((out / "config.yml").read_text())
    assert cfg["algo"] == "ppo" and cfg["hyperparams"]["n_steps"] == 64 and cfg["hyperparams"]["n_envs"] == 4
    assert sorted(p.name for p in (out / "checkpoints").glob("*.zip")) == [
        "rl_model_256_steps.zip",
        "rl_model_512_steps.zip",
    ]

    p = _cli("train", "--algo", "ppo", "--out", str(out), "--resume", "--n-timesteps", "1024", "--no-progress")
    assert p.returncode == 0, p.stderr
    assert "resumed from 512" in p.stdout
    run = json.loads((out / "run.json").read_text())
    assert run["n_timesteps"] == 1024 and run["resumed_from"] == 512
    assert not (out / "checkpoints").exists()  # removed after a completed run without --keep-checkpoints

    p = _cli("evaluate", str(out), "--episodes", "2", "--seed", "5", "--json")
    assert p.returncode == 0, p.stderr
    report = json.loads(p.stdout)
    from agents.evaluate import baselines_for

    assert set(report["baselines"]) == set(baselines_for(cfg["env_id"]))  # the task's own (the planner among them)
    for s in [report["agent"], *report["baselines"].values()]:
        assert {"success_rate", "final_distance", "time_to_reach", "energy_change", "action_effort"} <= set(s)
        assert 0.0 <= s["success_rate"] <= 1.0 and s["final_distance"] >= 0.0


@pytest.mark.slow  # trains agents: a training check (pytest -m slow)
def test_sac_trains_and_saves(tmp_path):
    out = tmp_path / "sac"
    p = _cli(
        "train",
        "--algo",
        "sac",
        "--env",
        "FlatBody-v0",  # its entry uses gSDE (the v1 entries do not)
        "--n-timesteps",
        "256",
        "--n-envs",
        "2",
        "--out",
        str(out),
        "--no-progress",
        "--checkpoint-freq",
        "0",
        "--hyperparams",
        "learning_starts=64",
        "batch_size=32",
        "train_freq=4",
        "gradient_steps=1",
    )
    assert p.returncode == 0, p.stderr
    assert (out / "model.zip").exists() and (out / "vecnormalize.pkl").exists()
    from agents.evaluate import Agent, run_episodes

    agent = Agent(out)
    assert agent.algo == "sac"
    rec = run_episodes(agent, episodes=1, seed=3, env_kwargs=agent.env_kwargs)
    assert rec[0]["length"] >= 1
    # the shipped SAC settings use gSDE, whose actor ends in a Hardtanh the numpy evaluator does not run:
    # training still succeeds, says so in one line, and evaluate/demo run the policy with SB3
    assert not (out / "policy.npz").exists()
    assert "no policy.npz exported" in p.stderr and "Hardtanh" in p.stderr
    assert agent.backend == "sb3"


def test_shipped_model_is_small_and_loads():
    from agents.evaluate import Agent, shipped_model_dir

    folder = shipped_model_dir()
    size = sum(f.stat().st_size for f in folder.iterdir())
    assert size < 2_000_000  # model.zip (actor and critic, float32) and policy.npz (the actor): about 1.3 MB
    run = json.loads((folder / "run.json").read_text())
    assert run["command_line"].startswith("flatbody train")
    agent = Agent()
    assert agent.env_id == "FlatBody-v1" and agent.residual is None  # from scratch on the v1 task
    env = gym.make(agent.env_id)
    obs = np.stack([env.reset(seed=s)[0] for s in range(3)])
    actions = agent(obs)
    assert actions.shape == (3, 4) and np.all(np.abs(actions) <= 1.0)


def test_demo_runs_with_defaults(tmp_path):
    p = _cli("demo", "--out", str(tmp_path / "demo.rrd"), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "flatbody demo" in p.stdout and "distance" in p.stdout
    assert (tmp_path / "demo.rrd").stat().st_size > 0


@pytest.mark.slow
def test_shipped_evaluation_reproduces():
    """A fresh 100-episode evaluation reproduces the shipped ``evaluation.json`` (README table).

    Exact with the integrator the table was made with; a different default integrator moves the
    trajectories slightly, hence the tolerances.
    """
    from agents.evaluate import evaluate_all, shipped_model_dir

    saved = json.loads((shipped_model_dir() / "evaluation.json").read_text())
    report = evaluate_all(episodes=saved["episodes"], seed=saved["seed"])
    for name, new, old in [("agent", report["agent"], saved["agent"])] + [
        (k, report["baselines"][k], saved["baselines"][k]) for k in ("zero", "heuristic", "passivity")
    ]:
        assert new["success_rate"] == pytest.approx(old["success_rate"], abs=0.05), name
        assert new["final_distance"] == pytest.approx(old["final_distance"], rel=0.05), name


@pytest.mark.slow
def test_shipped_agent_acceptance():
    """Acceptance on held-out seeds the shipped evaluation never used: ≥ 95 % success over 100 episodes (the v1 goal of
    a learned agent from scratch) and a mean final distance inside the tolerance."""
    from agents.evaluate import evaluate_all

    report = evaluate_all(episodes=100, seed=20_000, baselines=False)
    agent = report["agent"]
    assert report["env_id"] == "FlatBody-v1"
    assert agent["success_rate"] >= 0.95
    assert agent["final_distance"] < 0.05


def test_record_agent_episode(tmp_path, capsys):
    """``flatbody record --agent``: the shipped agent's episode, read back with rerun's reader."""
    from flatbody_env.cli.main import main
    from flatbody_env.recording.reader import read_recording

    out = tmp_path / "agent.rrd"
    assert main(["record", "--agent", "--seed", "3", "--out", str(out)]) == 0
    data = read_recording(out)
    assert any(path.startswith("/series/action/") for path in data.entities)
    assert any(path.startswith("/series/reward/") for path in data.entities)
    assert "/world/body" in data.entities
    with pytest.raises(SystemExit) as info:
        raise SystemExit(main(["record", "--agent", "--scene", "default", "--out", str(out)]))
    assert info.value.code == 2


def _batch(env_id: str, n: int, seed: int):
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    from agents.evaluate import env_kwargs_for

    venv = FlatBodyVectorEnv(num_envs=n, **env_kwargs_for(env_id))
    obs, _ = venv.reset(seed=seed)
    return venv, obs


def test_thickness_pumping_acts_only_where_the_thickness_is_off_and_unforced():
    from agents.heuristic import PumpingController, PumpingGains

    venv, obs = _batch("FlatBodyTorque-v1", 3, 10_000)
    g = PumpingGains()
    pump = PumpingController(venv.body, venv.control, venv.limits, gains=g)
    lqr = HeuristicController(venv.body, venv.control, venv.limits)
    rho_star = obs[:, 14].copy()
    obs = obs.astype(np.float64)
    # row 0: at rest out of plane, the thickness moving inward far from its target: spin up along s1, at full torque
    obs[0, [0, 1, 6, 9]] = (0.0, 0.0, -0.2, rho_star[0] + 0.1)
    # row 1: spinning out of plane while the thickness moves outward: spin down along (s1, s2)
    obs[1, [0, 1, 6, 9]] = (0.3, 0.4, 0.2, rho_star[1])
    # row 2: the thickness mode below the gate: the LQR unchanged
    obs[2, [6, 9]] = (0.5 * g.gate, rho_star[2])
    a, a_lqr = pump.act(obs), lqr.act(obs)
    assert a.shape == a_lqr.shape == (3, 3)
    np.testing.assert_array_equal(a[:, 2], a_lqr[:, 2])  # τ3 is always the LQR's
    np.testing.assert_allclose(a[0, :2], [1.0, 0.0])
    push = np.clip(g.k_spin * (0.0 - 0.5), -1, 1)
    np.testing.assert_allclose(a[1, :2], [push * 0.6, push * 0.8], rtol=1e-6)
    np.testing.assert_array_equal(a[2], a_lqr[2])
    # one observation at a time is the batch's row
    for k in range(3):
        np.testing.assert_array_equal(pump.action(obs[k]), a[k])
    assert pump.channel == "thickness"
    assert PumpingController(venv.body, "torque+dilatation", venv.limits).channel == "shape"
    assert PumpingController(venv.body, "dilatation", venv.limits).channel == "none"


def test_shape_pumping_acts_only_toward_slow_targets_and_while_the_shape_moves_inward():
    from agents.heuristic import PumpingController, PumpingGains

    venv, obs = _batch("FlatBodySlowHard-v1", 24, 10_000)
    g = PumpingGains()
    pump = PumpingController(venv.body, venv.control, venv.limits, gains=g)
    assert pump.channel == "shape"
    lqr = HeuristicController(venv.body, venv.control, venv.limits)
    rates = pump.settling_rates(obs)
    slow, fast = np.flatnonzero(rates < g.shape_below_rate), np.flatnonzero(rates >= g.shape_below_rate)
    assert len(slow) >= 3 and len(fast) >= 3  # the hard rung draws both
    o = obs.astype(np.float64)
    # λ well inside its target and moving inward, μ on target, a little s1: spin s2 up (it pushes λ out), s1 down
    o[:, [0, 1, 4, 5]] = (0.05, 0.0, -0.1, 0.0)
    o[:, 7] = o[:, 12] - 0.1
    o[:, 8] = o[:, 13]
    a, a_lqr = pump.act(o), lqr.act(o)
    np.testing.assert_array_equal(a[fast], a_lqr[fast])  # toward fast targets, the LQR
    np.testing.assert_array_equal(a[slow, 2:], a_lqr[slow, 2:])  # τ3 and the thickness force: the LQR's
    np.testing.assert_allclose(a[slow, 1], 1.0)  # full torque on s2, the spin asked: min(0.7, 50 · 0.1)
    np.testing.assert_allclose(a[slow, 0], g.k_spin * (0.0 - 0.05), rtol=1e-6)  # μ on target: s1 driven to 0
    # λ moving outward: no spin asked anywhere, the LQR alone
    o[:, 4] = 0.1
    np.testing.assert_array_equal(pump.act(o), lqr.act(o))


def test_thickness_pumping_drains_the_thickness_mode_the_lqr_leaves_alone():
    """Torque alone moves the thickness only through the centrifugal force of the out-of-plane spin; the LQR (linear)
    leaves the thickness mode's amplitude where it started, the pumping law takes most of it out."""
    from agents.heuristic import PumpingController

    n = 8
    amplitudes = {}
    for name, cls in (("lqr", HeuristicController), ("pumping", PumpingController)):
        venv, obs = _batch("FlatBodyTorque-v1", n, 10_000)
        law = cls(venv.body, venv.control, venv.limits)
        start = np.hypot(obs[:, 9] - obs[:, 14], obs[:, 6])
        for _ in range(300):
            obs, *_ = venv.step(law.act(obs))
        amplitudes[name] = (start, np.hypot(obs[:, 9] - obs[:, 14], obs[:, 6]))
    start, lqr_end = amplitudes["lqr"]
    assert np.all(start >= 0.05 - 1e-9)  # every start is off in the thickness (the task's min_uncontrolled_offset)
    assert np.median(lqr_end / start) > 0.5
    pump_end = amplitudes["pumping"][1]
    assert np.median(pump_end / start) < 0.3
    assert np.mean(pump_end) < 0.5 * np.mean(lqr_end)


def test_the_pumping_baseline_belongs_to_the_v1_reach_tasks():
    from agents.evaluate import PUMPING, baselines_for
    from flatbody_env.env.registration import TASK_IDS, task_spec

    for env_id in TASK_IDS:
        spec = task_spec(env_id)
        expected = spec.version >= 1 and spec.kwargs["task"] != "hold-unstable"
        assert (PUMPING in baselines_for(env_id)) == expected, env_id
    assert PUMPING in baselines_for("FlatBodyTorque-v1") and PUMPING not in baselines_for("FlatBodyHoldUnstable-v1")


def test_a_residual_on_the_pumping_law_is_the_law_when_the_policy_is_silent():
    from agents.evaluate import env_kwargs_for, residual_action
    from agents.heuristic import PumpingController

    venv, obs = _batch("FlatBodyTorque-v1", 4, 10_000)
    law = PumpingController(venv.body, venv.control, venv.limits)
    res = residual_action(
        env_kwargs_for("FlatBodyTorque-v1"), {"residual": "pumping", "residual_scale": 0.5, "residual_mode": "additive"}
    )
    assert res.base == "pumping"
    np.testing.assert_array_equal(res(obs, np.zeros((4, 3))), law.act(obs))
    moved = res(obs, np.ones((4, 3)))
    np.testing.assert_allclose(moved, np.clip(law.act(obs) + 0.5, -1, 1), rtol=1e-6)
    from agents.heuristic import ResidualAction

    with pytest.raises(ValueError, match="^residual: must be one of heuristic, passivity, pumping"):
        ResidualAction(env_kwargs_for("FlatBodyTorque-v1"), base="pid")


def test_shape_pumping_settles_the_slow_targets_shape_faster_than_the_lqr():
    """Toward targets the LQR settles slowly, the out-of-plane spin's centrifugal force (−∂T/∂λ ∋ Jλω2²), applied while
    the shape moves inward, takes the in-plane error ‖(Δλ, Δμ, p_λ, p_μ)‖ down further in 15 s, target by target."""
    from agents.heuristic import PumpingController

    ratios = {}
    for name in ("lqr", "pumping"):
        venv, obs = _batch("FlatBodySlowHard-v1", 24, 10_000)
        pump = PumpingController(venv.body, venv.control, venv.limits)
        law = pump if name == "pumping" else pump.lqr
        slow = pump.settling_rates(obs.astype(np.float64)) < pump.gains.shape_below_rate

        def shape_error(o):
            o = o.astype(np.float64)
            return np.sqrt((o[:, 7] - o[:, 12]) ** 2 + (o[:, 8] - o[:, 13]) ** 2 + o[:, 4] ** 2 + o[:, 5] ** 2)

        start = shape_error(obs)
        for _ in range(300):
            obs, *_ = venv.step(law.act(obs))
        ratios[name] = (shape_error(obs) / start)[slow]
    assert len(ratios["lqr"]) >= 3
    assert np.all(ratios["pumping"] < ratios["lqr"])
    assert np.median(ratios["pumping"]) < 0.5 * np.median(ratios["lqr"])
