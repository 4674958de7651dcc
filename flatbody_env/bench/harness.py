"""The bench wing's harness: how every ``flatbody bench`` target times and reports.

Timing. This machine is shared and noisy, so a figure is the **best** of several timed blocks, and
figures that are compared are timed **in alternation** (A B C, A B C, …) in one run, so that the
load falls on all of them alike; the reliable results are the ratios of one run. Every benchmark times
with these and nothing else (a test reads the bench modules for clocks of their own):

* :func:`best_of` — the least wall time of ``repeats`` calls of one function (after an untimed warm-up
  call: compiling, caches); with ``enough_s``, fewer calls once that much time went into them.
* :func:`samples` — the wall time of each of ``repeats`` calls (for medians and spreads).
* :func:`alternate` / :func:`alternate_samples` — the cases timed in turn within each round; the least time
  of each case, or all of them. A case that times itself (a GPU launch series synchronised at its end, a
  block that sets up state first, a block run in another process) returns its own seconds; otherwise its
  call is timed. ``mirror`` runs every other round in reverse order, so that no case always follows the same one.
* :class:`Stopwatch` — a span that is not a repeated call: a run's wall time, less the spans it was paused
  for (evaluations left out of a training's time), or the sum of many spans (the time spent inside an env).

Reporting. A benchmark hands back a :class:`Report`: its JSON record, its CSV table, its chart and its
:class:`Table` s. The tables are rendered from their rows twice — :meth:`Report.text` for the terminal and
:meth:`Report.markdown` for the docs page's marked blocks — so the terminal and the docs always say the same.
:func:`write_report` writes one benchmark's files side by side: ``NAME.json`` (the record, with the machine it
ran on), ``NAME.csv`` (the table), ``NAME.png`` (drawn from the saved file by the benchmark's own chart
function, so a chart can always be redrawn from the table) and, when asked, the marked blocks
``<!-- bench:BLOCK -->`` of a docs page (:func:`flatbody_env.output.replace_marked_block`). Every file is
written atomically (:mod:`flatbody_env.output`).
"""

from __future__ import annotations

import contextlib
import os
import re
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flatbody_env.physics import validation


# --------------------------------------------------------------------------------------------- timers
def _calls(where: str, n: Any) -> int:
    return validation.integer(where, n, low=1, high=validation.MAX_COUNT)


def best_of(fn: Callable[[], object], repeats: int, *, warm: bool = True, enough_s: float | None = None) -> float:
    """The least wall time in seconds of ``repeats`` calls of ``fn()``, after one untimed call when ``warm``; with
    ``enough_s``, the calls stop early once that many seconds went into them (a long run is not repeated)."""
    _calls("repeats", repeats)
    if warm:
        fn()
    best, spent = float("inf"), 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        took = time.perf_counter() - start
        best, spent = min(best, took), spent + took
        if enough_s is not None and spent >= enough_s:
            break
    return best


def samples(fn: Callable[[], object], repeats: int, *, warm: bool = True) -> list[float]:
    """The wall time in seconds of each of ``repeats`` calls of ``fn()``, after one untimed call when ``warm``."""
    _calls("repeats", repeats)
    if warm:
        fn()
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return out


def alternate_samples(
    cases: Mapping[str, Callable[[], float | None]],
    rounds: int,
    *,
    warm: bool = True,
    mirror: bool = False,
    progress: Callable[[int], object] | None = None,
) -> dict[str, list[float]]:
    """The wall time in seconds of each case in each round, the cases timed in turn within each of ``rounds`` rounds.

    Parameters
    ----------
    cases : mapping of name to function
        A function returns the seconds it measured itself (a number), or anything else (``None``, a result): then
        its call is timed.
    rounds : int
        Timed rounds (≥ 1); one untimed round comes first when ``warm``.
    mirror : bool
        Every other round runs the cases in reverse order.
    progress : callable, optional
        Called with the round number (1 …) after each timed round.
    """
    _calls("rounds", rounds)
    if warm:
        for fn in cases.values():
            fn()
    out: dict[str, list[float]] = {name: [] for name in cases}
    order = list(cases.items())
    for k in range(rounds):
        for name, fn in reversed(order) if mirror and k % 2 else order:
            start = time.perf_counter()
            own = fn()
            took = time.perf_counter() - start
            own_seconds = isinstance(own, (int, float)) and not isinstance(own, bool)
            out[name].append(float(own) if own_seconds else took)
        if progress is not None:
            progress(k + 1)
    return out


