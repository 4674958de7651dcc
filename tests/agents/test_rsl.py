"""rsl_rl's PPO (``flatbody train --algo rsl-ppo``, agents/rsl.py): the LQR residual in torch equals the numpy one,
the export to SB3's format is exact, the adapter keeps rsl_rl's ``VecEnv`` contract, a short run writes the SB3
path's run folder and ``flatbody evaluate`` runs it unchanged; the slow test: the residual policy learns to beat the LQR."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")
pytest.importorskip("rsl_rl")

from agents.heuristic import ResidualAction  # noqa: E402
from agents.config import load_hyperparams  # noqa: E402

DEFAULTS = load_hyperparams("rsl-ppo", "FlatBody-v0")
"""The residual agent's settings (rsl-ppo.yml's FlatBody-v0 entry)."""
from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv  # noqa: E402


def _observations(n=12, steps=5):
    env = FlatBodyTorchVectorEnv(n, max_episode_steps=3)
    obs, _ = env.reset(seed=4)
    seen = [obs.clone()]
    for _ in range(steps):  # through resets: new targets, new gains
        obs = env.step(torch.zeros(n, 4))[0]
        seen.append(obs.clone())
    return seen


@pytest.mark.parametrize("mode", ["gain", "additive"])
def test_torch_residual_equals_the_numpy_residual(mode):
    from agents.rsl import TorchResidual

    res = TorchResidual({}, 0.7, mode, "cpu")
    ref = ResidualAction({}, 0.7, 0.0, mode)
    rng = np.random.default_rng(0)
    for obs in _observations():
        a = rng.uniform(-1.5, 1.5, (obs.shape[0], 4)).astype(np.float32)
        got = res(obs, torch.from_numpy(a)).numpy()
        np.testing.assert_allclose(got, ref(obs.numpy(), a), rtol=0, atol=2e-6)
    assert res.refreshed > 12  # the gains were refreshed at the resets
    with pytest.raises(ValueError, match="residual_gate"):
        TorchResidual({}, 1.0, "additive", "cpu", gate=0.1)


def test_adapter_contract_and_exact_export(tmp_path):
    from agents.rsl import RslVecEnv, TorchResidual, export_sb3, runner_config

    from rsl_rl.runners import OnPolicyRunner
    from stable_baselines3 import PPO

    n = 8
    env = FlatBodyTorchVectorEnv(n, max_episode_steps=5)
    venv = RslVecEnv(env, TorchResidual({}, 1.0, "gain", "cpu"), seed=0)
    td = venv.get_observations()
    assert td["policy"].shape == (n, 16) and td["policy"].dtype == torch.float32
    venv.episode_length_buf = torch.arange(n)  # rsl_rl's init_at_random_ep_len writes here
    np.testing.assert_array_equal(venv.episode_length_buf.numpy(), np.minimum(np.arange(n), 4))
    obs, rew, dones, extras = venv.step(torch.zeros(n, 4))
    assert rew.dtype == torch.float32 and dones.dtype == torch.long
    np.testing.assert_array_equal(dones.numpy(), (np.minimum(np.arange(n), 4) + 1 >= 5).astype(np.int64))
    assert extras["time_outs"].equal(dones.float()) and "/episode/final_distance" in extras["log"]
    hp = {**DEFAULTS, "num_steps_per_env": 4}
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        runner = OnPolicyRunner(venv, runner_config(hp), log_dir=None, device="cpu")
        runner.learn(1)
    actor = runner.alg.actor
    assert not isinstance(actor.obs_normalizer, torch.nn.Identity) and actor.obs_normalizer._mean.abs().sum() > 0
    export_sb3(actor, runner.alg.critic, tmp_path / "m.zip", hp, 0)
    model = PPO.load(str(tmp_path / "m.zip"), device="cpu")
    o = venv.get_observations()["policy"]
    with torch.no_grad():
        want = actor(venv.get_observations()).clamp(-1, 1).numpy()
        value = runner.alg.critic(venv.get_observations()).numpy()[:, 0]
        got_value = model.policy.predict_values(o).numpy()[:, 0]
    got, _ = model.predict(o.numpy(), deterministic=True)
    np.testing.assert_allclose(got, want, atol=1e-5)
    np.testing.assert_allclose(got_value, value, rtol=1e-5, atol=1e-5)


def test_held_noise_is_held_for_k_rollout_steps_and_fresh_in_the_update():
    from agents.rsl import HeldGaussianDistribution

    torch.manual_seed(0)
    dist = HeldGaussianDistribution(4, hold_steps=3, init_std=1.5)
    mean = torch.zeros(5, 4)
    dist.update(mean)
    with torch.inference_mode():  # rsl_rl's rollout
        draws = [dist.sample().clone() for _ in range(7)]
    for k in (1, 2, 4, 5):
        assert torch.equal(draws[k], draws[k - 1])
    assert not torch.equal(draws[3], draws[2]) and not torch.equal(draws[6], draws[5])
    assert draws[0].std() > 0.5  # sigma 1.5 (mean 0)
    dist.update(mean + 1.0)  # a new mean moves the held sample with it
    with torch.inference_mode():
        assert torch.allclose(dist.sample(), draws[6] + 1.0)
    a, b = dist.sample(), dist.sample()  # outside inference mode (the update): a fresh draw each time
    assert not torch.equal(a, b)
    with torch.inference_mode():  # another batch shape: a fresh draw
        dist.update(torch.zeros(3, 4))
        assert dist.sample().shape == (3, 4)
    one = HeldGaussianDistribution(4, hold_steps=1)
    one.update(mean)
    with torch.inference_mode():
        assert not torch.equal(one.sample(), one.sample())
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="noise_hold_steps"):
            HeldGaussianDistribution(4, hold_steps=bad)


def test_reward_normalisation_scales_the_training_rewards_only():
    from agents.rsl import RslVecEnv, TorchResidual

    n = 16
    raw = RslVecEnv(FlatBodyTorchVectorEnv(n, max_episode_steps=6), TorchResidual({}, 1.0, "gain", "cpu"), seed=1)
    norm = RslVecEnv(
        FlatBodyTorchVectorEnv(n, max_episode_steps=6), TorchResidual({}, 1.0, "gain", "cpu"), seed=1, reward_gamma=0.9
    )
    for _ in range(12):
        _, r_raw, _, _ = raw.step(torch.zeros(n, 4))
        _, r_norm, _, _ = norm.step(torch.zeros(n, 4))
        scale = r_raw / r_norm
        assert torch.allclose(scale, scale[0].expand_as(scale), rtol=1e-4)  # one positive factor for the whole batch
        assert float(scale[0]) > 0
    assert float(scale[0]) != pytest.approx(1.0)
    assert [e[0] for e in norm.episodes] == pytest.approx(
        [e[0] for e in raw.episodes]
    )  # episodes logged with raw rewards
    with pytest.raises(ValueError, match="gamma"):
        RslVecEnv(FlatBodyTorchVectorEnv(2), None, reward_gamma=1.5)


def test_short_run_writes_the_run_folder_and_evaluates(tmp_path, monkeypatch):
    from agents.evaluate import Agent, run_episodes
    from flatbody_env.cli.main import main

    monkeypatch.chdir(tmp_path)
    assert (
        main(
            [
                "train",
                "--algo",
                "rsl-ppo",
                "--env",
                "FlatBody-v0",
                "--num-envs",
                "8",
                "--n-timesteps",
                "100",
                "--device",
                "cpu",
                "--seed",
                "3",
                "--hyperparams",
                "num_steps_per_env=8",
                "--no-progress",
            ]
        )
        == 0
    )
    out = tmp_path / "runs" / "rsl-ppo-FlatBody-v0-seed3"
    assert {"model.zip", "config.yml", "run.json", "progress.csv", "policy.npz", "rsl_model.pt"} <= {
        p.name for p in out.iterdir()
    }
    cfg = yaml.safe_load((out / "config.yml").read_text())
    assert (
        cfg["algo"] == "rsl-ppo"
        and cfg["model_format"] == "ppo"
        and cfg["seed"] == 3
        and cfg["hyperparams"]["residual"] == "heuristic"
        and cfg["prior"] == {"residual": "heuristic"}
    )
    run = json.loads((out / "run.json").read_text())
    assert run["algo"] == "rsl-ppo" and run["n_timesteps"] == 128 and run["versions"]["rsl-rl-lib"] == "5.5.1"
    assert len((out / "progress.csv").read_text().splitlines()) == 3
    agent = Agent(out)
    assert agent.backend == "numpy" and agent.residual == "heuristic"
    recs = run_episodes(agent, episodes=2, seed=10_000)
    assert len(recs) == 2 and all(np.isfinite(r["final_distance"]) for r in recs)
    assert (
        main(["train", "--algo", "rsl-ppo", "--out", str(tmp_path / "x"), "--hyperparams", "nope=1", "--no-progress"])
        == 2
    )
    assert (
        main(
            [
                "train",
                "--algo",
                "rsl-ppo",
                "--out",
                str(tmp_path / "z"),
                "--hyperparams",
                "learning_rate=fast",
                "--no-progress",
            ]
        )
        == 2
    )
    assert (
        main(
            [
                "train",
                "--algo",
                "rsl-ppo",
                "--out",
                str(tmp_path / "w"),
                "--hyperparams",
                "noise_hold_steps=0",
                "--no-progress",
            ]
        )
        == 2
    )
    assert main(["train", "--algo", "ppo", "--device", "cuda", "--out", str(tmp_path / "y")]) == 2
    assert not (tmp_path / "y").exists()


def test_callback_stops_the_run_and_the_live_policy_is_the_exported_agent(tmp_path):
    from agents.evaluate import Agent
    from agents.rsl import TorchResidual, live_policy
    from agents.train import train

    obs = _observations(n=6, steps=2)[-1].numpy()
    seen = []

    def callback(runner, row):
        seen.append(row["iteration"])
        live = live_policy(runner.alg.actor, TorchResidual({}, 1.0, "gain", "cpu"))
        seen.append(live(obs))
        if row["iteration"] == 1:  # the log is on disk while the run goes on (its first row at once)
            lines = (tmp_path / "run" / "progress.csv").read_text().splitlines()
            assert len(lines) == 2 and lines[0].startswith("iteration,timesteps,")
        return row["iteration"] == 2

    result = train(
        "rsl-ppo",
        tmp_path / "run",
        env_id="FlatBody-v0",
        seed=1,
        n_timesteps=10_000,
        n_envs=8,
        overrides=["num_steps_per_env=8"],
        progress=False,
        callback=callback,
    )
    assert seen[0::2] == [1, 2] and result.timesteps == 2 * 8 * 8
    assert json.loads((tmp_path / "run" / "run.json").read_text())["n_timesteps"] == 128
    assert len((tmp_path / "run" / "progress.csv").read_text().splitlines()) == 3
    np.testing.assert_allclose(
        Agent(tmp_path / "run")(obs), seen[-1], atol=1e-5
    )  # what the callback evaluated is what ships


@pytest.mark.slow
def test_residual_policy_beats_the_lqr_on_held_out_seeds(tmp_path):
    """rsl_rl's PPO on the LQR residual with the defaults (10^6 steps): every held-out episode succeeds and the mean final
    distance on 20 held-out seeds is below the LQR's (measured: 0.0008 vs 0.0018; seeds 1, 2: 0.0008, 0.0009)."""
    from agents.evaluate import Agent, run_episodes
    from agents.train import train

    out = tmp_path / "run"
    train("rsl-ppo", out, env_id="FlatBody-v0", seed=0, progress=False)
    seeds = dict(episodes=20, seed=50_000)
    records = run_episodes(Agent(out), **seeds)
    agent = np.mean([r["final_distance"] for r in records])
    lqr = np.mean([r["final_distance"] for r in run_episodes("heuristic", **seeds)])
    assert all(r["success"] for r in records)
    assert agent < lqr, (agent, lqr)


