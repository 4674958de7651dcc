"""``flatbody bench compare REV``: a bad revision is one line (exit 2); the table, CSV and chart of a result; the whole
comparison end to end against HEAD (slow: it checks HEAD out beside this tree and compiles its kernels)."""

from __future__ import annotations

import csv
import json

import pytest

from flatbody_env.bench.compare import FIGURES, report, resolve, this_tree
from flatbody_env.bench.harness import write_report
from flatbody_env.cli.main import main


@pytest.mark.parametrize("rev", ["no-such-revision-xyz", "-h", "--output=x", "HEAD~100000", ""])
def test_a_bad_revision_is_refused_in_one_line(rev, tmp_path, capsys):
    assert main(["bench", "compare", "--out-dir", str(tmp_path / "out"), "--", rev]) == 2  # "--": a REV like "-h"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("flatbody bench compare: error: rev: "), err
    assert not (tmp_path / "out" / "compare.json").exists()


def test_an_unknown_task_is_refused_in_one_line_before_anything_is_checked_out(tmp_path, capsys):
    assert main(["bench", "compare", "HEAD", "--env", "NoSuchTask-v9", "--out-dir", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "env: must be one of" in err[0] and "NoSuchTask-v9" in err[0], err
    assert not (tmp_path / "out" / "compare.json").exists()


def test_a_revision_resolves_to_its_commit():
    root = this_tree()
    head = resolve("HEAD", root)
    assert len(head) == 40 and resolve(head[:10], root) == head


def _result(ratio_simulate: float = 1.5) -> dict:
    return {
        "benchmark": "compare",
        "rev": "main",
        "rev_commit": "a" * 40,
        "working_tree": {"head": "b" * 40, "changed_files": 3},
        "env_id": "FlatBody-v1",
        "rounds": 3,
        "figures": [
            {
                "figure": "env-step",
                "what": "single env step, gym.make(FlatBody-v1)",
                "unit": "µs per step",
                "old": 20.0,
                "new": 18.0,
                "ratio": 0.9,
                "old_blocks": [20.0, 21.0, 25.0],
                "new_blocks": [18.0, 19.0, 18.5],
            },
            {
                "figure": "simulate",
                "what": "compiled simulate",
                "unit": "ms per call",
                "old": 2.0,
                "new": 2.0 * ratio_simulate,
                "ratio": ratio_simulate,
                "old_blocks": [2.0, 2.2, 2.1],
                "new_blocks": [3.0, 3.1, 3.3],
            },
            {
                "figure": "ppo",
                "what": "SB3 PPO iteration",
                "unit": "s per iteration",
                "old": None,
                "new": None,
                "ratio": None,
                "failed": "the REV tree: TypeError: no such argument",
            },
        ],
        "load_avg_1min": {"before": 3.0, "after": 3.5},
    }


def test_the_table_csv_and_chart_of_a_comparison(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    rep = report(_result())
    text = rep.text()
    assert "main (aaaaaaa)" in text and "working tree (bbbbbbb + 3 changed)" in text
    assert "1.50×" in text and "0.90×" in text and "not timed: the REV tree: TypeError" in text
    paths = write_report(rep, tmp_path)
    assert [p.name for p in paths] == ["compare.json", "compare.csv", "compare.png"]
    rows = list(csv.DictReader((tmp_path / "compare.csv").read_text().splitlines()))
    assert [r["figure"] for r in rows] == ["env-step", "simulate", "ppo"] and float(
        rows[1]["ratio_new_over_old"]
    ) == 1.5
    assert json.loads((tmp_path / "compare.json").read_text())["figures"][0]["old_blocks"] == [20.0, 21.0, 25.0]
    assert (tmp_path / "compare.png").stat().st_size > 10_000


def test_the_comparison_chart_is_clean(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flatbody_env.bench.compare import plot
    from flatbody_env.figures import caption_text, layout_problems

    saved = tmp_path / "compare.json"
    saved.write_text(json.dumps(_result()))
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    before = set(plt.get_fignums())
    plot(saved, tmp_path / "c.png")
    (num,) = sorted(set(plt.get_fignums()) - before)
    fig = plt.figure(num)
    try:
        assert "Ticks: every block" in caption_text(fig) and layout_problems(fig) == []
        assert [t.get_text().split("\n")[0] for t in fig.axes[0].get_yticklabels()] == ["env-step", "simulate"]
    finally:
        monkeypatch.undo()
        plt.close(fig)


@pytest.mark.slow
def test_compare_against_head_end_to_end(tmp_path, capsys):
    """The working tree against HEAD: both workers import their own tree, every figure asked for is timed, the files
    are written and the temporary checkout is gone."""
    import subprocess

    root = this_tree()
    before = subprocess.run(["git", "-C", str(root), "worktree", "list"], capture_output=True, text=True).stdout
    argv = ["bench", "compare", "HEAD", "--figures", "simulate,planner", "--rounds", "2", "--env", "FlatBodyAnyBody-v1"]
    assert main([*argv, "--out-dir", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "compare.json").read_text())
    assert data["env_id"] == "FlatBodyAnyBody-v1"  # the task asked for, registered by both trees
    assert [r["figure"] for r in data["figures"]] == ["simulate", "planner"]  # the planner: to the episode's end here
    for row in data["figures"]:
        assert len(row["old_blocks"]) == len(row["new_blocks"]) == 2 and row["ratio"] > 0, row
    assert data["rev_commit"] == resolve("HEAD", root) and set(FIGURES) >= {r["figure"] for r in data["figures"]}
    after = subprocess.run(["git", "-C", str(root), "worktree", "list"], capture_output=True, text=True).stdout
    assert after == before
