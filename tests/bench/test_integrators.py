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