def test_from_scratch_option_trains_without_the_lqr_and_evaluates_unchanged(tmp_path):
    """``--hyperparams residual=null``: the policy's clipped action is the executed control (no LQR anywhere), and the
    exported agent, the live policy and the adapter agree on it."""
    from agents.rsl import RslVecEnv, TorchResidual, runner_config

    import contextlib
    import io

    from rsl_rl.runners import OnPolicyRunner

    from agents.evaluate import Agent
    from agents.rsl import live_policy
    from flatbody_env.cli.main import main

    out = tmp_path / "scratch"
    assert (
        main(
            [
                "train",
                "--algo",
                "rsl-ppo",
                "--env",
                "FlatBody-v0",
                "--num-envs",
                "8",
                "--n-timesteps",
                "64",
                "--device",
                "cpu",
                "--seed",
                "2",
                "--out",
                str(out),
                "--hyperparams",
                "residual=null",
                "num_steps_per_env=8",
                "init_std=0.5",
                "--no-progress",
            ]
        )
        == 0
    )
    cfg = yaml.safe_load((out / "config.yml").read_text())
    assert cfg["hyperparams"]["residual"] is None and cfg["hyperparams"]["init_std"] == 0.5
    agent = Agent(out)
    assert agent.residual is None and agent._base is None
    obs = _observations(n=6, steps=2)[-1].numpy()
    actor = torch.load(out / "rsl_model.pt", weights_only=False)
    venv = RslVecEnv(FlatBodyTorchVectorEnv(6), None, seed=0)
    hp = {**DEFAULTS, "residual": None, "num_steps_per_env": 8, "init_std": 0.5}
    with contextlib.redirect_stdout(io.StringIO()):
        runner = OnPolicyRunner(venv, runner_config(hp), log_dir=None, device="cpu")
    runner.alg.actor.load_state_dict(actor["actor"])
    live = live_policy(runner.alg.actor, None)(obs)
    np.testing.assert_allclose(agent(obs), live, atol=1e-5)  # the shipped action is the live one
    assert np.all(np.abs(live) <= 1.0)
    lqr = TorchResidual({}, 1.0, "gain", "cpu").lqr(torch.from_numpy(obs)).numpy()
    assert not np.allclose(live, lqr, atol=1e-3)  # not the LQR's action
    same = [
        RslVecEnv(FlatBodyTorchVectorEnv(6), None, seed=5) for _ in range(2)
    ]  # the adapter clips the policy's output itself
    o_big = same[0].step(torch.full((6, 4), 3.0))[0]["policy"]
    o_one = same[1].step(torch.ones(6, 4))[0]["policy"]
    o_zero = RslVecEnv(FlatBodyTorchVectorEnv(6), None, seed=5).step(torch.zeros(6, 4))[0]["policy"]
    assert torch.equal(o_big, o_one) and not torch.equal(o_one, o_zero)


