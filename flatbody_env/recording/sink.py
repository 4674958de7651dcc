"""Where a :class:`~flatbody_env.recording.writer.Recorder` writes its ``.rrd`` file: :class:`FileSink`.

rerun's own file sink (``RecordingStream.save(path)``) writes from rerun's threads, and once one of its
writes fails — a full disk (ENOSPC), the file-size limit (EFBIG) — its ``flush`` waits for ever: the
program hangs instead of failing. So rerun never writes the file itself here. rerun's file sink writes
into a private pipe (a FIFO in a fresh temporary folder), and a thread of ours copies the pipe into a
temporary file next to the target, which is renamed over the target when the recording is closed
(:func:`flatbody_env.output.atomic_path`). A write that fails is an ``OSError`` in our thread: the thread
keeps draining the pipe (so rerun never blocks), the failure is raised in the recording's thread as an
:class:`~flatbody_env.output.OutputError` (one line, exit 1) at the next block or at ``close``, the
temporary file is removed, and a file that was already under the target's name is kept as it was.

The bytes are rerun's own encoding, footer included (the same file ``save`` writes), streamed as they
are logged: the memory used does not grow with the recording. Only rerun's public API is used
(``RecordingStream.save``, ``flush``, ``disconnect``).

Where a FIFO cannot be made (no ``os.mkfifo``), rerun's ``binary_stream`` is read once at ``close`` and
written by us: same file and same failure handling, but the whole recording is held in memory until then
(a stream read more than once gives a file with several footers, which ``rerun rrd verify`` refuses).
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import functools
import os
import select
import shutil
import tempfile
import threading
import weakref
from pathlib import Path
from typing import Any

from flatbody_env.output import OutputError, atomic_path

try:
    import fcntl
except ImportError:  # pragma: no cover - not on Windows
    fcntl = None

CHUNK = 1 << 20
"""Bytes read from the pipe at a time."""

PIPE_SIZE = 1 << 20
"""Bytes the pipe holds (Linux's default is 64 KiB; 1 MiB is the unprivileged maximum)."""

FINISH_TIMEOUT_S = 120.0
"""Generous limit for the copy thread to finish after rerun has closed the pipe (it has at most a pipe's
buffer left to write); past it the recording fails instead of waiting."""

_REASONS = {
    errno.EFBIG: "file too large: over the file-size limit (RLIMIT_FSIZE)",
    errno.ENOSPC: "no space left on device",
    errno.EDQUOT: "disk quota exceeded",
}


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError):
        return _REASONS.get(exc.errno, exc.strerror or str(exc))
    return str(exc) or type(exc).__name__


