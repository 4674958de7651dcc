"""The bench wing's harness: best of repeats, cases in alternation, one report writer (files, chart from the saved
file, docs block, machine record)."""

from __future__ import annotations

import csv
import json
import time

import pytest

from flatbody_env.bench.harness import (
    Report,
    Stopwatch,
    Table,
    alternate,
    alternate_samples,
    best_of,
    samples,
    write_docs,
    write_report,
)


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
        tables=[Table(columns=["n", "rate"], rows=[["1", "2.5"]])],
    )
    paths = write_report(report, tmp_path / "out", docs=page)
    out = tmp_path / "out"
    assert [p.name for p in paths] == ["demo.json", "demo.csv", "demo.png", "page.md"]
    record = json.loads((out / "demo.json").read_text())
    assert record["rows"] == [[1, 2.5]] and {"cpu", "python", "numpy", "git"} <= set(record["machine"])
    assert list(csv.reader((out / "demo.csv").read_text().splitlines())) == [["n", "rate"], ["1", "2.5"]]
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


def test_best_of_stops_repeating_once_enough_time_went_in():
    calls = []
    best_of(lambda: (calls.append(1), time.sleep(0.02)), 50, warm=False, enough_s=0.05)
    assert 2 <= len(calls) <= 4  # not the 50 asked for


def test_samples_and_mirrored_alternation_keep_every_time():
    pauses = iter([0.0, 0.01, 0.02])
    times = samples(lambda: time.sleep(next(pauses)), 3, warm=False)
    assert len(times) == 3 and times[0] < times[2]
    order = []
    cases = {k: (lambda k=k: order.append(k)) for k in "abc"}
    got = alternate_samples(cases, 3, warm=False, mirror=True)
    assert order == list("abc") + list("cba") + list("abc")  # every other round reversed
    assert {k: len(v) for k, v in got.items()} == {"a": 3, "b": 3, "c": 3}


def test_stopwatch_adds_spans_and_leaves_paused_ones_out():
    sw = Stopwatch()
    for _ in range(2):
        with sw:
            time.sleep(0.02)
    assert 0.035 < sw.seconds < 0.5
    run = Stopwatch.started()
    time.sleep(0.02)
    with run.paused():
        time.sleep(0.1)
    assert 0.015 < run.seconds < 0.09


def test_a_table_is_the_same_rows_on_the_terminal_and_in_the_docs():
    t = Table(
        title="rates",
        columns=["what", "µs"],
        rows=[["`FlatBody-v1`", "**15.7**"], ["Pendulum-v1", "16.5"]],
        notes=["same run"],
    )
    text, md = t.text(), t.markdown()
    assert text.splitlines()[0] == "rates" and "FlatBody-v1" in text and "**" not in text and "`" not in text
    lines = text.splitlines()  # the title, the header, the rule, the rows, the notes
    assert lines[3].endswith("15.7") and lines[4].endswith("16.5") and lines[5] == "same run"  # numbers right-aligned
    assert md.startswith("rates\n\n| what | µs |\n|---|---|\n| `FlatBody-v1` | **15.7** |") and md.endswith("same run")
    with pytest.raises(ValueError, match="rows"):
        Table(columns=["a", "b"], rows=[["1"]])


def test_write_docs_writes_each_block_the_page_shows_and_refuses_a_page_without_any(tmp_path):
    report = Report(
        name="demo",
        record={},
        header=["a"],
        rows=[],
        tables=[
            Table(columns=["a"], rows=[["1"]], block="one"),
            Table(columns=["b"], rows=[["2"]], block="two"),
            Table(columns=["c"], rows=[["3"]], block=None),  # the terminal's only
        ],
    )
    assert report.blocks == ["one", "two"] and "| c |" not in report.markdown("one") and "c" in report.text()
    page = tmp_path / "p.md"
    page.write_text("<!-- bench:two -->\nold\n<!-- /bench:two -->\n")
    assert write_docs(report, page) == ["two"]
    assert page.read_text() == "<!-- bench:two -->\n| b |\n|---|\n| 2 |\n<!-- /bench:two -->\n"
    other = tmp_path / "other.md"
    other.write_text("nothing here\n")
    with pytest.raises(ValueError, match="^docs: .* shows none of the blocks"):
        write_docs(report, other)


def test_no_benchmark_keeps_a_clock_of_its_own():
    """Every ``flatbody bench`` module times with the harness (best_of, samples, alternate, Stopwatch): none reads a
    clock itself. The compare worker is the exception: it runs against another revision's tree, which may have no
    harness (or another one)."""
    import ast
    from pathlib import Path

    import flatbody_env.bench as bench

    clocks = {"perf_counter", "perf_counter_ns", "monotonic", "monotonic_ns", "process_time", "time", "time_ns"}
    found = []
    for path in sorted(Path(bench.__file__).parent.glob("*.py")):
        if path.name in ("harness.py", "compare_worker.py"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr in clocks
                and isinstance(node.func.value, ast.Name)
                and node.func.value.id == "time"
            ):
                found.append(f"{path.name}:{node.lineno} time.{node.func.attr}()")
    assert not found, found
