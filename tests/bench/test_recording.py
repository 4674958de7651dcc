"""``flatbody bench recording``'s report: the docs table, the CSV of sizes and the chart, from a saved result."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from flatbody_env.bench.harness import write_report
from flatbody_env.bench.recording import CSV_HEADER, report

RESULT = Path(__file__).resolve().parents[2] / "docs" / "img" / "recording.json"


def test_report_writes_the_table_the_sizes_and_the_chart_from_the_saved_result(tmp_path):
    result = json.loads(RESULT.read_text(encoding="utf-8"))
    table = report(result).markdown()
    assert table.startswith("| what | result |") and f"{result['frame']['median_ms']:.2f} ms" in table
    assert f"`record_trajectory`, {result['steps']} steps" in table
    assert f"record_trajectory, {result['steps']} steps" in report(result).text()  # the same rows, plain
    page = tmp_path / "page.md"
    page.write_text("a\n<!-- bench:recording -->\nold\n<!-- /bench:recording -->\n")
    paths = write_report(report(result), tmp_path / "out", docs=page)
    assert [p.name for p in paths] == ["recording.json", "recording.csv", "recording.png", "page.md"]
    with open(tmp_path / "out" / "recording.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == CSV_HEADER and [int(r[0]) for r in rows[1:]] == [r["steps"] for r in result["sizes"]]
    saved = json.loads((tmp_path / "out" / "recording.json").read_text(encoding="utf-8"))
    assert saved == result  # every key as measured, none added
    assert (tmp_path / "out" / "recording.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "old" not in page.read_text() and table in page.read_text()
