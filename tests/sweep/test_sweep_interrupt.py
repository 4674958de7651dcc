"""Ctrl-C on ``flatbody sweep``: one line, exit code 130, no worker process left behind, the
finished rows kept, and ``--resume`` runs only the rest."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from processes import interrupt, sigint_default

psutil = pytest.importorskip("psutil")

ROOT = Path(__file__).resolve().parents[2]
MAP = ["--grid", "40", "--chunk", "1"]


def _env() -> dict[str, str]:
    # no progress line however long the sweep takes on a busy machine (the default interval is 10 s)
    env = {**os.environ, "FLATBODY_PROGRESS_S": "3600"}
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return env


def _rows(db_path: Path) -> dict[str, str]:
    if not db_path.exists():
        return {}
    try:
        with sqlite3.connect(db_path, timeout=5) as db:
            return dict(db.execute("SELECT key, finished_utc FROM rows"))
    except sqlite3.OperationalError:  # the table is not created yet
        return {}


@pytest.mark.slow  # long: a real sweep interrupted and resumed; resume after a kill is in the default run (test_sweep_cli)
def test_ctrl_c_ends_a_sweep_in_one_line_and_resume_continues(tmp_path):
    out = tmp_path / "map"
    db_path = out / "results.sqlite"
    # its own session, so that the signal can go to the whole process group, as a terminal's Ctrl-C does
    proc = subprocess.Popen(
        [sys.executable, "-m", "flatbody_env.cli", "sweep", "stability-map", *MAP, "--out", str(out), "--workers", "2"],
        cwd=ROOT,
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=sigint_default,
    )
    try:
        deadline = time.monotonic() + 120
        while len(_rows(db_path)) < 2:
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "the sweep stored no rows in time"
            time.sleep(0.02)
        children = psutil.Process(proc.pid).children(recursive=True)
        assert len(children) >= 2  # the two Dask worker processes (and multiprocessing's resource tracker)
    finally:
        stdout, stderr = interrupt(proc)
    assert proc.returncode == 130, stderr[-3000:]
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) <= 2, stderr[-3000:]
    assert stderr.strip().splitlines()[-1] == "flatbody sweep: interrupted"
    _, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, [p.cmdline()[:3] for p in alive]
    before = _rows(db_path)
    assert 2 <= len(before) < 40
    resumed = subprocess.run(
        [
            sys.executable,
            "-m",
            "flatbody_env.cli",
            "sweep",
            "stability-map",
            *MAP,
            "--out",
            str(out),
            "--workers",
            "0",
            "--resume",
        ],
        cwd=ROOT,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert f"({40 - len(before)} run now)" in resumed.stdout
    after = _rows(db_path)
    assert len(after) == 40 and all(after[k] == v for k, v in before.items())  # the kept rows were not run again
