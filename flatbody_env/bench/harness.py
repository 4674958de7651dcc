"""The bench wing's harness: how every ``flatbody bench`` target times and reports.

Timing. This machine is shared and noisy, so a figure is the **best** of several timed blocks, and
figures that are compared are timed **in alternation** (A B C, A B C, …) in one run, so that the
load falls on all of them alike; the reliable results are the ratios of one run.

* :func:`best_of` — the least wall time of ``repeats`` calls of one function (after an untimed warm-up
  call: compiling, caches).
* :func:`alternate` — the least wall time of each of several cases, timed in turn within each round.
  A case that times itself (a GPU launch series synchronised at its end, a block that sets up state
  first) returns its own seconds; otherwise its call is timed.

Reporting. :func:`write_report` writes one benchmark's files side by side: ``NAME.json`` (the record,
with the machine it ran on), ``NAME.csv`` (the table), ``NAME.png`` (drawn from the saved file by the
benchmark's own chart function, so a chart can always be redrawn from the table) and, when asked,
the marked block ``<!-- bench:BLOCK -->`` of a docs page (:func:`flatbody_env.output.replace_marked_block`).
Every file is written atomically (:mod:`flatbody_env.output`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flatbody_env.output import atomic_write, replace_marked_block, write_csv
from flatbody_env.provenance import machine


def best_of(fn: Callable[[], object], repeats: int, *, warm: bool = True) -> float:
    """The least wall time in seconds of ``repeats`` calls of ``fn()``, after one untimed call when ``warm``."""
    if not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats: must be an integer >= 1, got {repeats!r}")
    if warm:
        fn()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def alternate(
    cases: Mapping[str, Callable[[], float | None]],
    rounds: int,
    *,
    warm: bool = True,
    progress: Callable[[int], object] | None = None,
) -> dict[str, float]:
    """The least wall time in seconds of each case, the cases timed in turn within each of ``rounds`` rounds.

    Parameters
    ----------
    cases : mapping of name to function
        A function returns ``None`` (its call is timed) or the seconds it measured itself.
    rounds : int
        Timed rounds (≥ 1); one untimed round comes first when ``warm``.
    progress : callable, optional
        Called with the round number (1 …) after each timed round.
    """
    if not isinstance(rounds, int) or rounds < 1:
        raise ValueError(f"rounds: must be an integer >= 1, got {rounds!r}")
    if warm:
        for fn in cases.values():
            fn()
    best = {name: float("inf") for name in cases}
    for k in range(rounds):
        for name, fn in cases.items():
            start = time.perf_counter()
            own = fn()
            took = time.perf_counter() - start if own is None else float(own)
            best[name] = min(best[name], took)
        if progress is not None:
            progress(k + 1)
    return best


@dataclass(frozen=True, kw_only=True)
class Report:
    """One benchmark's results, ready for :func:`write_report`.

    Attributes
    ----------
    name : str
        File stem: ``NAME.json``, ``NAME.csv``, ``NAME.png``.
    record : dict
        The JSON document (rows, settings, ratios); :func:`write_report` adds ``"machine"`` unless present.
    header, rows
        The CSV table.
    chart : callable, optional
        ``chart(saved_path, png_path)`` draws the PNG from the saved file (``chart_from`` picks which).
    chart_from : {"csv", "json"}
        The saved file the chart reads.
    markdown : str, optional
        The docs block's text (the tables of this run).
    block : str
        The docs block's name (``<!-- bench:BLOCK -->``); default ``name``.
    """

    name: str
    record: dict
    header: Sequence[str]
    rows: Sequence[Sequence[Any]]
    chart: Callable[[Path, Path], None] | None = None
    chart_from: str = "json"
    markdown: str | None = None
    block: str = ""

    def __post_init__(self) -> None:
        if self.chart_from not in ("csv", "json"):
            raise ValueError(f"chart_from: must be 'csv' or 'json', got {self.chart_from!r}")


def write_report(report: Report, out_dir: str | os.PathLike, *, docs: str | os.PathLike | None = None) -> list[Path]:
    """Write ``report`` into ``out_dir`` (made if missing): JSON, CSV, then the PNG drawn from the saved file;
    with ``docs`` (a Markdown page) also its ``<!-- bench:BLOCK -->`` block. Returns the paths written."""
    import json

    if docs and report.markdown is None:
        raise ValueError(f"docs: the {report.name} benchmark writes no docs block")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    record = dict(report.record)
    record.setdefault("machine", machine())
    paths = [
        atomic_write(out / f"{report.name}.json", json.dumps(record, indent=2, default=float) + "\n"),
        write_csv(out / f"{report.name}.csv", report.header, report.rows),
    ]
    if report.chart is not None:
        png = out / f"{report.name}.png"
        report.chart(paths[0] if report.chart_from == "json" else paths[1], png)
        paths.append(png)
    if docs:
        paths.append(replace_marked_block(docs, report.block or report.name, report.markdown))
    return paths


def redraw(
    out_dir: str | os.PathLike, name: str, chart: Callable[[Path, Path], object], *, where: str = "out_dir"
) -> Path:
    """Redraw ``NAME.png`` from the saved ``NAME.json`` in ``out_dir`` (``--plot-only``); a ``ValueError`` naming ``where``
    when no saved run is there. Returns the PNG's path."""
    saved, png = Path(out_dir) / f"{name}.json", Path(out_dir) / f"{name}.png"
    if not saved.exists():
        raise ValueError(f"{where}: no {saved} to plot (run without --plot-only first)")
    chart(saved, png)
    return png


__all__ = ["Report", "alternate", "best_of", "redraw", "write_report"]
