"""``flatbody bench train`` (flatbody_env/bench/train.py): like-for-like stacks, the files and the docs table
(the full comparison is a benchmark, run by hand: docs/agents.md)."""

from __future__ import annotations

import csv
import json

import pytest

from flatbody_env.bench.harness import write_report
from flatbody_env.bench.train import FLATBODY_ONLY, TrainBenchmark, TrainTiming, _run, report


@pytest.mark.parametrize("env_id", ["FlatBody-v0", "Pendulum-v1"])
def test_train_benchmark_monitors_each_stack_once(env_id):
    """``flatbody bench train`` compares like with like: each stack runs under one ``VecMonitor`` and no
    per-env ``Monitor`` (SB3 warns when both wrap an env, and each step would be counted twice)."""
    import warnings

    from agents.config import load_hyperparams

    hp = {**load_hyperparams("ppo", "FlatBody-v0"), "n_envs": 2, "n_steps": 32, "batch_size": 32}
    if env_id != "FlatBody-v0":
        hp = {k: v for k, v in hp.items() if k not in FLATBODY_ONLY}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        timing = _run(env_id, hp, 64, 0)
    assert not [w for w in caught if "Monitor" in str(w.message)], [str(w.message) for w in caught]
    assert timing.timesteps >= 64 and 0.0 < timing.env_s < timing.wall_s


def test_files_and_table(tmp_path):
    fb = TrainTiming(env_id="FlatBody-v0", timesteps=64_000, wall_s=6.6, env_s=0.83)
    pd = TrainTiming(env_id="Pendulum-v1", timesteps=64_000, wall_s=7.6, env_s=1.95)
    b = TrainBenchmark(
        flatbody=fb,
        pendulum=pd,
        ratio_wall=fb.wall_s / pd.wall_s,
        flatbody_env_share=fb.env_share,
        pendulum_env_share=pd.env_share,
        lqr_us_per_body_step=0.94,
        n_envs=32,
    )
    docs = tmp_path / "agents.md"
    docs.write_text("before\n<!-- bench:train -->\nold\n<!-- /bench:train -->\nafter\n", encoding="utf-8")
    write_report(report(b), tmp_path, docs=docs)
    data = json.loads((tmp_path / "train_benchmark.json").read_text())
    assert data["flatbody"] == {"env_id": "FlatBody-v0", "timesteps": 64_000, "wall_s": 6.6, "env_s": 0.83}
    assert data["ratio_wall"] == pytest.approx(6.6 / 7.6) and data["n_envs"] == 32 and data["machine"]["cpu"]
    with open(tmp_path / "train_benchmark.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["env_id"] for r in rows] == ["FlatBody-v0", "Pendulum-v1"] and rows[1]["env_share"] == f"{1.95 / 7.6:.4f}"
    assert (tmp_path / "train_benchmark.png").stat().st_size > 1000
    page = docs.read_text(encoding="utf-8")
    assert "old" not in page and report(b).markdown() in page and "| **0.87** | ≤ 1.0 (met) |" in page
    assert "0.87" in report(b).text() and "**" not in report(b).text()
