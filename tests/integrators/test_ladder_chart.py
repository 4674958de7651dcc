"""The ladder chart (analysis.ladder, flatbody chart --ladder): rows, chosen rungs, the PNG from the table."""

from __future__ import annotations

import math
import re

import pytest

from analysis.ladder import applicable_rungs, ladder_study, read_csv, speedups, write_csv, write_scenes
from analysis.ladder_plots import plot_ladder
from flatbody_env.cli.main import main
from flatbody_env.scene import load_scene


def test_applicable_rungs_follow_the_invariants():
    assert applicable_rungs(load_scene("stationary-v1")) == [
        "stationary",
        "planar-V1",
        "planar",
        "two-polar",
        "regular",
    ]
    assert applicable_rungs(load_scene("planar-v3")) == ["planar", "two-polar", "regular"]
    assert applicable_rungs(load_scene("default")) == ["two-polar", "regular"]


def test_ladder_study_quick_and_plot(tmp_path):
    points, records = ladder_study(["stationary-v1", "planar-v1-crossing"], quick=True, repeats=1, max_run_s=1.0)
    assert {r.scene: r.chosen for r in records} == {"stationary-v1": "stationary", "planar-v1-crossing": "planar-V1"}
    by = {(p.scene, p.rung) for p in points}
    assert ("stationary-v1", "stationary") in by and ("planar-v1-crossing", "regular") in by
    assert ("planar-v1-crossing", "stationary") not in by
    exact = [p for p in points if p.rung == "stationary"]
    assert len(exact) == 1 and exact[0].error == 0.0 and exact[0].status == "ok"
    # the exact in-plane solution is the reference of its scene; the full two-polar model agrees with it
    tp = [p for p in points if p.scene == "planar-v1-crossing" and p.rung == "two-polar" and p.setting == "rtol=1e-12"]
    assert tp and tp[0].error < 1e-9
    sp = speedups(points)
    assert any(s["rung"] == "stationary" and s["reached_target"] for s in sp)
    csv_path, scenes_path = (
        write_csv(points, tmp_path / "ladder.csv"),
        write_scenes(records, tmp_path / "ladder_scenes.csv"),
    )
    rows = read_csv(csv_path)
    assert len(rows) == len(points) and all(isinstance(r["error"], float) for r in rows)
    png = plot_ladder(csv_path, scenes_path, tmp_path / "ladder.png")
    assert png.stat().st_size > 10_000
    assert math.isfinite(read_csv(scenes_path)[0]["floor"])


def test_cli_chart_ladder_bad_input(tmp_path, capsys):
    assert main(["chart", "--ladder", "--scenes", "nope", "--out", str(tmp_path)]) == 2
    assert "scenes" in capsys.readouterr().err
    assert main(["chart", "--ladder", "--plot-only", "--out", str(tmp_path)]) == 2
    assert "plot-only" in capsys.readouterr().err


@pytest.mark.parametrize("scene", ["stationary-ellipse", "planar-v3", "planar-v1-crossing"])
def test_new_scenes_validate(scene):
    sc = load_scene(scene)
    assert sc.state["s1"] == 0.0 and sc.state["s2"] == 0.0 and sc.t_end == 100.0


def test_cli_ladder_prints_no_nan(tmp_path, capsys):
    """The horizon rows run no scipy DOP853 and their reference is exact: the ratio and the floor
    that cannot be measured are said so ("n/a (why)"), never printed as nan."""
    assert (
        main(
            [
                "chart",
                "--ladder",
                "--quick",
                "--scenes",
                "stationary-ellipse",
                "--max-run-s",
                "0.2",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert not re.search(r"\bx?nan\b", out), out
    horizon = [line for line in out.splitlines() if "stationary-ellipse t=1e+02" in line and " ms: " in line]
    assert horizon and all("vs scipy DOP853 n/a (not run on this scene)" in line for line in horizon), out
    assert any("floor n/a" in line for line in out.splitlines() if "auto ->" in line)


def test_speedups_say_why_a_ratio_is_missing():
    from analysis.ladder import LadderPoint

    def point(scene, rung, method, error, wall, status="ok"):
        return LadderPoint(
            scene=scene,
            chosen="stationary",
            rung=rung,
            method=method,
            setting="s",
            t_end=1.0,
            error=error,
            wall_time=wall,
            nfev=1,
            status=status,
        )

    points = [
        point("a", "stationary", "ladder-stationary", 0.0, 1e-5),
        point("a", "two-polar", "DOP853-numba", 1e-12, 1e-4),
        point("a", "two-polar", "DOP853", 1e-7, 1e-2),
        point("a", "two-polar", "DOP853", math.nan, math.nan, "skipped"),
        point("b", "stationary", "ladder-stationary", 0.0, 1e-5),
        point("b", "two-polar", "DOP853-numba", 1e-6, 1e-4),
    ]
    by = {(s["scene"], s["method"]): s for s in speedups(points)}
    a = by["a", "ladder-stationary"]
    assert a["speedup_vs_full"] == pytest.approx(10.0) and a["why_no_full"] == ""
    assert (
        math.isnan(a["speedup_vs_default"]) and a["why_no_default"] == "it did not reach 1e-09 within the time budget"
    )
    b = by["b", "ladder-stationary"]
    assert math.isnan(b["speedup_vs_full"]) and b["why_no_full"] == "no full model reached 1e-09"
    assert b["why_no_default"] == "not run on this scene"
    assert by["b", "DOP853-numba"]["why_no_full"] == "no full model reached 1e-09"
