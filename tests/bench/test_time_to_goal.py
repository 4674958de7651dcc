"""``flatbody bench train --to-goal`` (flatbody_env/bench/time_to_goal.py): the goal and LQR criteria, the files and the docs table,
checked on made-up curves (the race itself is a benchmark, run by hand: docs/agents.md)."""

from __future__ import annotations

import json

import pytest

from flatbody_env.bench.harness import write_report
from flatbody_env.bench.time_to_goal import GoalBenchmark, _curve, _Reached, load, plot, report, run


def test_criteria_and_curves():
    reached = _Reached(0.99, 0.002, 0.0018)
    pts = [
        (50_000, 2.0, 1.0, 0.0025),
        (100_000, 4.0, 0.95, 0.0010),
        (150_000, 6.0, 1.0, 0.0019),
        (200_000, 8.0, 1.0, 0.0017),
    ]
    assert not reached(0, 0, pts[:2])  # success 95 % does not count
    assert not reached(0, 0, pts[:3])  # the goal, not yet the LQR
    assert reached(0, 0, pts)
    c = _curve("rsl-ppo", pts, reached)
    assert (c.goal_s, c.goal_timesteps, c.lqr_s, c.lqr_timesteps) == (6.0, 150_000, 8.0, 200_000)
    missed = _curve("sb3-ppo", pts[:1], reached)
    assert missed.goal_s is None and missed.lqr_s is None


def test_files_and_table(tmp_path):
    reached = _Reached(0.99, 0.002, 0.0018)
    sb3 = _curve("sb3-ppo", [(100_000, 10.0, 1.0, 0.0019), (200_000, 20.0, 1.0, 0.0017)], reached)
    rsl = _curve("rsl-ppo", [(100_000, 4.0, 1.0, 0.0015)], reached)
    settings = {
        "lqr_final_distance": 0.0018,
        "lqr_success": 1.0,
        "episodes": 20,
        "eval_seed": 50_000,
        "success_goal": 0.99,
        "distance_goal": 0.002,
        "seed": 0,
    }
    b = GoalBenchmark(sb3=sb3, rsl=rsl, **settings)
    assert b.ratio == pytest.approx(0.4) and b.ratio_lqr == pytest.approx(0.2)
    assert report(b).block == "time-to-goal"
    write_report(report(b), tmp_path)
    data = json.loads((tmp_path / "time_to_goal.json").read_text())
    assert data["ratio"] == pytest.approx(0.4) and data["rsl"]["lqr_timesteps"] == 100_000 and data["machine"]["cpu"]
    assert len((tmp_path / "time_to_goal.csv").read_text().splitlines()) == 4
    assert (tmp_path / "time_to_goal.png").stat().st_size > 1000
    assert load(tmp_path / "time_to_goal.json") == b
    table = report(b).markdown()
    assert (
        "| rsl-ppo | 4.0 s (100000 steps) | 4.0 s (100000 steps) |" in table and "**0.40** (goal ≤ 0.5: met)" in table
    )
    slow = GoalBenchmark(sb3=sb3, rsl=_curve("rsl-ppo", [(100_000, 15.0, 1.0, 0.0025)], reached), **settings)
    assert slow.ratio is None and "not reached" in report(slow).markdown() and "not reached" in report(slow).text()


@pytest.mark.parametrize(
    "kw, field",
    [
        ({"max_timesteps": 0}, "max_timesteps"),
        ({"episodes": 1.5}, "episodes"),
        ({"success_goal": 1.5}, "success_goal"),
        ({"distance_goal": 0.0}, "distance_goal"),
    ],
)
def test_bad_settings_name_the_field(kw, field, tmp_path):
    with pytest.raises(ValueError, match=field):
        run(out_dir=tmp_path, **kw)


def test_the_committed_chart_explains_itself_and_nothing_overlaps(tmp_path, monkeypatch):
    """docs/img/time_to_goal.png redrawn from its saved JSON: a caption that explains LQR and the goal, a clean layout."""
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flatbody_env.figures import all_text, caption_text, layout_problems

    saved = Path(__file__).resolve().parents[2] / "docs" / "img" / "time_to_goal.json"
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    before = set(plt.get_fignums())
    plot(saved, tmp_path / "c.png")
    (num,) = sorted(set(plt.get_fignums()) - before)
    fig = plt.figure(num)
    try:
        text = all_text(fig)
        assert caption_text(fig) and "linear-quadratic regulator" in text and "Goal: success" in text and "gSDE" in text
        assert layout_problems(fig) == []
        b = load(saved)
        assert b.rsl.points and b.sb3.points and b.lqr_final_distance > 0
    finally:
        monkeypatch.undo()
        plt.close(fig)


@pytest.mark.slow
def test_bench_train_to_goal_writes_its_files(tmp_path):
    """``flatbody bench train --to-goal`` end to end on a tiny budget: both trainers, the three files."""
    from flatbody_env.cli.main import main

    assert (
        main(
            [
                "bench",
                "train",
                "--to-goal",
                "--max-timesteps",
                "8192",  # half of rsl-ppo's collection (256 envs x 64 steps), the larger: the least both accept
                "--eval-every",
                "8192",
                "--episodes",
                "1",
                "--out-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    for name in ("time_to_goal.json", "time_to_goal.csv", "time_to_goal.png"):
        assert (tmp_path / name).stat().st_size > 0
