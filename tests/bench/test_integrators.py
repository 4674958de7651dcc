"""The docs tables of ``flatbody bench integrators --docs``: made from the report, written between markers."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from flatbody_env.bench.integrators import docs_tables
from flatbody_env.output import replace_marked_block

REPORT = Path(__file__).resolve().parents[2] / "docs" / "img" / "bench_integrators.json"


def test_tables_come_from_the_saved_report_and_replace_only_their_block(tmp_path):
    rep = json.loads(REPORT.read_text())
    tables = docs_tables(rep)
    assert {"integrators-regular", "integrators-close", "integrators-long", "integrators-short-step"} <= set(tables)
    for a in rep["regular"]["at_target"]:
        assert f"| {a['method']} |" in tables["integrators-regular"]
    for x in rep["short_step"]:
        assert f"{x['us_per_step']:.1f}" in tables["integrators-short-step"]
    if rep.get("auto"):
        for x in rep["auto"]:
            assert f"| {x['scene']} (t = {x['t_end']:g}) | {x['model']} | {x['method']}" in tables["integrators-auto"]
    page = tmp_path / "p.md"
    page.write_text("a\n<!-- bench:integrators-long -->\nstale\n<!-- /bench:integrators-long -->\nb\n")
    replace_marked_block(page, "integrators-long", tables["integrators-long"])
    text = page.read_text()
    assert (
        "stale" not in text
        and text.startswith("a\n<!-- bench:integrators-long -->\n| method and setting")
        and text.endswith("-->\nb\n")
    )
    with pytest.raises(ValueError, match="^docs:"):
        replace_marked_block(page, "integrators-close", "x")


def test_csv_rows_and_docs_come_from_the_saved_report(tmp_path):
    """``bench_integrators.csv`` holds one figure a row; ``--docs`` rewrites the blocks the page shows and skips the rest."""
    from flatbody_env.bench.integrators import CSV_HEADER, csv_rows, write_docs

    rep = json.loads(REPORT.read_text())
    rows = csv_rows(rep)
    assert all(len(r) == len(CSV_HEADER) for r in rows)
    assert {r[0] for r in rows} >= {"regular", "close-approach", "long-horizon", "short-step"}
    assert sum(r[0] == "long-horizon" for r in rows) == len(rep["long_horizon"])
    page = tmp_path / "p.md"
    page.write_text("<!-- bench:integrators-long -->\nstale\n<!-- /bench:integrators-long -->\n")
    assert write_docs(REPORT, page) == ["integrators-long"]
    assert "stale" not in page.read_text() and "| method and setting |" in page.read_text()


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
    table = docs_tables(rep)["integrators-simulate"]
    assert f"{v['simulate_s'] * 1e3:.3f} ms | {v['simulate_over_kernel']:.3f}×" in table and "12554" in table
    rows = [r for r in csv_rows(rep) if r[0] == "simulate-vs-kernel"]
    assert {r[3] for r in rows} == {"kernel", "integrate", "simulate"}
    assert ("ratio_vs_kernel", v["simulate_over_kernel"]) in [(r[4], r[5]) for r in rows if r[3] == "simulate"]
