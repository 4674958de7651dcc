"""Writing a command's output files: atomically, with one-line errors.

:func:`atomic_write` writes to a temporary file in the target's folder and renames it over the
target (``os.replace``), so a killed or failing run never leaves a half-written file under the
requested name and an existing file is replaced in one step. I/O failures become
:class:`OutputError` (an ``OSError`` subclass the CLI prints as one line, exit code 1).
Every output gets the mode the user's umask gives a new file (``0666 & ~umask``: 0644 under the
usual 022), like any file a program creates, not the 0600 of a private temporary file.
:func:`atomic_open`, :func:`write_csv` and :func:`save_figure` do the same for text files, tables and charts.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import os
import re
import secrets
import stat
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, TextIO


class OutputError(OSError):
    """An output file could not be written; the message names the file and the reason (one line)."""


def _new_file(folder: Path, prefix: str, suffix: str) -> Path:
    """A new empty file with a unique name in ``folder``, created with mode 0666 so that the umask
    decides its permissions (``tempfile.mkstemp`` would make it 0600)."""
    for _ in range(100):
        name = folder / f"{prefix}{secrets.token_hex(4)}{suffix}"
        try:
            fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return name
    raise FileExistsError(errno.EEXIST, "no unused temporary file name", str(folder))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path next to ``path``; on normal exit it is renamed to ``path``, on error removed.

    For writers that want a file name (matplotlib's ``savefig``, rerun's ``save``)::

        with atomic_path("chart.png") as tmp:
            fig.savefig(tmp, format="png")
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    try:
        tmp = _new_file(folder, f".{target.name}.", ".tmp" + target.suffix)
    except OSError as exc:
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    try:
        yield tmp
        os.replace(tmp, target)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OutputError):
            if repr(str(tmp)) in str(exc):  # a writer that is atomic itself named our temporary file: name the target
                raise OutputError(str(exc).replace(repr(str(tmp)), repr(str(target)))) from None
            raise
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def atomic_write(
    path: str | os.PathLike, data: str | bytes | Callable[[Path], None], *, encoding: str = "utf-8"
) -> Path:
    """Write ``data`` (text, bytes, or a function that writes a given temporary path) to ``path`` atomically.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The folder is missing or not writable, the disk is full, … (one line naming the file).
    """
    with atomic_path(path) as tmp:
        if callable(data):
            data(tmp)
        elif isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data, encoding=encoding)
    return Path(path)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike) -> Iterator[TextIO]:
    """A text file (UTF-8, ``newline=""`` as the csv module wants) that becomes ``path`` when the
    block ends without error (:func:`atomic_path`)::

        with atomic_open("table.csv") as fh:
            csv.writer(fh).writerow(["a", "b"])
    """
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            yield fh


def write_csv(path: str | os.PathLike, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    """Write a CSV table (a header row, then ``rows``) to ``path`` atomically (:func:`atomic_open`)."""
    with atomic_open(path) as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return Path(path)


def save_figure(fig, path: str | os.PathLike, *, dpi: int) -> Path:
    """Save a matplotlib figure as PNG to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return Path(path)


def check_output_path(name: str, text: str | os.PathLike, suffixes: tuple[str, ...] = ()) -> Path:
    """The checks of :func:`output_file` (``ValueError`` naming ``name``), for paths built by a command."""
    p = Path(text)
    if not str(text) or "\0" in str(text):
        raise ValueError(f"{name}: expected a file path, got {str(text)[:60]!r}")
    if suffixes and p.suffix.lower() not in suffixes:
        raise ValueError(f"{name}: expected a file ending in {' or '.join(suffixes)}, got {str(text)[:60]!r}")
    try:
        info = p.stat()
    except FileNotFoundError:
        info = None
    except OSError as exc:
        raise ValueError(f"{name}: cannot use {str(text)[:60]!r} ({exc.strerror or exc})") from None
    if info is not None:
        if stat.S_ISDIR(info.st_mode):
            raise ValueError(f"{name}: {str(text)[:60]!r} is a directory; give a file name")
        if not stat.S_ISREG(info.st_mode):
            raise ValueError(f"{name}: {str(text)[:60]!r} is not a regular file")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"{name}: the directory {str(parent)[:60]!r} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{name}: the directory {str(parent)[:60]!r} is not writable")
    return p


def replace_marked_block(path: str | os.PathLike, name: str, text: str, *, kind: str = "bench") -> Path:
    """Replace the text between ``<!-- KIND:NAME -->`` and ``<!-- /KIND:NAME -->`` in ``path`` (a
    Markdown page) with ``text``, atomically. Each marker is a line of its own (a marker quoted in
    a sentence is not one). ValueError naming the markers when they are missing, so a docs table
    (``bench``) or transcript (``demo``) is regenerated by the command that makes it and never
    edited by hand."""
    target = Path(path)
    begin, end = f"<!-- {kind}:{name} -->", f"<!-- /{kind}:{name} -->"
    try:
        page = target.read_text(encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot read {str(target)!r}: {exc.strerror or exc}") from None
    first = re.search(rf"^[ \t]*{re.escape(begin)}[ \t]*$", page, re.M)
    last = re.compile(rf"^[ \t]*{re.escape(end)}[ \t]*$", re.M).search(page, first.end()) if first else None
    if last is None:
        raise ValueError(
            f"docs: {str(target)!r} has no block {begin} … {end} (each marker on a line of its own) to regenerate"
        )
    return atomic_write(target, page[: first.end()] + "\n" + text.rstrip("\n") + "\n" + page[last.start() :])


__all__ = [
    "OutputError",
    "atomic_open",
    "atomic_path",
    "atomic_write",
    "replace_marked_block",
    "save_figure",
    "write_csv",
]
