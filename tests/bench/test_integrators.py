"""The tables of ``flatbody bench integrators``: made from the saved report, shown on the terminal and written into
the docs page's blocks."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from flatbody_env.bench.harness import write_docs
from flatbody_env.bench.integrators import report, tables

REPORT = Path(__file__).resolve().parents[2] / "docs" / "img" / "bench_integrators.json"


def test_tables_come_from_the_saved_report_and_replace_only_their_block(tmp_path):
    rep = json.loads(REPORT.read_text())
    by_block = {t.block: t.markdown() for t in tables(rep) if t.block}
    assert {"integrators-regular", "integrators-close", "integrators-long", "integrators-short-step"} <= set(by_block)
    for a in rep["regular"]["at_target"]:
        assert f"| {a['method']} |" in by_block["integrators-regular"]
    for x in rep["short_step"]:
        assert f"{x['us_per_step']:.1f}" in by_block["integrators-short-step"]
    if rep.get("auto"):
        for x in rep["auto"]:
            assert f"| {x['scene']} (t = {x['t_end']:g}) | {x['model']} | {x['method']}" in by_block["integrators-auto"]
    text = report(rep).text()
    assert "same rtol, DOP853-numba vs scipy DOP853" in text  # the terminal shows the table the docs leave out
    page = tmp_path / "p.md"
    page.write_text("a\n<!-- bench:integrators-long -->\nstale\n<!-- /bench:integrators-long -->\nb\n")
    assert write_docs(report(rep), page) == ["integrators-long"]  # the blocks the page does not show: skipped
    text = page.read_text()
    assert (
        "stale" not in text
        and text.startswith("a\n<!-- bench:integrators-long -->\n| method and setting")
        and text.endswith("-->\nb\n")
    )
    empty = tmp_path / "e.md"
    empty.write_text("no blocks\n")
    with pytest.raises(ValueError, match="^docs:"):
        write_docs(report(rep), empty)


def test_csv_rows_come_from_the_saved_report():
    """``bench_integrators.csv`` holds one figure a row."""
    from flatbody_env.bench.integrators import CSV_HEADER, csv_rows

    rep = json.loads(REPORT.read_text())
    rows = csv_rows(rep)
    assert all(len(r) == len(CSV_HEADER) for r in rows)
    assert {r[0] for r in rows} >= {"regular", "close-approach", "long-horizon", "short-step"}
    assert sum(r[0] == "long-horizon" for r in rows) == len(rep["long_horizon"])


def test_plot_only_with_docs_rewrites_the_tables_from_the_saved_json(tmp_path):
    from flatbody_env.cli.main import main

    (tmp_path / "bench_integrators.json").write_text(REPORT.read_text())
    page = tmp_path / "p.md"
    page.write_text("<!-- bench:integrators-close -->\nstale\n<!-- /bench:integrators-close -->\n")
    assert main(["bench", "integrators", "--out", str(tmp_path), "--plot-only", "--docs", str(page)]) == 0
    assert "stale" not in page.read_text() and "| s3 − p_θ |" in page.read_text()
    assert (tmp_path / "bench_integrators.png").stat().st_size > 10_000


def test_simulate_vs_kernel_row_comes_from_the_record():
    """Section 6 (simulate against the bare kernel): its table and CSV rows carry the record's figures."""
    from flatbody_env.bench.integrators import csv_rows

    rep = json.loads(REPORT.read_text())
    rep["simulate_vs_kernel"] = v = {
        "scene": "planar-v3",
        "t_end": 100.0,
        "method": "DOP853-numba",
        "nfev": 12554,
        "rounds": 3,
        "kernel_s": 0.00171,
        "integrate_s": 0.00183,
        "simulate_s": 0.00197,
    }
    v["integrate_over_kernel"] = v["integrate_s"] / v["kernel_s"]
    v["simulate_over_kernel"] = v["simulate_s"] / v["kernel_s"]
    (table,) = [t.markdown() for t in tables(rep) if t.block == "integrators-simulate"]
    assert f"{v['simulate_s'] * 1e3:.3f} ms | {v['simulate_over_kernel']:.3f}×" in table and "12554" in table
    rows = [r for r in csv_rows(rep) if r[0] == "simulate-vs-kernel"]
    assert {r[3] for r in rows} == {"kernel", "integrate", "simulate"}
    assert ("ratio_vs_kernel", v["simulate_over_kernel"]) in [(r[4], r[5]) for r in rows if r[3] == "simulate"]
