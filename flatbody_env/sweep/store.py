"""The result store of a sweep: one SQLite file, one row per task key.

Why SQLite (and not Parquet): a sweep appends results one task at a time while it runs and may be
killed at any moment. SQLite ships with Python (no new dependency), commits each row atomically
(``INSERT ... ON CONFLICT(key) DO UPDATE``: an upsert by key), survives a ``SIGKILL`` between two
commits with every committed row intact (its journal rolls back the half-written one), and can
answer "which keys are done?" without reading the payloads. Parquet files are immutable: appending
row by row means one file per row or rewriting the file, and a kill during a rewrite loses it.

Layout of ``DIR/results.sqlite``:

================ ===========================================================================
table ``sweep``  one row: ``spec`` (JSON of the sweep's kind and parameters, checked on resume)
table ``rows``   ``key`` (primary key), ``status`` (``ok`` | ``error``), ``payload`` (JSON of
                 the task's rows), ``error`` (one line), ``seconds`` (the task's own run time),
                 ``worker``, ``finished_utc``
================ ===========================================================================

Only the process that drives the sweep writes; workers return their results to it.
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

STORE_NAME = "results.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS sweep (id INTEGER PRIMARY KEY CHECK (id = 1), spec TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS rows (
    key TEXT PRIMARY KEY,
    status TEXT NOT NULL CHECK (status IN ('ok', 'error')),
    payload TEXT,
    error TEXT,
    seconds REAL,
    worker TEXT,
    finished_utc TEXT
);
"""


@dataclass(frozen=True, kw_only=True)
class StoredResult:
    """One task's stored outcome.

    Attributes
    ----------
    key : str
        The task key (sort order of the sweep's output).
    status : str
        ``"ok"`` or ``"error"``.
    payload : Any
        The task's result (JSON-decoded; ``None`` for a failed task).
    error : str or None
        One line: the exception type and message of a failed task.
    seconds : float
        The task's run time on its worker.
    worker : str
        Where it ran (a Dask worker address or ``"local"``).
    """

    key: str
    status: str
    payload: Any
    error: str | None
    seconds: float
    worker: str


