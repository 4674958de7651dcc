"""``flatbody bench sweep`` runs end to end (small) and its figures are consistent with each other."""

from __future__ import annotations

import json
import math

import pytest

from flatbody_env.bench.sweep import break_even_grid


@pytest.mark.slow  # a benchmark run (flatbody bench sweep); the sweep paths it times are tested by default
def test_bench_sweep_small_run_writes_consistent_figures(cli, tmp_path):
    r = cli(
        "bench",
        "sweep",
        "--grid",
        "8",
        "--chunk",
        "3",
        "--workers",
        "1",
        "--sim-workers",
        "2",
        "--noop-tasks",
        "20",
        "--out",
        str(tmp_path),
    )
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "scaling.json").read_text())
    assert (tmp_path / "scaling.csv").exists() and (tmp_path / "scaling.png").stat().st_size > 10_000
    assert rep["tasks"] == math.ceil(8 / 3) == len(rep["task_costs_s"]) and rep["points"] == 64
    (one,) = rep["local"]
    assert one["speedup"] == pytest.approx(rep["serial_s"] / one["run_s"])
    assert rep["overhead_per_task_s"] > 0 and rep["connect_s"] > 0
    sim = rep["simulated"]
    assert sim["wall_s"] >= max(rep["task_costs_s"])  # no schedule beats its longest task
    assert sim["ideal_s"] == pytest.approx(sum(rep["task_costs_s"]) / 2)
    for x in rep["extrapolated"]:
        assert x["break_even_grid"] == pytest.approx(
            break_even_grid(
                rep["cost_per_point_s"],
                x["workers"],
                t0=rep["connect_s"],
                overhead=rep["overhead_per_task_s"],
                rows_per_task=3,
            )
        )
    assert [x["workers"] for x in rep["extrapolated"]] == [8, 32, 128]
    r = cli("bench", "sweep", "--out", str(tmp_path), "--plot-only")
    assert r.returncode == 0 and "scaling.png" in r.stdout