class FileSink:
    """rerun's file sink writing into a pipe that our thread copies to ``path`` (atomically).

    Parameters
    ----------
    rec : rerun.RecordingStream
        The recording; its data logged so far and from now on go to ``path``.
    path : Path
        The ``.rrd`` file; it appears under this name only when :meth:`close` succeeds.
    blueprint : rerun blueprint, optional
        The recording's default blueprint (as ``RecordingStream.save(..., default_blueprint=...)``).

    Raises
    ------
    OutputError
        The folder cannot hold a new file (one line naming the file).
    """

    def __init__(self, rec: Any, path: str | os.PathLike, blueprint: Any = None) -> None:
        self.path = Path(path)
        self.rec = rec
        self.error: BaseException | None = None
        self._failure: OutputError | None = None
        self.bytes = 0
        self._closed = False
        self._ended = threading.Event()
        self._atomic = contextlib.ExitStack()
        tmp = self._atomic.enter_context(atomic_path(self.path))  # OutputError naming the file
        self._tmpdir: str | None = None
        self._fd: int | None = None
        self._stream = None
        self._thread: threading.Thread | None = None
        self._out = None
        try:
            self._out = open(tmp, "wb")  # noqa: SIM115 (closed by the copy thread or close())
            if hasattr(os, "mkfifo"):
                self._tmpdir = tempfile.mkdtemp(prefix="flatbody-rrd-")
                fifo = os.path.join(self._tmpdir, "sink.rrd")
                os.mkfifo(fifo, 0o600)
                # opened for reading first and without blocking, so that rerun's open for writing returns at once;
                # the copy runs before ``save``, which writes what was logged so far before it returns
                self._fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
                with contextlib.suppress(
                    OSError, AttributeError
                ):  # fewer hand-overs between rerun and the copy (Linux)
                    fcntl.fcntl(self._fd, fcntl.F_SETPIPE_SZ, PIPE_SIZE)
                self._thread = threading.Thread(target=self._copy, name=f"flatbody-rrd-{self.path.name}", daemon=True)
                self._thread.start()
                rec.save(fifo, default_blueprint=blueprint)
            else:  # platforms without FIFOs
                self._stream = rec.binary_stream()
                if blueprint is not None:
                    rec.send_blueprint(blueprint, make_active=False, make_default=True)
        except BaseException as exc:
            self._discard(exc)
            if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                raise OutputError(f"cannot write {str(self.path)!r}: {_reason(exc)}") from None
            raise
        # a program that ends without closing the recording still finishes it (rerun would otherwise
        # write into a pipe that nobody reads once this thread has stopped)
        self._at_exit = functools.partial(_abandon, weakref.ref(self))
        atexit.register(self._at_exit)

    # -- the copy thread ---------------------------------------------------------------------------
    def _copy(self) -> None:
        """Copy the pipe to the temporary file until rerun closes the pipe; after a failed write keep
        draining it (rerun must never block) and remember the failure. The thread owns the pipe's end."""
        try:
            self._copy_pipe(self._fd)
        finally:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None

    def _copy_pipe(self, fd: int) -> None:
        named = True
        poll = select.poll() if hasattr(select, "poll") else None
        if poll is not None:
            poll.register(fd, select.POLLIN)
        while True:
            try:
                data = os.read(fd, CHUNK)
            except BlockingIOError:  # rerun has the pipe open and nothing to say: wait for it
                if poll is not None:
                    poll.poll(100)
                else:  # pragma: no cover
                    select.select([fd], [], [], 0.1)
                continue
            except OSError as exc:  # pragma: no cover - reading a pipe does not fail
                self._fail(exc)
                return
            if not data:
                if self._ended.is_set():
                    break
                self._ended.wait(0.005)  # rerun has not opened the pipe yet, or has just closed it (close() sets it)
                continue
            if named and self._tmpdir is not None:
                named = False
                shutil.rmtree(self._tmpdir, ignore_errors=True)  # rerun has it open: the name is no longer needed
                self._tmpdir = None
            if self.error is None:
                try:
                    self._out.write(data)
                    self.bytes += len(data)
                except BaseException as exc:  # noqa: BLE001 - any failure here is the recording's failure
                    self._fail(exc)
        if self.error is None:
            try:
                self._out.close()
            except OSError as exc:
                self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        if self.error is None:
            self.error = exc
        with contextlib.suppress(OSError):
            if self._out is not None:
                self._out.close()

    # -- finishing ---------------------------------------------------------------------------------
    def check(self) -> None:
        """Raise :class:`OutputError` (and end the recording, removing its temporary file) if a write has
        failed; called after each block, so that a full disk stops a long run early."""
        if self.error is not None and not self._closed:
            self.close()

    def close(self) -> Path:
        """Finish rerun's stream (footer included), wait for the copy, rename the file into place.

        Raises
        ------
        OutputError
            A write failed (disk full, file-size limit, …), or the copy did not finish: one line naming
            the file; the temporary file is removed and the target left as it was.
        """
        if self._closed:
            if self._failure is not None:
                raise self._failure
            return self.path
        self._closed = True
        with contextlib.suppress(Exception):
            atexit.unregister(self._at_exit)
        try:
            try:
                self.rec.flush()
                self.rec.disconnect()
                if self._stream is not None:  # platforms without FIFOs
                    data = self._stream.read(flush=True)
                    try:
                        self._out.write(data or b"")
                        self.bytes += len(data or b"")
                        self._out.close()
                    except OSError as exc:
                        self._fail(exc)
            finally:
                self._ended.set()
                if self._thread is not None:
                    self._thread.join(FINISH_TIMEOUT_S)
                    if self._thread.is_alive() and self.error is None:
                        self.error = TimeoutError(
                            f"the copy of rerun's stream did not finish within {FINISH_TIMEOUT_S:g} s"
                        )
            if self.error is None and self.bytes == 0:
                self.error = OSError(errno.EIO, "rerun wrote nothing")
        except BaseException as exc:
            self._discard(exc)
            raise
        if self.error is not None:
            self._failure = OutputError(f"cannot write {str(self.path)!r}: {_reason(self.error)}")
            self._discard(self._failure)
            raise self._failure from None
        self._release()
        self._atomic.close()  # renames the temporary file over the target (OutputError on failure)
        return self.path

    def abandon(self) -> None:
        """End the recording without keeping its file: the program exits without having closed it (a run
        that did not finish leaves no file under the target's name)."""
        if self._closed:
            return
        self._closed = True
        try:
            with contextlib.suppress(Exception):
                self.rec.flush()
                self.rec.disconnect()
        finally:
            self._ended.set()
            if self._thread is not None:
                self._thread.join(FINISH_TIMEOUT_S)
            self._discard(OutputError(f"{str(self.path)!r}: the recording was not closed"))

    def _release(self) -> None:
        if self._fd is not None and self._thread is None:  # (a started copy thread closes it itself)
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None
        with contextlib.suppress(OSError):
            if self._out is not None and not self._out.closed and (self._thread is None or not self._thread.is_alive()):
                self._out.close()

    def _discard(self, exc: BaseException) -> None:
        """Remove the temporary file (``atomic_path`` on an error) and release the pipe."""
        self._closed = True
        self._ended.set()
        with contextlib.suppress(Exception):
            atexit.unregister(self._at_exit)
        self._release()
        with contextlib.suppress(BaseException):
            self._atomic.__exit__(type(exc), exc, exc.__traceback__)


def _abandon(ref: weakref.ref) -> None:
    sink = ref()
    if sink is not None:
        sink.abandon()


__all__ = ["CHUNK", "FINISH_TIMEOUT_S", "PIPE_SIZE", "FileSink"]