def test_from_scratch_curve_evaluates_the_policy_it_ships_and_the_chart_reads_the_table(tmp_path):
    """The curve's last point is the saved agent's held-out evaluation (the run stops at the evaluation past the budget),
    and the chart is drawn from the saved CSV alone."""
    import csv

    from agents.evaluate import Agent, run_episodes
    from agents.rsl import CURVE_HEADER, from_scratch_curve, plot_curve

    table = tmp_path / "curve.csv"
    rows = from_scratch_curve(
        tmp_path / "run",
        table,
        budget_s=1e-3,
        eval_every_s=1e-3,
        episodes=2,
        eval_seed=10_000,
        overrides=["n_envs=8", "num_steps_per_env=8"],
    )
    assert len(rows) == 1 and rows[0][0] == 64  # stopped after the first iteration
    with open(table, newline="") as fh:
        saved = list(csv.reader(fh))
    assert tuple(saved[0]) == CURVE_HEADER and len(saved) == 2
    cfg = yaml.safe_load((tmp_path / "run" / "config.yml").read_text())
    assert cfg["hyperparams"]["residual"] is None and cfg["hyperparams"]["hidden_dims"] == [128, 128]
    recs = run_episodes(Agent(tmp_path / "run"), episodes=2, seed=10_000)
    assert float(saved[1][3]) == pytest.approx(np.mean([r["final_distance"] for r in recs]), rel=1e-4)
    png = tmp_path / "curve.png"
    plot_curve(table, png, budget_s=1e-3, episodes=2)
    assert png.stat().st_size > 10_000
    with pytest.raises(ValueError, match="budget_s"):
        from_scratch_curve(tmp_path / "bad", table, budget_s=0)


