"""Ctrl-C on ``flatbody serve`` while a job runs: the service stops its workers and jobs, no worker
prints a traceback, the last line says so, exit code 130, no process left behind."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from processes import interrupt, sigint_default

psutil = pytest.importorskip("psutil")
httpx = pytest.importorskip("httpx")

ROOT = Path(__file__).resolve().parents[2]


def test_ctrl_c_stops_the_service_and_its_workers_quietly(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    # its own session, so that the signal can go to the whole process group, as a terminal's Ctrl-C does
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "flatbody_env.cli",
            "serve",
            "--port",
            str(port),
            "--workers",
            "2",
            "--data-dir",
            str(tmp_path / "data"),
            "--log-level",
            "warning",
        ],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=sigint_default,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 90
        while True:
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "the service did not answer /health in time"
            try:
                if httpx.get(url + "/health", timeout=1.0).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        job = httpx.post(url + "/jobs", json={"kind": "stability-map", "params": {"grid": 60}}, timeout=30).json()["id"]
        while httpx.get(f"{url}/jobs/{job}", timeout=10).json()["status"] != "running":
            assert time.monotonic() < deadline, "the job did not start in time"
            time.sleep(0.1)
        children = psutil.Process(proc.pid).children(recursive=True)
        assert len(children) >= 3  # the forkserver, the request workers, the job's process
    finally:
        _, stderr = interrupt(proc)
    assert proc.returncode == 130, stderr[-3000:]
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr[-3000:]
    assert stderr.strip().splitlines()[-1] == "flatbody serve: interrupted"
    _, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, [p.cmdline()[:4] for p in alive]
