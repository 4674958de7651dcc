"""The job store: one embedded SQLite database (``DATA_DIR/jobs.sqlite3``) and a folder per job.

=============  ========================================================================
column         meaning
=============  ========================================================================
id             32 hex digits (random)
kind           ``simulate``, ``family``, ``stability-map``, ``record``, ``evaluate``
params         the validated parameters (JSON)
status         ``queued`` → ``running`` → ``done`` | ``failed``
progress       0 … 1 (never decreases while the job runs)
stage          what the job is doing now (one short line, e.g. ``row 12 of 30``), or NULL
result         the answer (JSON), when done
error          one line, when failed
artifacts      file names in ``DATA_DIR/jobs/ID/`` (JSON list), the first is the main one
created, started, finished   Unix times
pid            the worker process running the job
client         the address of the client that queued it (for the per-client queue quota)
=============  ========================================================================

The service and its worker processes write to the same database (WAL mode, one connection per
process and thread). A worker finishes a job only while the row still says ``running`` under its
own pid, so a job that was marked failed (the service restarted) or deleted is never
overwritten. Results are kept until the job is deleted.

Quotas: :meth:`JobStore.create` counts the queued jobs (in all, and of the client) and the stored
jobs in the same transaction as the insert, and refuses with :class:`QueueFull` past the limits.
Results are stored as finite JSON text (NaN/inf as null) and spliced into answers without being
parsed again (:meth:`JobStore.get_json`); :meth:`JobStore.list_json` answers a page of jobs without
results, at most ``max_bytes`` long, and the cursor of the next page. A database that is missing,
corrupt or on a full disk raises ``sqlite3.Error`` or ``OSError``: the service answers 503.
"""

from __future__ import annotations

import json
import secrets
import shutil
import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any
from urllib.parse import quote

STATUSES = ("queued", "running", "done", "failed")

RESTART_REASON = "the service stopped while this job was running; it was not re-run (submit it again)"
"""The error of a job found ``running`` when the service starts."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    params TEXT NOT NULL,
    status TEXT NOT NULL,
    progress REAL NOT NULL DEFAULT 0,
    result TEXT,
    error TEXT,
    artifacts TEXT NOT NULL DEFAULT '[]',
    created REAL NOT NULL,
    started REAL,
    finished REAL,
    pid INTEGER,
    stage TEXT,
    client TEXT
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status, created);
"""
_MIGRATIONS = (
    ("stage", "ALTER TABLE jobs ADD COLUMN stage TEXT"),
    ("client", "ALTER TABLE jobs ADD COLUMN client TEXT"),
)

_PUBLIC = "id, kind, params, status, progress, error, artifacts, created, started, finished, stage"
"""The columns of a job as GET /jobs lists it (no result, no pid, no client)."""


class QueueFull(Exception):
    """A job refused by a quota (HTTP 429); ``field`` names the quota, ``retry`` whether waiting helps."""

    def __init__(self, message: str, *, retry: bool = True) -> None:
        super().__init__(message)
        self.retry = retry


class MissingDatabase(sqlite3.OperationalError):
    """The job database file is gone from the data dir (the service answers 503)."""


"""Columns added since the first schema: a data dir written by an older service gets them on start."""


