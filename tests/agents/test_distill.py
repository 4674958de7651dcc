"""Distilling the planner (``flatbody imitate distill``, agents/imitation.py): round 0 labels the planner's own
episodes, later rounds the states the policy reaches; the run folder holds a policy that executes the law plus its
residual; ``--config`` repeats a distillation bit for bit; bad input is one line."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import yaml

import flatbody_env  # noqa: F401  (registers the tasks)
from agents.evaluate import EVAL_SEED, MODELS_DIR, Agent, env_kwargs_for
from agents.imitation import DistillSettings, _demonstrations, distill, distill_config
from agents.planner import settings_for
from flatbody_env.cli.main import main as flatbody
from flatbody_env.env.vector_env import FlatBodyVectorEnv

ENV = "FlatBodyTorque-v1"
TINY = {"samples": 4, "horizon": 5}
"""A planner small enough for the default suite (its choices, not their quality, are under test)."""


class _Steps:
    def update(self, n):
        pass


def _replay(seeds, actions):
    """Observations (T, B, d) of the seeded episodes under the given actions (T, B, n), stepped afresh."""
    env = FlatBodyVectorEnv(num_envs=len(seeds), **env_kwargs_for(ENV))
    obs, _ = env.reset(seed=[int(s) for s in seeds])
    seen = []
    for a in actions:
        seen.append(obs.copy())
        obs, *_ = env.step(a)
    env.close()
    return np.array(seen)


def test_round_zero_labels_the_planners_own_episodes_and_later_rounds_the_policys():
    """With the identity as label, round 0's labels are the planner's executed actions: replayed open loop in a fresh
    environment they visit the recorded observations exactly. A later round records the states the executed policy
    reaches (here the zero action) and labels them with what the planner would have done there."""
    seeds = np.array([3, 4])
    settings = settings_for(ENV, TINY)
    identity = lambda obs, a: np.asarray(a, dtype=np.float64)  # noqa: E731
    obs, acts, _ = _demonstrations(ENV, env_kwargs_for(ENV), seeds, settings, 0, identity, None, _Steps())
    steps = len(obs) // 2
    obs, acts = obs.reshape(steps, 2, -1), acts.reshape(steps, 2, -1)  # no episode of the task ends early
    np.testing.assert_array_equal(_replay(seeds, acts.astype(np.float32)), obs)
    assert np.abs(acts).max() > 0.05  # the planner acts

    zero = lambda o: np.zeros((len(o), 3), dtype=np.float32)  # noqa: E731
    obs0, labels0, _ = _demonstrations(ENV, env_kwargs_for(ENV), seeds, settings, 0, identity, zero, _Steps())
    obs0 = obs0.reshape(steps, 2, -1)
    np.testing.assert_array_equal(_replay(seeds, np.zeros((steps, 2, 3), np.float32)), obs0)
    assert np.abs(labels0).max() > 0.05  # labelled by the planner, not by the policy that ran


def test_distill_writes_a_run_that_executes_the_law_plus_its_residual_and_repeats_from_its_config(tmp_path):
    config = distill_config(ENV, planner=TINY)
    assert config.algo == "ppo" and config.hyperparams["residual"] == "pumping"  # the law this task's planner perturbs
    res = distill(
        config,
        tmp_path / "d",
        seeds=(0, 2),
        settings=DistillSettings(rounds=2, epochs=3),
        planner=TINY,
        progress=False,
    )
    rows = res["rounds"]
    assert [r["executed"] for r in rows] == ["planner", "policy"] and [r["episodes"] for r in rows] == [1, 1]
    assert rows[1]["pairs"] > rows[0]["pairs"] == 400  # round 1's pairs join round 0's
    assert {"config.yml", "run.json", "progress.csv", "model.zip", "vecnormalize.pkl", "policy.npz"} <= {
        p.name for p in (tmp_path / "d").iterdir()
    }
    saved = yaml.safe_load((tmp_path / "d" / "config.yml").read_text())
    im = saved["prior"]["imitation"]
    assert im["method"] == "distill" and im["seeds"] == [0, 2] and im["rounds"] == 2
    # every setting of the planner, not only the overrides: what the task's planner is later does not change the run
    assert im["planner"] == dataclasses.asdict(settings_for(ENV, TINY)) and im["planner"]["samples"] == 4
    assert "pumping" in im["expert"] and json.loads((tmp_path / "d" / "run.json").read_text())["n_timesteps"] == 0

    # the exported policy (numpy) is the SB3 model's mean action; the run executes the law plus it
    numpy_agent, sb3_agent = Agent(tmp_path / "d", backend="numpy"), Agent(tmp_path / "d", backend="sb3")
    env = FlatBodyVectorEnv(num_envs=4, **env_kwargs_for(ENV))
    obs, _ = env.reset(seed=EVAL_SEED)
    env.close()
    np.testing.assert_allclose(numpy_agent(obs), sb3_agent(obs), atol=1e-5)
    law = numpy_agent.residual_action.controller.predict(obs)[0]
    own = numpy_agent.policy_actions(obs)
    np.testing.assert_allclose(numpy_agent(obs), np.clip(law + np.clip(own, -1, 1), -1, 1), atol=1e-6)

    # the command repeats it from its config.yml: the same weights, the same rounds
    assert flatbody(["imitate", "distill", "--config", str(tmp_path / "d" / "config.yml"), "--out", str(tmp_path / "again"), "--no-progress"]) == 0  # fmt: skip
    a, b = np.load(tmp_path / "d" / "policy.npz"), np.load(tmp_path / "again" / "policy.npz")
    for key in a.files:
        if key != "meta":  # the source files' hashes (a zip and a pickle carry their own times)
            np.testing.assert_array_equal(a[key], b[key])
    assert (tmp_path / "d" / "progress.csv").read_text() == (tmp_path / "again" / "progress.csv").read_text()
    with pytest.raises(ValueError, match="out|holds"):  # an existing run is not overwritten
        distill(config, tmp_path / "d", seeds=(0, 2), settings=DistillSettings(rounds=1), planner=TINY, progress=False)


@pytest.mark.parametrize(
    "argv, field",
    [
        (["--env", ENV, "--seeds", "9990:10010"], "seeds"),  # into the evaluation seeds
        (["--env", ENV, "--seeds", "0:3", "--rounds", "5"], "seeds"),  # fewer episodes than rounds
        (["--env", ENV, "--hyperparams", "residual_mode=gain"], "residual_mode"),
        (["--env", ENV, "--hyperparams", "residual_gate=0.1"], "residual_mode"),
        (["--env", ENV, "--hyperparams", "residual_scale=0"], "residual_scale"),
        (["--env", ENV, "--seeds", "0:9000", "--rounds", "2"], "seeds"),  # more than a round may plan at once
        (["--env", ENV, "--planner", "bogus=1"], "--planner"),
        (["--env", "FlatBody-v9"], "env"),
        ([], "--env"),
        (["--env", ENV, "--config", "x.yml"], "--env"),
        (["--env", ENV, "--rounds", "0"], "rounds"),
        (["--env", ENV, "--learning-rate", "nan"], "learning-rate"),
    ],
)
def test_command_refuses_bad_input_with_one_line_before_any_work(tmp_path, capsys, argv, field):
    try:
        rc = flatbody(["imitate", "distill", "--out", str(tmp_path / "d"), *argv])
    except SystemExit as exc:  # argparse's own types
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) <= 2 and field in err[-1]
    assert not (tmp_path / "d").exists()


def test_a_config_that_is_not_a_distillation_is_refused(tmp_path, capsys):
    rc = flatbody(["imitate", "distill", "--config", str(MODELS_DIR / "rsl-ppo-FlatBody-v1" / "config.yml"), "--out", str(tmp_path / "d")])  # fmt: skip
    assert rc == 2 and "distill" in capsys.readouterr().err


SHIPPED = sorted(p for p in MODELS_DIR.glob("distilled-*") if (p / "model.zip").exists())
"""The shipped distilled agents (``agents/models/distilled-ID/``)."""


@pytest.mark.slow  # the planner over a fifth of the training episodes, then 100 evaluation episodes
@pytest.mark.parametrize("folder", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_distilled_agent_repeats_its_first_round_and_its_evaluation(folder, tmp_path):
    """The shipped agent's first round (the planner's own episodes and the fit on them) repeats from its config.yml bit
    for bit — the figures of its progress.csv's first row — and its saved evaluation reproduces episode by episode."""
    import csv
    from dataclasses import replace

    from agents.config import RunConfig
    from agents.evaluate import evaluate_task
    from agents.imitation import distill_settings_of

    config = RunConfig.read(folder)
    settings, planner, (lo, hi) = distill_settings_of(config)
    first = np.array_split(np.arange(lo, hi), settings.rounds)[0]
    res = distill(
        config,
        tmp_path / "r0",
        seeds=(int(first[0]), int(first[-1]) + 1),
        settings=replace(settings, rounds=1),
        planner=planner,
        progress=False,
    )
    with open(folder / "progress.csv") as fh:
        saved = next(csv.DictReader(fh))
    row = res["rounds"][0]
    assert (row["episodes"], row["pairs"]) == (int(saved["episodes"]), int(saved["pairs"]))
    assert (row["executed_success"], row["mse"]) == (float(saved["executed_success"]), float(saved["mse"]))

    evaluation = json.loads((folder / "evaluation.json").read_text())
    report = evaluate_task(
        config.env_id, episodes=evaluation["episodes"], seed=evaluation["seed"], model=folder, baselines=False
    )
    assert report["agent"]["success_rate"] == evaluation["agent"]["success_rate"]
    assert report["agent"]["return"] == pytest.approx(evaluation["agent"]["return"], rel=1e-9)
