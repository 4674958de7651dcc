"""Writing a command's output files: atomically, with one-line errors.

:func:`atomic_write` writes to a temporary file in the target's folder and renames it over the
target (``os.replace``), so a killed or failing run never leaves a half-written file under the
requested name and an existing file is replaced in one step. I/O failures become
:class:`OutputError` (an ``OSError`` subclass the CLI prints as one line, exit code 1).
Every output gets the mode the user's umask gives a new file (``0666 & ~umask``: 0644 under the
usual 022), like any file a program creates, not the 0600 of a private temporary file.
:func:`atomic_open`, :func:`write_csv` and :func:`save_figure` do the same for text files, tables and charts.

No planted link is followed: the temporary file is created new (``O_EXCL | O_NOFOLLOW``), a symbolic link
or special file under the requested name is refused (checked before writing and again before the
rename), and the temporary file is removed on any failure (disk full, a writer's error, Ctrl-C).
:func:`append_line` is the one appending writer (the list of trusted run folders).
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

from flatbody_env.physics import validation


class OutputError(OSError):
    """An output file could not be written; the message names the file and the reason (one line)."""


_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def _new_file(folder: Path, prefix: str, suffix: str) -> tuple[Path, int]:
    """A new empty file with a unique name in ``folder`` and its open descriptor, created with mode 0666 so
    that the umask decides its permissions (``tempfile.mkstemp`` would make it 0600). ``O_EXCL`` and
    ``O_NOFOLLOW``: a file or link planted under the name is never opened (another name is drawn)."""
    for _ in range(100):
        name = folder / f"{prefix}{secrets.token_hex(4)}{suffix}"
        try:
            fd = os.open(name, _CREATE, 0o666)
        except FileExistsError:
            continue
        return name, fd
    raise FileExistsError(errno.EEXIST, "no unused temporary file name", str(folder))


def _check_target(target: Path) -> None:
    """Refuse a final name that is a symbolic link or a special file (``OutputError`` naming it): a link planted
    there is never written through nor silently replaced, a FIFO or device never written to."""
    try:
        info = os.lstat(target)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    if stat.S_ISLNK(info.st_mode):
        raise OutputError(
            f"cannot write {str(target)!r}: it is a symbolic link (never written through; remove it to write the file)"
        )
    if stat.S_ISDIR(info.st_mode):
        raise OutputError(f"cannot write {str(target)!r}: it is a directory")
    if not stat.S_ISREG(info.st_mode):
        raise OutputError(f"cannot write {str(target)!r}: it is not a regular file (a FIFO, socket or device)")


@contextlib.contextmanager
def _atomic(path: str | os.PathLike) -> Iterator[tuple[Path, list]]:
    """The temporary file of :func:`atomic_path` and a one-item list holding its open descriptor (a caller that
    closes it, or hands it to a file object, sets the item to None; it is closed here otherwise). On normal exit it is renamed to ``path``; on any error — or when the temporary is no longer a
    regular file of ours (a link swapped in) — it is removed and ``path`` is left as it was."""
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    _check_target(target)
    try:
        tmp, fd = _new_file(folder, f".{target.name}.", ".tmp" + target.suffix)
    except OSError as exc:
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    held = [fd]
    try:
        yield tmp, held
        if held[0] is not None:
            os.close(held[0])
            held[0] = None
        if not stat.S_ISREG(os.lstat(tmp).st_mode):
            raise OutputError(f"cannot write {str(target)!r}: its temporary file was replaced by a link")
        _check_target(target)
        os.replace(tmp, target)
    except OSError as exc:
        _discard(tmp, held)
        if isinstance(exc, OutputError):
            if repr(str(tmp)) in str(exc):  # a writer that is atomic itself named our temporary file: name the target
                raise OutputError(str(exc).replace(repr(str(tmp)), repr(str(target)))) from None
            raise
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    except BaseException:
        _discard(tmp, held)
        raise


def _discard(tmp: Path, held: list) -> None:
    if held and held[0] is not None:
        with contextlib.suppress(OSError):
            os.close(held[0])
        held[0] = None
    with contextlib.suppress(OSError):
        tmp.unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path next to ``path``; on normal exit it is renamed to ``path``, on error removed.

    For writers that want a file name (matplotlib's ``savefig``, rerun's ``save``, SB3's ``save``)::

        with atomic_path("chart.png") as tmp:
            fig.savefig(tmp, format="png")

    The temporary file is created new (``O_EXCL | O_NOFOLLOW``: nothing planted under its name is opened);
    a symbolic link or special file at ``path`` is refused before anything is written and again before the
    rename (:class:`OutputError` naming ``path``), so a planted link is never written through.
    """
    with _atomic(path) as (tmp, held):
        os.close(held[0])
        held[0] = None
        yield tmp


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def atomic_write(
    path: str | os.PathLike, data: str | bytes | Callable[[Path], None], *, encoding: str = "utf-8"
) -> Path:
    """Write ``data`` (text, bytes, or a function that writes a given temporary path) to ``path`` atomically.

    Text and bytes are written through the descriptor of the temporary file created for them (never
    reopened by name).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The folder is missing or not writable, the disk is full, ``path`` is a symbolic link, … (one line
        naming the file); the temporary file is removed.
    """
    if callable(data):
        with atomic_path(path) as tmp:
            data(tmp)
        return Path(path)
    raw = data if isinstance(data, bytes) else data.encode(encoding)
    with _atomic(path) as (_, held):
        _write_all(held[0], raw)
    return Path(path)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike) -> Iterator[TextIO]:
    """A text file (UTF-8, ``newline=""`` as the csv module wants) that becomes ``path`` when the
    block ends without error (:func:`atomic_path`)::

        with atomic_open("table.csv") as fh:
            csv.writer(fh).writerow(["a", "b"])
    """
    with _atomic(path) as (_, held):
        fh = os.fdopen(held[0], "w", newline="", encoding="utf-8")
        held[0] = None  # the file object owns the descriptor now
        with fh:
            yield fh


