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
from agents.rsl import DEFAULTS, RslVecEnv, TorchResidual, export_sb3, runner_config  # noqa: E402
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


def test_short_run_writes_the_run_folder_and_evaluates(tmp_path, monkeypatch):
    from agents.evaluate import Agent, run_episodes
    from flatbody_env.cli.main import main

    monkeypatch.chdir(tmp_path)
    assert main(["train", "--algo", "rsl-ppo", "--num-envs", "8", "--n-timesteps", "100", "--device", "cpu", "--seed", "3",
                 "--hyperparams", "num_steps_per_env=8", "--no-progress"]) == 0
    out = tmp_path / "runs" / "rsl-ppo-FlatBody-v0-seed3"
    assert {"model.zip", "config.yml", "run.json", "progress.csv", "policy.npz", "rsl_model.pt"} <= {p.name for p in out.iterdir()}
    cfg = yaml.safe_load((out / "config.yml").read_text())
    assert cfg["algo"] == "ppo" and cfg["seed"] == 3 and cfg["trainer"]["name"] == "rsl-ppo" and cfg["hyperparams"]["residual"] == "heuristic"
    run = json.loads((out / "run.json").read_text())
    assert run["algo"] == "rsl-ppo" and run["n_timesteps"] == 128 and run["versions"]["rsl_rl"] == "5.5.1"
    assert len((out / "progress.csv").read_text().splitlines()) == 3
    agent = Agent(out)
    assert agent.backend == "numpy" and agent.residual == "heuristic"
    recs = run_episodes(agent, episodes=2, seed=10_000)
    assert len(recs) == 2 and all(np.isfinite(r["final_distance"]) for r in recs)
    assert main(["train", "--algo", "rsl-ppo", "--out", str(tmp_path / "x"), "--hyperparams", "nope=1", "--no-progress"]) == 2
    assert main(["train", "--algo", "ppo", "--device", "cuda", "--out", str(tmp_path / "y")]) == 2


@pytest.mark.slow
@pytest.mark.xfail(strict=False, reason="not reached yet: 500k steps with the defaults gave a mean final distance of 0.0028 against "
                   "the LQR's 0.0018 on these seeds (docs/agents.md, rsl_rl); the defaults still need a search")
def test_residual_policy_beats_the_lqr_on_held_out_seeds(tmp_path):
    """rsl_rl's PPO on the LQR residual: the mean final distance on 20 held-out seeds below the LQR's."""
    from agents.evaluate import Agent, run_episodes
    from agents.rsl import train_rsl

    out = tmp_path / "run"
    train_rsl(out, seed=0, n_timesteps=500_000, n_envs=256, progress=False)
    seeds = dict(episodes=20, seed=50_000)
    agent = np.mean([r["final_distance"] for r in run_episodes(Agent(out), **seeds)])
    lqr = np.mean([r["final_distance"] for r in run_episodes("heuristic", **seeds)])
    assert agent < lqr, (agent, lqr)
