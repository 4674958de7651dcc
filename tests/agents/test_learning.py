"""The default hyperparameters learn (slow): each algorithm's FlatBody-v1 entry, from scratch, trained for a short budget,
beats the zero policy's mean return on held-out seeds; and a shipped agent's config.yml trains its first steps again bit
for bit (the progress.csv rows of the shipped run)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from agents.evaluate import Agent, run_episodes
from agents.train import train

SMOKE = {
    "ppo": (204_800, 5.0),
    "sac": (50_000, 5.0),
    "td3": (50_000, 5.0),
    "rsl-ppo": (1_000_000, 20.0),
}
"""(budget in environment steps, margin in return) per algorithm: each run's held-out mean return must beat the zero
policy's by the margin; the budgets are about 3 min of one core (the benchmark table of docs/tasks.md measures what each
algorithm reaches at larger budgets over five seeds)."""
EPISODES, SEED = 50, 10_000


@pytest.mark.slow
@pytest.mark.parametrize("algo", list(SMOKE))
def test_the_default_hyperparameters_learn_on_flatbody_v1(tmp_path, algo):
    budget, margin = SMOKE[algo]
    out = tmp_path / "run"
    train(algo, out, env_id="FlatBody-v1", n_timesteps=budget, checkpoint_freq=0, progress=False, notes=False)
    agent = Agent(out)
    assert agent.residual_action is None  # from scratch: the policy's action is the control
    learned = np.mean([r["return"] for r in run_episodes(agent, episodes=EPISODES, seed=SEED, env_id="FlatBody-v1")])
    zero = np.mean([r["return"] for r in run_episodes("zero", episodes=EPISODES, seed=SEED, env_id="FlatBody-v1")])
    assert learned > zero + margin, (algo, learned, zero)


def _rows(path):
    with open(path, newline="") as fh:
        return [{k: v for k, v in row.items() if not k.startswith("time/")} for row in csv.DictReader(fh)]


FIRST_STEPS = {"ppo-FlatBody-v0": 25_600, "rsl-ppo-FlatBody-v1": 49_152}
"""Shipped agent → the steps of its first two progress rows (two SB3 rollouts of 32 × 400; two rsl_rl iterations of
1024 × 24)."""


@pytest.mark.slow
@pytest.mark.parametrize("name", list(FIRST_STEPS))
def test_the_shipped_agent_trains_its_first_steps_again_bit_for_bit(tmp_path, name):
    """``flatbody train --config agents/models/NAME/config.yml`` for two progress rows: the rows (returns, success,
    final distance, losses, KL, entropy, noise, learning rate) are the shipped run's, digit for digit."""
    from agents.numpy_policy import MODELS_DIR
    from flatbody_env.cli.main import main

    shipped = MODELS_DIR / name
    out = tmp_path / "again"
    argv = [
        "train",
        "--config",
        str(shipped / "config.yml"),
        "--out",
        str(out),
        "--n-timesteps",
        str(FIRST_STEPS[name]),
    ]
    assert main([*argv, "--no-progress", "--checkpoint-freq", "0"]) == 0
    timing = {"time_s", "fps"}  # wall-clock columns of rsl-ppo's rows
    mine, theirs = _rows(out / "progress.csv"), _rows(shipped / "progress.csv")
    assert len(mine) == 2
    for a, b in zip(mine, theirs):
        assert {k: v for k, v in a.items() if v != "" and k not in timing} == {
            k: b[k] for k, v in a.items() if v != "" and k not in timing
        }
