"""Progress of long work (sweeps, training, studies, benchmarks), on stderr: one home for every bar.

:func:`progress_bar` gives a tqdm bar when stderr is a terminal, and otherwise (a log file, a pipe,
a job scheduler's output) a :class:`LineProgress` that prints one plain line every
:data:`INTERVAL_S` seconds — never carriage returns — and a last line when the work completes, if it
printed any. Work shorter than the interval prints nothing. The environment variable
``FLATBODY_PROGRESS_S`` sets that interval (seconds, ≥ 0; 0: a line at every update).

Both kinds take the same calls: ``update(n)``, ``set_postfix_str(text)``, ``set_postfix(mapping)``,
``close()``, iteration over a given iterable, and ``with``.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, TextIO

INTERVAL_S = 10.0
"""Seconds between two progress lines when stderr is not a terminal (``FLATBODY_PROGRESS_S`` overrides)."""


def interval_s() -> float:
    """The line interval: ``FLATBODY_PROGRESS_S`` when set, else :data:`INTERVAL_S`.

    Raises
    ------
    ValueError
        ``FLATBODY_PROGRESS_S`` is not a number ≥ 0 (one line naming it).
    """
    text = os.environ.get("FLATBODY_PROGRESS_S")
    if text is None or not text.strip():
        return INTERVAL_S
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    from flatbody_env.physics import validation

    validation.requirement(
        "FLATBODY_PROGRESS_S", text[:40], math.isfinite(value) and value >= 0, "be a number of seconds >= 0"
    )
    return value


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    h, rest = divmod(s, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60:02d}:{rest % 60:02d}"


class LineProgress:
    """Progress as plain lines (for a stderr that is not a terminal).

    Parameters
    ----------
    iterable : iterable, optional
        Iterate over this, counting one per item.
    total : int, optional
        Units of work (default ``len(iterable)`` where it has one).
    desc, unit : str
        What is counted, e.g. ``"sweep stability-map"``, ``"task"``.
    initial : int
        Units already done (a resumed run).
    enabled : bool
        False: print nothing.
    file : text stream, optional
        Where the lines go (default ``sys.stderr``).
    interval : float, optional
        Seconds between lines (default :func:`interval_s`).
    """

    def __init__(
        self,
        iterable: Iterable | None = None,
        *,
        total: int | None = None,
        desc: str = "",
        unit: str = "it",
        initial: int = 0,
        enabled: bool = True,
        file: TextIO | None = None,
        interval: float | None = None,
    ) -> None:
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)  # type: ignore[arg-type]
        self.iterable = iterable
        self.total = total
        self.desc = desc
        self.unit = unit
        self.n = int(initial)
        self.enabled = enabled
        self.file = file
        self.interval = (interval_s() if interval is None else float(interval)) if enabled else math.inf
        self.postfix = ""
        self.lines = 0
        self._initial = int(initial)
        self._t0 = self._last = time.monotonic()
        self._closed = False

    def __iter__(self) -> Iterator:
        for item in self.iterable if self.iterable is not None else ():
            yield item
            self.update(1)
        self.close()  # as tqdm does at the end of the iterable

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def update(self, n: int = 1) -> None:
        """Count ``n`` more units; print a line when the interval has passed since the last one."""
        self.n += n
        now = time.monotonic()
        if self.enabled and not self._closed and now - self._last >= self.interval:
            self._write(self.line(now))
            self._last = now

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        """What is being worked on, shown at the end of the next line."""
        self.postfix = str(s)

    def set_postfix(self, ordered_dict: Mapping[str, Any] | None = None, refresh: bool = True, **kwargs: Any) -> None:
        """Figures shown at the end of the next line (``name=value, ...``)."""
        items = {**(ordered_dict or {}), **kwargs}
        self.postfix = ", ".join(f"{k}={v}" for k, v in items.items())

    def line(self, now: float | None = None) -> str:
        """The progress line: count, share, elapsed time, time left at the mean rate, postfix."""
        elapsed = (time.monotonic() if now is None else now) - self._t0
        text = f"{self.desc}: {self.n}" if self.desc else f"{self.n}"
        units = self.unit if self.unit.endswith("s") else self.unit + "s"
        if self.total:
            text += f"/{self.total} {units} ({100.0 * self.n / self.total:.0f}%)"
        else:
            text += f" {units}"
        text += f", {_clock(elapsed)} elapsed"
        done = self.n - self._initial
        if self.total and done > 0 and self.n < self.total:
            text += f", ~{_clock(elapsed / done * (self.total - self.n))} left"
        return text + (f" [{self.postfix}]" if self.postfix else "")

    def close(self) -> None:
        """End the bar: a last line when the work completed and a line was printed before."""
        if self._closed:
            return
        self._closed = True
        if self.enabled and self.lines and (self.total is None or self.n >= self.total):
            self.postfix = ""
            self._write(self.line() + " - done")

    def _write(self, text: str) -> None:
        out = self.file if self.file is not None else sys.stderr
        try:
            out.write(text + "\n")
            out.flush()
        except (OSError, ValueError):  # a closed or broken stderr never stops the work
            self.enabled = False
        self.lines += 1


def progress_bar(
    iterable: Iterable | None = None,
    *,
    total: int | None = None,
    desc: str = "",
    unit: str = "it",
    initial: int = 0,
    enabled: bool = True,
    leave: bool = True,
    file: TextIO | None = None,
):
    """A progress bar on stderr: tqdm on a terminal, :class:`LineProgress` lines otherwise.

    Parameters
    ----------
    iterable : iterable, optional
        Iterate over the bar to count its items.
    total : int, optional
        Units of work.
    desc, unit : str
        Label and unit.
    initial : int
        Units already done.
    enabled : bool
        False: nothing is shown (the bar still counts).
    leave : bool
        On a terminal, keep the finished bar on screen.
    file : text stream, optional
        Default ``sys.stderr``.

    Returns
    -------
    tqdm or LineProgress
    """
    out = file if file is not None else sys.stderr
    try:
        tty = bool(out.isatty())
    except (AttributeError, ValueError, OSError):
        tty = False
    if tty and enabled:
        from tqdm.auto import tqdm

        return tqdm(
            iterable, total=total, desc=desc, unit=unit, initial=initial, leave=leave, dynamic_ncols=True, file=out
        )
    return LineProgress(iterable, total=total, desc=desc, unit=unit, initial=initial, enabled=enabled, file=file)


__all__ = ["INTERVAL_S", "LineProgress", "interval_s", "progress_bar"]