def append_line(path: str | os.PathLike, line: str) -> Path:
    """Append one line to ``path`` (created with mode 0600 if missing) in a single ``write`` of an
    ``O_APPEND`` descriptor, so concurrent writers never interleave within a line. A symbolic link or a
    special file at ``path`` is refused (``O_NOFOLLOW``, then ``fstat``): :class:`OutputError` naming it.
    For logs that only grow (the list of trusted run folders)."""
    target = Path(path)
    text = line.rstrip("\n") + "\n"
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(target, flags | os.O_NONBLOCK, 0o600)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputError(f"cannot write {str(target)!r}: it is a symbolic link (never written through)") from None
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OutputError(f"cannot write {str(target)!r}: it is not a regular file")
        _write_all(fd, text.encode("utf-8"))
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    return target


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
        info = p.lstat()
    except FileNotFoundError:
        info = None
    except OSError as exc:
        raise ValueError(f"{name}: cannot use {str(text)[:60]!r} ({exc.strerror or exc})") from None
    if info is not None:
        if stat.S_ISLNK(info.st_mode):
            raise ValueError(
                f"{name}: {str(text)[:60]!r} is a symbolic link; outputs are never written through one (remove it)"
            )
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


def shown_path(path: str | os.PathLike, base: str | os.PathLike | None = None) -> str:
    """``path`` as a saved file names it: relative to ``base`` (default: the working directory) when it lies below it —
    the same on every machine —, else as given."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(Path(base if base is not None else Path.cwd()).resolve()))
    except ValueError:
        return str(p)


def replace_marked_block(path: str | os.PathLike, name: str, text: str, *, kind: str = "bench") -> Path:
    """Replace the text between ``<!-- KIND:NAME -->`` and ``<!-- /KIND:NAME -->`` in ``path`` (a
    Markdown page) with ``text``, atomically. Each marker is a line of its own (a marker quoted in
    a sentence is not one). ValueError naming the markers when they are missing, so a docs table
    (``bench``) or transcript (``demo``) is regenerated by the command that makes it and never
    edited by hand."""
    target = Path(path)
    begin, end = f"<!-- {kind}:{name} -->", f"<!-- /{kind}:{name} -->"
    page = validation.read_text("docs", target)  # the one reading door: a regular file, bounded, UTF-8
    first = re.search(rf"^[ \t]*{re.escape(begin)}[ \t]*$", page, re.M)
    last = re.compile(rf"^[ \t]*{re.escape(end)}[ \t]*$", re.M).search(page, first.end()) if first else None
    if last is None:
        raise ValueError(
            f"docs: {str(target)!r} has no block {begin} … {end} (each marker on a line of its own) to regenerate"
        )
    return atomic_write(target, page[: first.end()] + "\n" + text.rstrip("\n") + "\n" + page[last.start() :])


__all__ = [
    "shown_path",
    "OutputError",
    "append_line",
    "atomic_open",
    "atomic_path",
    "atomic_write",
    "replace_marked_block",
    "save_figure",
    "write_csv",
]