@pytest.mark.gpu
def test_rsl_ppo_trains_a_v1_task_on_the_gpu_and_the_agent_runs_on_the_cpu(tmp_path):
    """On a CUDA GPU: env and policy on the device (``flatbody train --device cuda``); the held-out evaluation made
    during training (the live policy on the GPU) equals the saved agent's evaluation on the CPU (numpy policy)."""
    import torch

    from agents.evaluate import Agent, HeldOutEvaluations, run_episodes
    from agents.train import train

    if not torch.cuda.is_available():
        pytest.skip("no CUDA GPU here")
    evals = HeldOutEvaluations("FlatBody-v1", [512], seed=10_000, episodes=4)
    result = train("rsl-ppo", tmp_path / "run", env_id="FlatBody-v1", seed=0, n_timesteps=512, n_envs=64,
                   overrides=["num_steps_per_env=8"], device="cuda", progress=False, evaluations=evals)  # fmt: skip
    assert result.timesteps == 512 and len(evals.points) == 1
    recs = run_episodes(Agent(tmp_path / "run"), episodes=4, seed=10_000, env_id="FlatBody-v1")
    assert evals.points[0]["final_distance"] == pytest.approx(np.mean([r["final_distance"] for r in recs]), rel=1e-3)


def test_the_gpu_curve_is_its_saved_run_record_and_the_docs_quote_it(tmp_path):
    """docs/img/rsl_ppo_cuda_v1.csv is :func:`agents.rsl.curve_from_run` of the saved record of the GPU run, and
    docs/agents.md quotes its first evaluation at 95 % (steps and seconds); a folder without the tables is refused."""
    from pathlib import Path

    from agents.rsl import curve_from_run

    root = Path(__file__).resolve().parents[2]
    rows = curve_from_run(root / "agents/data/gpu/rsl-ppo-FlatBody-v1-cuda", tmp_path / "c.csv")
    assert (tmp_path / "c.csv").read_text() == (root / "docs/img/rsl_ppo_cuda_v1.csv").read_text()
    steps, seconds, _, _ = next(r for r in rows if r[2] >= 0.95)
    text = " ".join((root / "docs/agents.md").read_text().split())
    assert f"95 % at {steps / 1e6:.1f} M steps, **{seconds:.1f} s** after the compile" in text
    with pytest.raises(ValueError, match="^run: "):
        curve_from_run(tmp_path, tmp_path / "x.csv")


