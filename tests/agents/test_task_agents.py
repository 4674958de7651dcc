"""The agents of the other tasks (docs/tasks.md): training on any registered id, the residual on the
LQR or on the passivity law per task, and the shipped task agents' evaluations reproduce from their seeds."""

from __future__ import annotations

import json

import numpy as np
import pytest

import flatbody_env  # noqa: F401  (registers the tasks)
from agents.evaluate import MODELS_DIR, env_kwargs_for, run_episodes
from agents.heuristic import ResidualAction
from flatbody_env.env.registration import TASK_IDS

TASK_AGENTS = sorted(p for p in MODELS_DIR.glob("ppo-*") if p.name != "ppo-FlatBody-v0" and (p / "model.zip").exists())
"""The shipped agents of the tasks other than FlatBody-v0 (``agents/models/ppo-ID/``)."""


def test_every_task_has_ppo_hyperparameters():
    from agents.config import load_hyperparams

    for env_id in [i for i in TASK_IDS if i.endswith("-v0")]:  # the v0 ids' residual agents (the prior track)
        hp = load_hyperparams("ppo", env_id)
        assert hp["residual"] if env_id != "FlatBodyDilatation-v0" else not hp.get("residual")  # no LQR exists there


def test_curriculum_switches_the_training_task_and_keeps_the_registered_one(tmp_path):
    """``flatbody curriculum`` (agents/curriculum.py): the stages rebuild the training environments with the keyword,
    the last stage is the task's own, config.yml records the schedule as the run's prior and keeps the task's
    hyperparameters (what evaluation reads)."""
    import yaml

    from flatbody_env.cli.main import main

    out = tmp_path / "run"
    assert (
        main(
            [
                "curriculum",
                "--env",
                "FlatBodySlow-v0",
                "--out",
                str(out),
                "--stages",
                "0.15,0",
                "--min-stage-steps",
                "1",
                "--max-stage-steps",
                "1",
                "--n-timesteps",
                "64",
                "--train-env-kwargs",
                "w_tumble=0",
                "--log-std-per-action=-1,-1,-3,-3",
                "--hyperparams",
                "n_envs=2",
                "n_steps=16",
                "batch_size=32",
                "n_epochs=1",
                "--no-progress",
            ]
        )
        == 0
    )
    cfg = yaml.safe_load((out / "config.yml").read_text())
    curriculum = cfg["prior"]["curriculum"]
    assert [h["value"] for h in curriculum["history"]] == [0.15, 0.0]
    assert curriculum["train_env_kwargs"] == {"w_tumble": 0} and curriculum["log_std_per_action"] == [-1, -1, -3, -3]
    assert cfg["hyperparams"]["env_kwargs"] == {}
    assert "curriculum/value" in (out / "progress.csv").read_text().splitlines()[0]


def test_train_refuses_an_unregistered_id(tmp_path):
    from agents.train import train

    with pytest.raises(ValueError, match="env"):
        train("ppo", tmp_path / "run", env_id="CartPole-v1")


@pytest.mark.parametrize(
    "env_id,residual",
    [
        ("FlatBodyDilatation-v0", None),
        pytest.param("FlatBodyHoldUnstable-v0", "passivity", marks=pytest.mark.slow),
        pytest.param("FlatBodyAnyBody-v0", "heuristic", marks=pytest.mark.slow),
    ],
)
def test_train_and_evaluate_on_a_task(tmp_path, env_id, residual):
    """A tiny run on the task: the saved config names it, the agent evaluates on it (its spaces, its residual)."""
    import yaml

    from agents.evaluate import Agent
    from agents.train import train

    over = ["n_steps=16", "batch_size=32", "n_epochs=1"] + ([f"residual={residual}"] if residual else [])
    res = train(
        "ppo",
        tmp_path / "run",
        env_id=env_id,
        n_timesteps=64,
        n_envs=2,
        overrides=over,
        checkpoint_freq=0,
        progress=False,
    )
    cfg = yaml.safe_load((res.out / "config.yml").read_text())
    assert cfg["env_id"] == env_id
    agent = Agent(res.out)
    assert agent.env_kwargs["task"] == env_kwargs_for(env_id)["task"]
    assert (agent._base is not None) == bool(residual)
    records = run_episodes(agent, episodes=2, seed=10_000, env_kwargs=agent.env_kwargs, env_id=env_id, batch=2)
    assert len(records) == 2 and all(np.isfinite(r["final_distance"]) for r in records)


@pytest.mark.parametrize(
    "env_id,base",
    [
        ("FlatBodyHoldUnstable-v0", "passivity"),
        ("FlatBodyHoldUnstable-v0", "heuristic"),
        ("FlatBodyAnyBody-v0", "heuristic"),
    ],
)
def test_zero_residual_is_the_base_controller(env_id, base):
    """A zero policy on the residual (gain mode) runs exactly the base controller: its baseline's figures."""
    ra = ResidualAction(env_kwargs_for(env_id), 1.0, 0.0, "gain", base)
    n = ra.controller.mask.sum()
    zero = run_episodes(lambda o: ra(o, np.zeros((o.shape[0], n))), episodes=6, seed=10_000, env_id=env_id)
    ref = run_episodes(base, episodes=6, seed=10_000, env_id=env_id)
    assert [r["final_distance"] for r in zero] == pytest.approx([r["final_distance"] for r in ref], rel=1e-9)


@pytest.mark.slow  # 100 episodes per shipped task agent
@pytest.mark.parametrize("folder", TASK_AGENTS, ids=[p.name for p in TASK_AGENTS])
def test_shipped_task_agent_evaluation_reproduces(folder):
    """A fresh evaluation of the shipped task agent over the stored seeds reproduces its ``evaluation.json``
    (episode by episode: success and final distance)."""
    from agents.evaluate import evaluate_task

    saved = json.loads((folder / "evaluation.json").read_text())
    env_id = saved["env_id"]
    assert folder.name == f"ppo-{env_id}"
    report = evaluate_task(env_id, episodes=saved["episodes"], seed=saved["seed"], model=folder, baselines=False)
    old = next(v for v in saved["policies"].values() if v["kind"] == "agent")  # named by its algo ("ppo")
    new = report["policies"]["agent"]
    assert saved["targets"]["seed"] == list(range(saved["seed"], saved["seed"] + saved["episodes"]))
    assert new["episodes"]["success"] == old["episodes"]["success"]
    assert new["episodes"]["final_distance"] == pytest.approx(old["episodes"]["final_distance"], rel=1e-6, abs=1e-9)
    assert new["summary"]["success_rate"] == old["summary"]["success_rate"]