class JobStore:
    """Jobs in SQLite under ``data_dir`` (see the module table).

    Parameters
    ----------
    data_dir : str or Path
        Created if missing; holds ``jobs.sqlite3`` and ``jobs/ID/`` folders.
    create : bool
        Create the database (and bring its schema up to date) if needed: the service does, once at
        start; a job's worker process opens the service's database and never makes a new one (a
        database deleted under a running service stays missing: :class:`MissingDatabase`).
    """

    def __init__(self, data_dir: str | Path, *, create: bool = True) -> None:
        self.data_dir = Path(data_dir)
        self.db_path = self.data_dir / "jobs.sqlite3"
        self._created = not create
        if not create:
            return
        self.data_dir.mkdir(parents=True, exist_ok=True)
        with self.connect() as db:
            db.executescript(_SCHEMA)
            have = {row[1] for row in db.execute("PRAGMA table_info(jobs)")}
            for column, statement in _MIGRATIONS:
                if column not in have:
                    db.execute(statement)
        self._created = True

    @contextmanager
    def connect(self) -> Iterator[sqlite3.Connection]:
        """A short-lived connection (a transaction committed on exit)."""
        missing = MissingDatabase(f"the job database {self.db_path} is missing")
        if self._created and not self.db_path.exists():  # deleted under the service: never a new, empty database
            raise missing
        try:  # once created, opened read-write only: SQLite must not make a new file in its place
            db = sqlite3.connect(
                f"file:{quote(str(self.db_path.resolve()))}?mode=rw" if self._created else self.db_path,
                timeout=30.0,
                isolation_level=None,
                uri=self._created,
            )
        except sqlite3.OperationalError:
            if self._created and not self.db_path.exists():
                raise missing from None
            raise
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA busy_timeout=30000")
            db.row_factory = sqlite3.Row
            yield db
        finally:
            db.close()

    def lock(self) -> None:
        """Hold the data dir for this process (one service per data dir), until :meth:`unlock`.

        Raises
        ------
        ValueError
            ``data-dir: ... is in use by another flatbody serve``.
        """
        import fcntl

        fh = open(self.data_dir / "service.lock", "a+", encoding="utf-8")  # noqa: SIM115 - held until unlock()
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            raise ValueError(
                f"data-dir: {self.data_dir} is in use by another flatbody serve (one service per data dir)"
            ) from None
        self._lock_file = fh

    def unlock(self) -> None:
        fh = getattr(self, "_lock_file", None)
        if fh is not None:
            fh.close()
            self._lock_file = None

    def job_dir(self, job_id: str) -> Path:
        """``DATA_DIR/jobs/ID`` (the job's artifacts)."""
        return self.data_dir / "jobs" / job_id

    # -- the service's side ------------------------------------------------------------------
    def create(
        self,
        kind: str,
        params: dict[str, Any],
        *,
        client: str | None = None,
        max_queued: int | None = None,
        max_queued_per_client: int | None = None,
        max_stored: int | None = None,
    ) -> str:
        """A new queued job; its id.

        Raises
        ------
        QueueFull
            More than ``max_queued`` jobs queued, ``max_queued_per_client`` of them from ``client``, or
            ``max_stored`` jobs kept (counted in the transaction that inserts the job).
        """
        job_id = secrets.token_hex(16)
        text = json.dumps(params, allow_nan=False)
        with self.connect() as db:
            db.execute("BEGIN IMMEDIATE")
            try:
                if max_queued is not None:
                    queued = db.execute("SELECT COUNT(*) FROM jobs WHERE status = 'queued'").fetchone()[0]
                    if queued >= max_queued:
                        raise QueueFull(
                            f"jobs: the queue is full ({queued} jobs waiting, at most {max_queued}); try again later"
                        )
                if max_queued_per_client is not None:
                    mine = db.execute(
                        "SELECT COUNT(*) FROM jobs WHERE status = 'queued' AND client IS ?", (client,)
                    ).fetchone()[0]
                    if mine >= max_queued_per_client:
                        raise QueueFull(
                            f"jobs: you have {mine} jobs waiting (at most {max_queued_per_client} per client); "
                            "try again when some have started"
                        )
                if max_stored is not None:
                    stored = db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
                    if stored >= max_stored:
                        raise QueueFull(
                            f"jobs: the service keeps at most {max_stored} jobs; delete finished ones "
                            "(DELETE /jobs/{{id}}) first",
                            retry=False,
                        )
                db.execute(
                    "INSERT INTO jobs (id, kind, params, status, created, client) VALUES (?, ?, ?, 'queued', ?, ?)",
                    (job_id, kind, text, time.time(), client),
                )
            except BaseException:
                db.execute("ROLLBACK")
                raise
            db.execute("COMMIT")
        return job_id

    def get(self, job_id: str) -> dict[str, Any] | None:
        """The job as the API shows it, or None."""
        with self.connect() as db:
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else _as_dict(row)

    def list(self, limit: int = 100) -> list[dict[str, Any]]:
        """The newest jobs first, without their results."""
        with self.connect() as db:
            rows = db.execute(
                f"SELECT {_PUBLIC}, NULL AS result FROM jobs ORDER BY created DESC, id DESC LIMIT ?", (limit,)
            ).fetchall()
        return [_as_dict(r, with_result=False) for r in rows]

    def get_json(self, job_id: str) -> bytes | None:
        """The job as ``GET /jobs/{id}`` answers it (JSON bytes, the stored result spliced in unparsed), or None."""
        with self.connect() as db:
            row = db.execute(f"SELECT {_PUBLIC}, result FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None:
            return None
        public = _as_dict(row, with_result=False)
        del public["result"]
        head = json.dumps(public, allow_nan=False)
        return (head[:-1] + ', "result": ' + _finite_text(row["result"]) + "}").encode("utf-8")

    def list_json(self, limit: int, *, before: str | None = None, max_bytes: int) -> bytes:
        """A page of ``GET /jobs``: ``{"jobs": [...], "next"}``, newest first, without results, at most ``max_bytes``
        long (at least one job); ``next`` is the ``before`` cursor of the next page, or null.

        ``before`` is the ``next`` of a previous page (``created:id``); the page starts after that job.
        """
        where, args = "", []
        if before:
            created, _, last_id = before.partition(":")
            where, args = "WHERE created < ? OR (created = ? AND id < ?)", [float(created), float(created), last_id]
        parts: list[str] = []
        size = 32
        next_cursor = None
        last = None  # the last job put on the page (the cursor of the next one)
        with self.connect() as db:
            cur = db.execute(
                f"SELECT {_PUBLIC}, NULL AS result FROM jobs {where} ORDER BY created DESC, id DESC LIMIT ?",
                (*args, limit + 1),
            )
            for row in cur:
                if len(parts) == limit:
                    next_cursor = _cursor(last)
                    break
                text = json.dumps(_as_dict(row, with_result=False), allow_nan=False)
                if parts and size + len(text) + 2 > max_bytes:
                    next_cursor = _cursor(last)
                    break
                parts.append(text)
                size += len(text) + 2
                last = row
        return ('{"jobs": [' + ", ".join(parts) + '], "next": ' + json.dumps(next_cursor) + "}").encode("utf-8")

    def fail_interrupted(self) -> int:
        """Mark the jobs left ``running`` by a previous service process failed (:data:`RESTART_REASON`)."""
        with self.connect() as db:
            cur = db.execute(
                "UPDATE jobs SET status = 'failed', error = ?, finished = ?, pid = NULL WHERE status = 'running'",
                (RESTART_REASON, time.time()),
            )
            return cur.rowcount

    def claim_next(self) -> dict[str, Any] | None:
        """Move the oldest queued job to ``running`` and return it (None when the queue is empty)."""
        with self.connect() as db:
            db.execute("BEGIN IMMEDIATE")
            row = db.execute("SELECT * FROM jobs WHERE status = 'queued' ORDER BY created LIMIT 1").fetchone()
            if row is None:
                db.execute("COMMIT")
                return None
            db.execute(
                "UPDATE jobs SET status = 'running', started = ?, progress = 0 WHERE id = ?", (time.time(), row["id"])
            )
            db.execute("COMMIT")
        return _as_dict(row)

    def set_pid(self, job_id: str, pid: int) -> None:
        with self.connect() as db:
            db.execute("UPDATE jobs SET pid = ? WHERE id = ? AND status = 'running'", (pid, job_id))

    def fail(self, job_id: str, error: str, *, only_running: bool = True) -> bool:
        """Mark a job failed with one line ``error``; False if it was not running (or not there)."""
        cond = " AND status = 'running'" if only_running else " AND status IN ('queued', 'running')"
        with self.connect() as db:
            cur = db.execute(
                f"UPDATE jobs SET status = 'failed', error = ?, finished = ?, pid = NULL WHERE id = ?{cond}",
                (error, time.time(), job_id),
            )
            return cur.rowcount == 1

    def delete(self, job_id: str) -> bool:
        """Remove the job and its folder; False if there was no such job."""
        with self.connect() as db:
            cur = db.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
        return cur.rowcount == 1

    # -- the worker's side -------------------------------------------------------------------
    def progress(self, job_id: str, pid: int, fraction: float, stage: str | None = None) -> bool:
        """Record progress (never lower than the job's last one) and, when given, what the job is doing;
        False when the job is no longer this worker's (deleted or failed)."""
        with self.connect() as db:
            cur = db.execute(
                "UPDATE jobs SET progress = MAX(progress, ?), stage = COALESCE(?, stage) "
                "WHERE id = ? AND status = 'running' AND pid = ?",
                (min(max(float(fraction), 0.0), 1.0), None if stage is None else str(stage)[:200], job_id, pid),
            )
            return cur.rowcount == 1

    def finish(
        self, job_id: str, pid: int, *, result: Any = None, artifacts: list[str] | None = None, error: str | None = None
    ) -> bool:
        """Mark the job done (``result``) or failed (``error``) if it is still this worker's."""
        now = time.time()
        with self.connect() as db:
            if error is None:
                cur = db.execute(
                    "UPDATE jobs SET status = 'done', progress = 1, result = ?, artifacts = ?, finished = ?, pid = NULL "
                    "WHERE id = ? AND status = 'running' AND pid = ?",
                    (finite_json(result), json.dumps(artifacts or []), now, job_id, pid),
                )
            else:
                cur = db.execute(
                    "UPDATE jobs SET status = 'failed', error = ?, finished = ?, pid = NULL WHERE id = ? AND status = 'running' AND pid = ?",
                    (error, now, job_id, pid),
                )
            return cur.rowcount == 1


def finite_json(value: Any) -> str:
    """``value`` as JSON text, with NaN and ±inf (never valid JSON) as null."""
    try:
        return json.dumps(value, allow_nan=False)
    except ValueError:
        return json.dumps(_finite(value), allow_nan=False)


def _finite(value: Any) -> Any:
    import math

    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def _finite_text(text: str | None) -> str:
    """A stored result as finite JSON text (a row written by an older service may hold NaN/Infinity)."""
    if text is None:
        return "null"
    if "NaN" in text or "Infinity" in text:
        return finite_json(json.loads(text))
    return text


def _cursor(row: sqlite3.Row) -> str:
    return f"{row['created']!r}:{row['id']}"


def _as_dict(row: sqlite3.Row, *, with_result: bool = True) -> dict[str, Any]:
    keys = row.keys()
    return {
        "id": row["id"],
        "kind": row["kind"],
        "status": row["status"],
        "progress": float(row["progress"]),
        "params": json.loads(row["params"]),
        "result": json.loads(row["result"]) if with_result and row["result"] is not None else None,
        "error": row["error"],
        "artifacts": json.loads(row["artifacts"]),
        "created": row["created"],
        "started": row["started"],
        "finished": row["finished"],
        **({"pid": row["pid"]} if "pid" in keys else {}),
        "stage": row["stage"],
        **_timing(row),
    }


def _timing(row: sqlite3.Row) -> dict[str, float | None]:
    """``elapsed``: seconds since the job started (to its end when it has ended); ``remaining``: while it
    runs, the seconds left at its mean rate so far (elapsed · (1 − progress) / progress), once it has
    reported some progress."""
    started, finished, progress = row["started"], row["finished"], float(row["progress"])
    if started is None:
        return {"elapsed": None, "remaining": None}
    elapsed = max(0.0, (finished if finished is not None else time.time()) - started)
    remaining = None
    if row["status"] == "running" and 0.05 <= progress < 1.0:
        remaining = elapsed * (1.0 - progress) / progress
    return {"elapsed": elapsed, "remaining": remaining}


__all__ = ["JobStore", "MissingDatabase", "QueueFull", "RESTART_REASON", "STATUSES", "finite_json"]
