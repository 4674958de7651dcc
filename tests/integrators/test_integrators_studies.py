"""The integrator studies return typed records, write CSV, and the plots draw from the CSV."""

from __future__ import annotations

import math

import pytest

from analysis.failure_study import FailurePoint, failure_study
from analysis.integrator_plots import plot_failure_study, plot_work_precision
from analysis.work_precision import WorkPrecisionPoint, read_csv, work_precision, write_json, write_records


def test_work_precision_records_and_chart(tmp_path):
    points, refs = work_precision(("regular",), ("DOP853-numba", "RK4"), quick=True, repeats=1, progress=False)
    assert points and all(isinstance(p, WorkPrecisionPoint) for p in points)
    assert {p.method for p in points} == {"DOP853-numba", "RK4"}
    assert refs[0].agreement < 1e-8  # the reference and its independent cross-check agree
    ok = [p for p in points if p.status == "ok"]
    assert all(math.isfinite(p.error) and p.wall_time > 0 and p.nfev > 0 for p in ok)
    # tighter settings give smaller errors (fixed step: h = 0.1 → 0.00625)
    rk4 = sorted((p for p in ok if p.method == "RK4"), key=lambda p: -p.step)
    assert rk4[-1].error < 1e-3 * rk4[0].error
    csv_path = write_records(points, tmp_path / "wp.csv")
    write_json(refs, tmp_path / "refs.json")
    rows = read_csv(csv_path)
    assert len(rows) == len(points) and rows[0]["scene"] == "regular"
    png = plot_work_precision(csv_path, tmp_path / "wp.png", tmp_path / "refs.json")
    assert png.stat().st_size > 10_000


def test_failure_study_records_the_facts(tmp_path):
    pts = failure_study(("gap",), ("RK4", "RATTLE-suzuki4"), quick=True, progress=False)
    assert all(isinstance(p, FailurePoint) for p in pts)
    rk4 = {p.parameter: p for p in pts if p.method == "RK4"}
    rat = {p.parameter: p for p in pts if p.method == "RATTLE-suzuki4"}
    smallest = min(rk4)
    assert rk4[smallest].status != "ok" and math.isnan(rk4[smallest].error)  # detected, no state returned
    assert all(p.status == "ok" for p in rat.values())
    assert rat[smallest].measured < 1e-5  # the pass really came close to λ = μ
    assert rat[smallest].error < 10 * rat[max(rat)].error
    csv_path = write_records(pts, tmp_path / "fs.csv")
    assert plot_failure_study(csv_path, tmp_path / "fs.png").stat().st_size > 10_000


@pytest.mark.slow
def test_chart_command_quick(tmp_path):
    from flatbody_env.cli.main import main

    assert main(["chart", "--quick", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "work_precision.png").exists() and (tmp_path / "work_precision.csv").exists()


def test_failure_study_progress_and_summary_count_the_same_runs(tmp_path, capsys, monkeypatch):
    """The bar counts the planned runs (one per method and axis value, the reference runs not counted);
    the summary says how many of them ran and that the rest were skipped over the time budget."""
    import re

    from analysis.failure_study import planned_runs
    from flatbody_env.cli.main import main

    monkeypatch.setenv("FLATBODY_PROGRESS_S", "0")  # stderr is not a terminal here: a progress line per run
    argv = [
        "failure-study",
        "--quick",
        "--studies",
        "horizon",
        "--methods",
        "RK4",
        "DOP853-numba",
        "--max-run-s",
        "0.05",
        "--out",
        str(tmp_path),
    ]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    planned = planned_runs(("horizon",), ("RK4", "DOP853-numba"), quick=True)
    assert planned == 6
    counts = re.findall(r"^failure study: (\d+)/(\d+) runs", err, re.M)
    assert counts and {int(total) for _, total in counts} == {planned} and int(counts[-1][0]) == planned, err
    ran = len(read_csv(tmp_path / "failure_study.csv"))
    summary = next(line for line in out.splitlines() if "detected failures" in line)
    skipped = f" ({planned - ran} skipped: over the 0.05 s budget per run, --max-run-s)" if ran < planned else ""
    assert summary.startswith(f"{ran} of {planned} runs{skipped}, "), summary
