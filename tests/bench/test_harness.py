"""The bench wing's harness: best of repeats, cases in alternation, one report writer (files, chart from the saved
file, docs block, machine record)."""

from __future__ import annotations

import csv
import json
import time

import pytest

from flatbody_env.bench.harness import Report, alternate, best_of, write_report


def test_best_of_keeps_the_least_time_after_an_untimed_warm_up():
    pauses = iter([0.2, 0.03, 0.005, 0.02])  # the first (0.2 s, "compiling") is the warm-up
    calls = []

    def fn():
        calls.append(1)
        time.sleep(next(pauses))

    best = best_of(fn, 3)
    assert len(calls) == 4 and 0.005 <= best < 0.02
    with pytest.raises(ValueError, match="repeats"):
        best_of(fn, 0)


def test_alternate_times_the_cases_in_turn_and_takes_own_seconds():
    order = []
    own = iter([5.0, 3.0, 4.0])

    def a():
        order.append("a")

    def b():
        order.append("b")
        return next(own)  # a case that timed itself (e.g. a GPU launch series, synchronised)

    seen = []
    best = alternate({"a": a, "b": b}, 2, progress=seen.append)
    assert order == ["a", "b", "a", "b", "a", "b"]  # warm-up round, then two rounds in turn
    assert best["b"] == 3.0 and best["a"] < 0.01 and seen == [1, 2]
    with pytest.raises(ValueError, match="rounds"):
        alternate({"a": a}, 0)


def test_write_report_writes_the_record_the_table_the_chart_from_the_saved_file_and_the_docs_block(tmp_path):
    drawn = []

    def chart(saved, png):
        drawn.append(json.loads(saved.read_text())["rows"])
        png.write_bytes(b"png")

    page = tmp_path / "page.md"
    page.write_text("# x\n<!-- bench:demo -->\nold\n<!-- /bench:demo -->\nafter\n")
    report = Report(
        name="demo",
        record={"rows": [[1, 2.5]]},
        header=["n", "rate"],
        rows=[[1, 2.5]],
        chart=chart,
        markdown="| n | rate |\n|---|---|\n| 1 | 2.5 |\n",
    )
    paths = write_report(report, tmp_path / "out", docs=page)
    out = tmp_path / "out"
    assert [p.name for p in paths] == ["demo.json", "demo.csv", "demo.png", "page.md"]
    record = json.loads((out / "demo.json").read_text())
    assert record["rows"] == [[1, 2.5]] and {"cpu", "python", "numpy", "git"} <= set(record["machine"])
    assert list(csv.reader(open(out / "demo.csv"))) == [["n", "rate"], ["1", "2.5"]]
    assert drawn == [[[1, 2.5]]]
    assert (
        page.read_text()
        == "# x\n<!-- bench:demo -->\n| n | rate |\n|---|---|\n| 1 | 2.5 |\n<!-- /bench:demo -->\nafter\n"
    )


def test_write_report_refuses_a_docs_page_without_a_block_text(tmp_path):
    with pytest.raises(ValueError, match="docs"):
        write_report(Report(name="x", record={}, header=["a"], rows=[]), tmp_path / "out", docs=tmp_path / "p.md")
    assert not (tmp_path / "out").exists()  # refused before anything is written
    with pytest.raises(ValueError, match="chart_from"):
        Report(name="x", record={}, header=["a"], rows=[], chart_from="png")


def test_redraw_draws_from_the_saved_record_or_names_the_folder(tmp_path):
    from flatbody_env.bench.harness import redraw

    with pytest.raises(ValueError, match="out_dir: no .*demo.json to plot"):
        redraw(tmp_path, "demo", lambda saved, png: None)
    (tmp_path / "demo.json").write_text('{"rows": [1]}')
    seen = []
    png = redraw(tmp_path, "demo", lambda saved, png: seen.append((json.loads(saved.read_text()), png)))
    assert png == tmp_path / "demo.png" and seen == [({"rows": [1]}, png)]