def alternate(
    cases: Mapping[str, Callable[[], float | None]],
    rounds: int,
    *,
    warm: bool = True,
    mirror: bool = False,
    progress: Callable[[int], object] | None = None,
) -> dict[str, float]:
    """The least wall time in seconds of each case, the cases timed in turn within each round
    (:func:`alternate_samples`, whose parameters these are)."""
    times = alternate_samples(cases, rounds, warm=warm, mirror=mirror, progress=progress)
    return {name: min(v) for name, v in times.items()}


class Stopwatch:
    """Wall time of spans that are not repeated calls.

    ``with Stopwatch() as sw: ...`` times the block (``sw.seconds`` afterwards); one stopwatch used as the context of
    several blocks adds them up; :meth:`started` starts one running, :meth:`paused` leaves a span out of it.
    """

    __slots__ = ("_since", "_total")

    def __init__(self) -> None:
        self._total = 0.0
        self._since: float | None = None

    @classmethod
    def started(cls) -> Stopwatch:
        """A stopwatch running from now."""
        sw = cls()
        sw._since = time.perf_counter()
        return sw

    def __enter__(self) -> Stopwatch:
        self._since = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self._total += time.perf_counter() - self._since
        self._since = None

    @property
    def seconds(self) -> float:
        """The seconds timed so far (the running span included)."""
        return self._total + (0.0 if self._since is None else time.perf_counter() - self._since)

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """Leave the block's time out of a running stopwatch."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self._total -= time.perf_counter() - start


# --------------------------------------------------------------------------------------------- tables
_NUMERIC = re.compile(r"^[-+−]?[\d.,]+(e[-+]?\d+)?\s*([a-zµ%×x]{0,4}|[a-zµ/]+)?$", re.I)


def _plain(cell: Any) -> str:
    """A cell as the terminal shows it: no Markdown emphasis or code marks."""
    return str(cell).replace("**", "").replace("`", "")


@dataclass(frozen=True, kw_only=True)
class Table:
    """One table of a report, shown in the terminal and on the docs page from the same rows.

    Attributes
    ----------
    columns : sequence of str
        The header.
    rows : sequence of sequences
        The cells as shown (text: ``**bold**`` and ```code``` marks are kept on the docs page, dropped in the terminal).
    title : str
        A line above the table (none when empty).
    notes : sequence of str
        Lines under the table.
    block : str or None
        The docs block (``<!-- bench:BLOCK -->``) the table goes in: "" the report's own, ``None`` the terminal only.
    """

    columns: Sequence[str]
    rows: Sequence[Sequence[Any]]
    title: str = ""
    notes: Sequence[str] = ()
    block: str | None = ""

    def __post_init__(self) -> None:
        bad = [k for k, r in enumerate(self.rows) if len(r) != len(self.columns)]
        if bad:
            raise ValueError(f"rows: row {bad[0]} has {len(self.rows[bad[0]])} cells for {len(self.columns)} columns")

    def text(self) -> str:
        """Aligned columns for the terminal (numbers right-aligned), the title above and the notes under them."""
        cells = [[_plain(c) for c in self.columns]] + [[_plain(c) for c in r] for r in self.rows]
        widths = [max(len(row[i]) for row in cells) for i in range(len(self.columns))]
        right = [
            bool(self.rows) and all(_NUMERIC.match(r[i]) or r[i] in ("", "—", "–") for r in cells[1:])
            for i in range(len(self.columns))
        ]
        lines = [self.title] if self.title else []
        for k, row in enumerate(cells):
            lines.append("  ".join(c.rjust(w) if r else c.ljust(w) for c, w, r in zip(row, widths, right, strict=True)))
            if k == 0:
                lines.append("  ".join("-" * w for w in widths))
        lines += [_plain(n) for n in self.notes]
        return "\n".join(line.rstrip() for line in lines)

    def markdown(self) -> str:
        """A Markdown table, the title above it and the notes under it."""
        lines = [self.title, ""] if self.title else []
        lines.append("| " + " | ".join(str(c) for c in self.columns) + " |")
        lines.append("|" + "---|" * len(self.columns))
        lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in self.rows]
        if self.notes:
            lines += ["", *self.notes]
        return "\n".join(lines)


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
    tables : sequence of Table
        What the terminal shows (:meth:`text`) and the docs blocks hold (:meth:`markdown`).
    block : str
        The docs block of the tables whose own block is ""; default ``name``.
    """

    name: str
    record: dict
    header: Sequence[str]
    rows: Sequence[Sequence[Any]]
    chart: Callable[[Path, Path], object] | None = None
    chart_from: str = "json"
    tables: Sequence[Table] = field(default_factory=tuple)
    block: str = ""

    def __post_init__(self) -> None:
        if self.chart_from not in ("csv", "json"):
            raise ValueError(f"chart_from: expected 'csv' or 'json', got {self.chart_from!r}")

    def _block(self, table: Table) -> str | None:
        return None if table.block is None else table.block or self.block or self.name

    @property
    def blocks(self) -> list[str]:
        """The docs blocks this report writes, in order."""
        return list(dict.fromkeys(b for b in map(self._block, self.tables) if b is not None))

    def text(self) -> str:
        """Every table for the terminal, a blank line between them."""
        return "\n\n".join(t.text() for t in self.tables)

    def markdown(self, block: str | None = None) -> str:
        """The Markdown of the docs block ``block`` (default: the report's first): its tables, a blank line between."""
        block = block if block is not None else (self.blocks[0] if self.blocks else self.block or self.name)
        return "\n\n".join(t.markdown() for t in self.tables if self._block(t) == block) + "\n"


