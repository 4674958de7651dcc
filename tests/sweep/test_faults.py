"""Fault tests of ``flatbody sweep`` and ``flatbody tune``: a corrupt, foreign or directory database,
a full disk (``RLIMIT_FSIZE`` in a subprocess stands in for it) and a worker killed with SIGKILL.
Each ends in one line and exit 1 or 2, and keeps what was there before (docs/reliability.md)."""

from __future__ import annotations

import json
import os
import resource
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

FLATBODY = [sys.executable, "-m", "flatbody_env.cli"]
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}
SMALL = str(Path(__file__).with_name("ppo_search_small.yml"))
MAP = ["sweep", "stability-map", "--grid", "6", "--workers", "0", "--no-progress"]


def _run(args, *, fsize=None, timeout=120):
    pre = None
    if fsize is not None:

        def pre():
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    return subprocess.run(
        [*FLATBODY, *args], check=False, capture_output=True, text=True, timeout=timeout, env=ENV, preexec_fn=pre
    )


def _one_line(r, codes):
    assert r.returncode in codes, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1, r.stderr
    return lines[0]


def _bad_store(kind: str, path: Path) -> bytes | None:
    if kind == "directory":
        path.mkdir()
        return None
    if kind == "corrupt":
        path.write_bytes(b"SQLite format 3\x00" + os.urandom(3000))
    elif kind == "garbage":
        path.write_bytes(b"not a database at all\n" * 50)
    else:  # foreign: another program's intact database
        db = sqlite3.connect(path)
        db.execute("CREATE TABLE accounts (id INTEGER, owner TEXT)")
        db.commit()
        db.close()
    return path.read_bytes()


@pytest.mark.parametrize("kind", ["directory", "corrupt", "garbage", "foreign"])
def test_sweep_refuses_a_bad_results_database_and_keeps_it(tmp_path, kind):
    out = tmp_path / "sweep"
    out.mkdir()
    before = _bad_store(kind, out / "results.sqlite")
    line = _one_line(_run([*MAP, "--out", str(out)]), {2})
    assert "out:" in line and "results.sqlite" in line
    if before is not None:
        assert (out / "results.sqlite").read_bytes() == before


@pytest.mark.parametrize("kind", ["directory", "corrupt", "foreign"])
def test_tune_refuses_a_bad_sqlite_storage(tmp_path, kind):
    db = tmp_path / "optuna.sqlite3"
    before = _bad_store(kind, db)
    r = _run(
        [
            "tune",
            "--algo",
            "ppo",
            "--trials",
            "1",
            "--storage",
            f"sqlite:///{db}",
            "--out",
            str(tmp_path / "t"),
            "--workers",
            "1",
        ]
    )
    assert "storage" in _one_line(r, {2})
    if before is not None:
        assert db.read_bytes() == before


def test_sweep_on_a_full_disk_is_one_line_and_keeps_the_stored_rows(tmp_path):
    out = tmp_path / "sweep"
    r = _run(
        [*MAP[:2], "--grid", "40", "--chunk", "1", "--workers", "0", "--no-progress", "--out", str(out)], fsize=40_000
    )
    line = _one_line(r, {1})
    assert "I/O error" in line
    db = sqlite3.connect(out / "results.sqlite")
    (n,) = db.execute("SELECT COUNT(*) FROM rows").fetchone()  # still a readable database
    db.close()
    assert n >= 0


def test_record_refuses_up_front_what_the_disk_cannot_hold(tmp_path):
    target = tmp_path / "run.rrd"
    r = _run(["record", "--scene", "default", "--t-end", "5", "--out", str(target)], fsize=20_000, timeout=60)
    assert "file-size limit" in _one_line(r, {1})
    assert not target.exists() and not list(tmp_path.iterdir())


def test_record_on_a_disk_that_fills_mid_run_is_one_line(tmp_path):
    """The disk fills during the recording (RLIMIT_FSIZE stands in for it, the up-front space check
    switched off): one line naming the file and the limit, exit 1, no hang (rerun never writes the file
    itself: flatbody_env.recording.sink), the file already under that name kept, no temporary file left."""
    target = tmp_path / "run.rrd"
    target.write_bytes(b"the previous recording")
    code = (
        "import resource, sys; from flatbody_env.cli import record; record.check_space = lambda *a, **k: None; "
        "resource.setrlimit(resource.RLIMIT_FSIZE, (20000, 20000)); from flatbody_env.cli.main import main; "
        f"sys.exit(main(['record', '--scene', 'default', '--t-end', '5', '--out', {str(target)!r}]))"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=60, env=ENV
    )  # hang guard
    line = _one_line(r, {1})
    assert str(target) in line and "file-size limit" in line, line
    assert target.read_bytes() == b"the previous recording"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.rrd"]


@pytest.mark.slow
def test_killed_tune_worker_trial_is_marked_failed_by_the_heartbeat(tmp_path):
    """SIGKILL a worker mid-trial: Optuna's heartbeat (database storage) marks its trial FAIL, and the
    failed_trial_callback says so; nothing stays RUNNING."""
    pytest.importorskip("optuna")
    db = tmp_path / "optuna.sqlite3"
    env = {**ENV, "FLATBODY_TUNE_HEARTBEAT": "1"}
    args = [
        *FLATBODY,
        "tune",
        "--algo",
        "ppo",
        "--trials",
        "1",
        "--n-timesteps",
        "200000",
        "--n-envs",
        "2",
        "--evaluations",
        "2",
        "--eval-episodes",
        "2",
        "--search-file",
        SMALL,
        "--hyperparams",
        "n_steps=64",
        "batch_size=64",
        "--storage",
        f"sqlite:///{db}",
        "--study",
        "k",
        "--out",
        str(tmp_path / "t"),
        "--workers",
        "1",
    ]
    proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        running = False
        while time.monotonic() < deadline and not running:
            time.sleep(0.5)
            if db.exists():
                try:
                    s = sqlite3.connect(db)
                    running = bool(s.execute("SELECT COUNT(*) FROM trials WHERE state = 'RUNNING'").fetchone()[0])
                    s.close()
                except sqlite3.Error:
                    pass
        assert running, "the worker never started a trial"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    time.sleep(3.5)  # > grace period (3 heartbeats of 1 s)
    code = (
        "import json, sys; from agents.tune import summary; "
        f"print(json.dumps([t['state'] for t in summary('k', {f'sqlite:///{db}'!r})['trials']]))"
    )
    r = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0, r.stderr[-2000:]
    states = json.loads(r.stdout.strip().splitlines()[-1])
    assert states == ["FAIL"], states
    assert "marked FAIL" in r.stderr