class ResultStore:
    """Results of one sweep, keyed by task key, in ``DIR/results.sqlite``.

    Parameters
    ----------
    folder : str or Path
        The sweep's output folder (created if missing).
    """

    def __init__(self, folder: str | Path) -> None:
        from flatbody_env.physics import validation

        self.folder = Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise ValueError(f"out: {str(self.folder)!r} exists and is not a directory")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.path = self.folder / STORE_NAME
        # a directory, corrupt or foreign file in its place is refused before anything is written to it
        validation.sqlite_file("out", self.path, ("sweep", "rows"))
        try:
            self._db = sqlite3.connect(self.path, timeout=30.0)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
            self._db.commit()
        except sqlite3.Error as exc:
            raise store_error(self.path, exc) from None

    # -- the sweep's specification --------------------------------------------------------
    def spec(self) -> dict[str, Any] | None:
        """The stored sweep specification, or ``None`` for a new store."""
        row = self._db.execute("SELECT spec FROM sweep WHERE id = 1").fetchone()
        if row is None:
            return None
        try:
            spec = json.loads(row[0])
        except (TypeError, ValueError):
            spec = None
        if not isinstance(spec, dict):
            raise ValueError(
                f"out: {str(self.path)!r} holds a damaged sweep specification; move it away or choose another folder"
            )
        return spec

    def begin(self, spec: dict[str, Any], *, resume: bool, extends=None) -> None:
        """Record ``spec`` for a new sweep, or check it against the stored one on resume.

        Parameters
        ----------
        spec : dict
            The sweep's specification.
        resume : bool
            Continue the stored sweep.
        extends : callable, optional
            ``extends(stored, spec)``: whether ``spec`` only adds keys to the stored sweep without changing any
            stored key's meaning (a benchmark given one more algorithm). Such a ``spec`` replaces the stored one on
            resume; the rows already stored stay.

        Raises
        ------
        ValueError
            ``out`` already holds a sweep and ``resume`` is false; or ``resume`` with a different
            specification (resuming would mix two sweeps); or ``resume`` with no sweep stored.
        """
        stored = self.spec()
        text = json.dumps(spec, sort_keys=True)
        if stored is None:
            if resume:
                raise ValueError(f"resume: no sweep in {self.folder} to resume (start it without --resume)")
            self._db.execute("INSERT INTO sweep (id, spec) VALUES (1, ?)", (text,))
            self._db.commit()
            return
        if not resume:
            raise ValueError(
                f"out: {self.folder} already holds a sweep; pass --resume to continue it or choose another folder"
            )
        if json.dumps(stored, sort_keys=True) != text:
            if extends is not None and extends(stored, spec):
                self._db.execute("UPDATE sweep SET spec = ? WHERE id = 1", (text,))
                self._db.commit()
                return
            diff = sorted(k for k in set(stored) | set(spec) if stored.get(k) != spec.get(k))
            raise ValueError(
                f"resume: the sweep in {self.folder} was started with other parameters ({', '.join(diff)} differ)"
            )

    # -- rows ---------------------------------------------------------------------------------
    def put(
        self, key: str, *, payload: Any = None, error: str | None = None, seconds: float = 0.0, worker: str = "local"
    ) -> None:
        """Upsert the outcome of task ``key`` (one atomic commit): ok when ``error`` is None."""
        status = "ok" if error is None else "error"
        try:
            self._put(key, status, payload, error, seconds, worker)
        except sqlite3.Error as exc:  # disk full, I/O error: one line, exit 1; committed rows stay
            raise store_error(self.path, exc) from None

    def _put(self, key, status, payload, error, seconds, worker) -> None:
        self._db.execute(
            "INSERT INTO rows (key, status, payload, error, seconds, worker, finished_utc) VALUES (?, ?, ?, ?, ?, ?, ?) "
            "ON CONFLICT(key) DO UPDATE SET status = excluded.status, payload = excluded.payload, error = excluded.error, "
            "seconds = excluded.seconds, worker = excluded.worker, finished_utc = excluded.finished_utc",
            (
                key,
                status,
                None if error is not None else json.dumps(payload),
                error,
                float(seconds),
                worker,
                time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            ),
        )
        self._db.commit()

    def done_keys(self, *, include_errors: bool = False) -> set[str]:
        """Keys with a stored result (failed ones too when ``include_errors``); a resumed sweep
        runs the others, so a failed task is retried unless asked otherwise."""
        q = "SELECT key FROM rows" + ("" if include_errors else " WHERE status = 'ok'")
        return {k for (k,) in self._db.execute(q)}

    def forget(self, keys) -> int:
        """Remove the rows of ``keys`` (a resumed sweep runs those tasks again); returns how many were stored."""
        keys = list(keys)
        before = self._db.total_changes
        self._db.executemany("DELETE FROM rows WHERE key = ?", [(k,) for k in keys])
        self._db.commit()
        return self._db.total_changes - before

    def results(self) -> list[StoredResult]:
        """All stored outcomes, sorted by key."""
        cur = self._db.execute("SELECT key, status, payload, error, seconds, worker FROM rows ORDER BY key")
        return [
            StoredResult(
                key=k,
                status=s,
                payload=None if p is None else json.loads(p),
                error=e,
                seconds=float(t or 0.0),
                worker=w or "",
            )
            for k, s, p, e, t, w in cur
        ]

    def count(self) -> int:
        return int(self._db.execute("SELECT COUNT(*) FROM rows").fetchone()[0])

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def store_error(path: Path, exc: BaseException) -> OSError:
    """An SQLite failure as one-line ``OSError`` (the CLI's exit 1): disk full, I/O error, locked."""
    import errno

    text = " ".join(str(exc).split()) or type(exc).__name__
    code = errno.ENOSPC if "full" in text else errno.EIO
    return OSError(code, f"results database: {text} (the rows stored so far are kept; --resume continues)", str(path))


__all__ = ["STORE_NAME", "ResultStore", "StoredResult", "store_error"]