def write_docs(report: Report, docs: str | os.PathLike) -> list[str]:
    """Rewrite the ``<!-- bench:BLOCK -->`` blocks of the page ``docs`` with the report's tables. A block the page does
    not show is skipped, but a ``ValueError`` naming ``docs`` comes when it shows none of them (before anything is
    written). Returns the blocks rewritten."""
    from flatbody_env.output import replace_marked_block

    blocks = report.blocks
    if not blocks:
        raise ValueError(f"docs: the {report.name} benchmark writes no docs block")
    page = validation.read_text("docs", docs)
    shown = [b for b in blocks if re.search(rf"^[ \t]*<!-- bench:{re.escape(b)} -->[ \t]*$", page, re.M)]
    if not shown:
        raise ValueError(
            f"docs: {str(docs)!r} shows none of the blocks " + ", ".join(f"<!-- bench:{b} -->" for b in blocks)
        )
    for b in shown:
        replace_marked_block(docs, b, report.markdown(b))
    return shown


def write_report(report: Report, out_dir: str | os.PathLike, *, docs: str | os.PathLike | None = None) -> list[Path]:
    """Write ``report`` into ``out_dir`` (made if missing): JSON, CSV, then the PNG drawn from the saved file;
    with ``docs`` (a Markdown page) also its blocks (:func:`write_docs`). Returns the paths written."""
    import json

    from flatbody_env.output import atomic_write, write_csv
    from flatbody_env.provenance import machine

    if docs and not report.blocks:
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
        write_docs(report, docs)
        paths.append(Path(docs))
    return paths


def redraw(
    out_dir: str | os.PathLike, name: str, chart: Callable[[Path, Path], object], *, where: str = "out_dir"
) -> Path:
    """Redraw ``NAME.png`` from the saved ``NAME.json`` in ``out_dir`` (``--plot-only``); a ``ValueError`` naming
    ``where`` when no saved run is there. Returns the PNG's path."""
    saved, png = Path(out_dir) / f"{name}.json", Path(out_dir) / f"{name}.png"
    if not saved.exists():
        raise ValueError(f"{where}: no {saved} to plot (run without --plot-only first)")
    chart(saved, png)
    return png


__all__ = [
    "Report",
    "Stopwatch",
    "Table",
    "alternate",
    "alternate_samples",
    "best_of",
    "redraw",
    "samples",
    "write_docs",
    "write_report",
]