def test_committed_from_scratch_chart_redraws_from_its_table_without_overlaps(tmp_path, monkeypatch):
    """docs/img/from_scratch.png is drawn from docs/img/from_scratch.csv alone; its caption says what the lines are."""
    from pathlib import Path

    import matplotlib.pyplot as plt

    from agents.rsl import plot_curve
    from flatbody_env.figures import caption_text, layout_problems

    table = Path(__file__).resolve().parents[2] / "docs" / "img" / "from_scratch.csv"
    kept = []
    monkeypatch.setattr(plt, "close", lambda fig=None: kept.append(fig))
    plot_curve(table, tmp_path / "c.png", note="Seed 0.")
    fig = kept[0]
    assert layout_problems(fig) == []
    text = caption_text(fig)
    assert "held-out" in text and "goal" in text and "no LQR" in text
    assert len(fig.axes[0].lines[0].get_xdata()) == len(table.read_text().splitlines()) - 1


def test_periodic_checkpoints_are_atomic_and_rotated(tmp_path):
    """rsl-ppo saves rsl_rl's state every checkpoint_freq steps through the writing door, keeps the newest three
    (loadable without unpickling code: weights_only), and removes them after a completed run unless kept."""
    import torch

    from agents.train import train

    kw = dict(env_id="FlatBody-v0", seed=0, n_timesteps=320, n_envs=8, overrides=["num_steps_per_env=8"])
    train("rsl-ppo", tmp_path / "kept", checkpoint_freq=64, keep_checkpoints=True, progress=False, **kw)
    names = sorted(p.name for p in (tmp_path / "kept" / "checkpoints").iterdir())
    assert names == ["rsl_model_192_steps.pt", "rsl_model_256_steps.pt", "rsl_model_320_steps.pt"]
    state = torch.load(tmp_path / "kept" / "checkpoints" / "rsl_model_256_steps.pt", weights_only=True)
    assert state["iterations"] == 4 and {"actor", "critic", "optimizer", "learning_rate", "return_rms"} <= set(state)
    train("rsl-ppo", tmp_path / "done", checkpoint_freq=64, progress=False, **kw)
    assert not (tmp_path / "done" / "checkpoints").exists()


def test_an_elu_actor_exports_to_numpy_and_acts_as_the_sb3_model(tmp_path):
    """rsl_rl's default activation (ELU) on a v1 task from scratch: the run's ``policy.npz`` is written and the numpy
    policy's actions are the SB3 model's (so ``evaluate``, ``demo`` and ``record`` need no torch for it)."""
    from agents.evaluate import Agent
    from agents.numpy_policy import POLICY_FILE, load_policy
    from agents.train import train

    train(
        "rsl-ppo",
        tmp_path / "run",
        env_id="FlatBody-v1",
        seed=2,
        n_timesteps=128,
        n_envs=8,
        overrides=["num_steps_per_env=8", "activation=elu", "hidden_dims=[16,8]"],
        progress=False,
    )
    assert (tmp_path / "run" / POLICY_FILE).is_file()
    policy = load_policy(tmp_path / "run")
    assert policy.activation == "elu" and len(policy.weights) == 3
    obs = np.concatenate([o.numpy() for o in _observations(n=6, steps=4)])
    obs = np.concatenate([obs, 3.0 * obs])  # also where the hidden layers are far into ELU's negative side
    numpy_agent, sb3_agent = Agent(tmp_path / "run", backend="numpy"), Agent(tmp_path / "run", backend="sb3")
    np.testing.assert_allclose(numpy_agent(obs), sb3_agent(obs), rtol=0, atol=1e-5)
