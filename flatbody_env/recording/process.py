"""Recordings written by a helper process: :class:`RecorderProcess`.

Importing rerun takes 0.4–0.7 s on a small machine — as long as everything else a short command
such as ``flatbody demo`` does. A :class:`RecorderProcess` started at the beginning of such a
command imports rerun and the writer in a second Python process, on another core, while the
command loads its kernels and runs its episode; :class:`~flatbody_env.recording.wrapper.RerunRecorder`
then makes its :class:`~flatbody_env.recording.writer.Recorder` there (``recorder=``) and only
sends the episode's columns. The file is the same as one written in the process itself (tested);
it is complete when the recorder's ``close`` returns, which also reports any error of the helper
(a ``ValueError`` naming the field, as in the process itself).

Messages are pickled frames on the helper's standard input and on a pipe of its own (the helper's
standard output goes to its standard error, so nothing printed there can break a frame). The
helper ends when its input closes (:meth:`RecorderProcess.close`, or the command exiting).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import struct
import subprocess
import sys
from pathlib import Path
from collections.abc import Iterator
from typing import Any, BinaryIO

_HEAD = struct.Struct("<Q")
_MAX_FRAME = 1 << 31
"""Largest frame read (2 GiB): a corrupt length cannot make the reader allocate without bound."""


def _send(stream: BinaryIO, message: Any) -> None:
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEAD.pack(len(data)) + data)
    stream.flush()


def _receive(stream: BinaryIO) -> Any:
    """The next frame's message, or None at the end of the stream."""
    head = stream.read(_HEAD.size)
    if len(head) < _HEAD.size:
        return None
    (n,) = _HEAD.unpack(head)
    if n > _MAX_FRAME:
        raise RuntimeError(f"recorder process: a frame of {n} bytes (corrupt stream)")
    data = stream.read(n)
    if len(data) < n:
        return None
    return pickle.loads(data)


def can_overlap() -> bool:
    """Whether a helper process can run beside this one: a POSIX system (the helper's reply pipe is
    an inherited file descriptor) with more than one processor available."""
    if os.name != "posix" or not sys.executable:  # (an embedded interpreter has no executable to start)
        return False
    try:
        return len(os.sched_getaffinity(0)) > 1
    except AttributeError:  # pragma: no cover - platforms without sched_getaffinity
        return (os.cpu_count() or 1) > 1


@contextlib.contextmanager
def helper_recorder(needed: bool) -> Iterator["RecorderProcess | None"]:
    """A started :class:`RecorderProcess` when a recording is ``needed`` and :func:`can_overlap`, else
    None (the caller records in its own process); closed on leaving the block. Start it before the
    slow imports it is meant to overlap."""
    if not (needed and can_overlap()):
        yield None
        return
    with RecorderProcess() as helper:
        yield helper


class RecorderProcess:
    """A helper process that makes :class:`~flatbody_env.recording.writer.Recorder` objects and
    writes their files; call it like the ``Recorder`` class (``RerunRecorder(env, path,
    recorder=RecorderProcess())``). One recording at a time. POSIX systems (:func:`can_overlap`
    says whether one helps here).

    Use as a context manager or call :meth:`close`.
    """

    def __init__(self) -> None:
        import flatbody_env

        source = str(Path(flatbody_env.__file__).resolve().parents[1])  # the helper imports this very package
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (source, os.environ.get("PYTHONPATH", "")) if p)}
        read_fd, write_fd = os.pipe()
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "flatbody_env.recording.process", str(write_fd)],
                stdin=subprocess.PIPE,
                pass_fds=(write_fd,),
                close_fds=True,
                env=env,
            )
        finally:
            os.close(write_fd)
        self._replies = os.fdopen(read_fd, "rb")
        self._open: _RemoteRecorder | None = None

    def _send(self, message: Any) -> None:
        try:
            _send(self._proc.stdin, message)
        except (BrokenPipeError, OSError) as exc:
            raise RuntimeError(f"recorder process: it ended (exit code {self._proc.poll()}); see its messages above") from exc

    def _reply(self) -> Any:
        reply = _receive(self._replies)
        if reply is None:
            raise RuntimeError(f"recorder process: it ended without an answer (exit code {self._proc.wait()}); see its messages above")
        return reply

    def __call__(self, path: str | Path, body, **kwargs) -> "_RemoteRecorder":
        if self._open is not None:
            raise RuntimeError("recorder process: one recording at a time (close the open one first)")
        self._send(("open", (str(path), body), kwargs))
        self._open = _RemoteRecorder(self, Path(path))
        return self._open

    def close(self) -> None:
        """End the helper. A recording still open is abandoned: the helper removes its file (the
        caller failed part-way, so no half-written file is left behind)."""
        if self._open is not None and self._proc.poll() is None:
            try:
                self._send(("abort", (), {}))
                self._reply()
            except RuntimeError:
                pass
        self._open = None
        if self._proc.poll() is None:
            try:
                self._proc.stdin.close()
            except OSError:
                pass
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._replies.close()

    def __enter__(self) -> "RecorderProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _RemoteRecorder:
    """What :class:`~flatbody_env.recording.wrapper.RerunRecorder` uses of a ``Recorder``, in the helper."""

    def __init__(self, owner: RecorderProcess, path: Path) -> None:
        self._owner = owner
        self.path = path
        self._closed = False

    def extend(self, *args, **kwargs) -> None:
        self._owner._send(("extend", args, kwargs))

    def note(self, *args, **kwargs) -> None:
        self._owner._send(("note", args, kwargs))

    def close(self) -> Path:
        """Finish the file in the helper; raises what the helper raised (``ValueError`` as such)."""
        if self._closed:
            return self.path
        self._closed = True
        self._owner._open = None
        self._owner._send(("close", (), {}))
        kind, text = self._owner._reply()
        if kind == "ValueError":
            raise ValueError(text)
        if kind is not None:
            raise RuntimeError(f"recorder process: {kind}: {text}")
        return self.path


def _serve(inp: BinaryIO, out: BinaryIO) -> None:
    """The helper's loop: import rerun and the writer, then serve open, extend, note, close and abort
    (close an open recording and remove its file)."""
    from flatbody_env.recording import writer

    writer.warm_up()
    rec = None
    error: tuple[str, str] | None = None
    while (message := _receive(inp)) is not None:
        op, args, kwargs = message
        try:
            if op == "open":
                rec, error = None, None
                rec = writer.Recorder(*args, **kwargs)
            elif op == "close":
                if rec is not None:
                    rec.close()
                _send(out, error or (None, ""))
                rec, error = None, None
            elif op == "abort":
                if rec is not None:
                    try:
                        rec.close()
                    finally:
                        rec.path.unlink(missing_ok=True)
                _send(out, (None, ""))
                rec, error = None, None
            elif error is None and rec is not None and op in ("extend", "note"):
                getattr(rec, op)(*args, **kwargs)
        except Exception as exc:  # reported at close, as the Recorder in the process itself would raise it
            error = error or (type(exc).__name__, str(exc))
            if op in ("close", "abort"):
                _send(out, error)
                rec, error = None, None


if __name__ == "__main__":
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the caller's: the helper ends when its input closes
    reply_fd = int(sys.argv[1])
    replies = os.fdopen(reply_fd, "wb")
    os.dup2(2, 1)  # whatever the helper prints goes to standard error, not into a frame
    _serve(sys.stdin.buffer, replies)
    # Every recording is closed (its file complete) by now: end without the interpreter's
    # finalisation, which with rerun and pyarrow loaded takes ≈ 0.2 s that the caller would wait for.
    sys.stderr.flush()
    os._exit(0)
