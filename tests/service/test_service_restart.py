"""The real service (uvicorn in a subprocess on loopback) killed mid-job and started again."""

from __future__ import annotations

import os
import signal
import sqlite3
import time

import httpx

from flatbody_env.service.launch import start_service
from flatbody_env.service.store import RESTART_REASON
from service.conftest import wait_job


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie has exited
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_killed_service_reports_the_running_job_failed_and_keeps_finished_results(live_service):
    proc, url, data_dir = live_service
    http = httpx.Client(base_url=url, timeout=60)
    finished = wait_job(
        http.get, http.post("/jobs", json={"kind": "stability-map", "params": {"grid": 5}}).json()["id"]
    )
    assert finished["status"] == "done"
    long_params = {"scene": "long-horizon", "t_end": 10000.0, "samples": 20001, "rtol": 1e-13, "atol": 1e-13}
    long_id = http.post("/jobs", json={"kind": "simulate", "params": long_params}).json()["id"]
    deadline = time.monotonic() + 60
    while http.get(f"/jobs/{long_id}").json()["status"] != "running" and time.monotonic() < deadline:
        time.sleep(0.1)
    assert http.get(f"/jobs/{long_id}").json()["status"] == "running"
    worker_pid = None
    while worker_pid is None and time.monotonic() < deadline:  # the worker's pid is stored once its process started
        with sqlite3.connect(data_dir / "jobs.sqlite3") as db:
            (worker_pid,) = db.execute("SELECT pid FROM jobs WHERE id = ?", (long_id,)).fetchone()
        time.sleep(0.05)
    assert worker_pid and _alive(worker_pid)

    proc.send_signal(signal.SIGKILL)  # the service dies without any chance to clean up
    proc.wait(timeout=30)
    deadline = time.monotonic() + 30
    while _alive(worker_pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(worker_pid), "the job's worker process outlived the service"

    proc2, url2 = start_service(data_dir, workers=1)
    try:
        http2 = httpx.Client(base_url=url2, timeout=60)
        job = http2.get(f"/jobs/{long_id}").json()
        assert job["status"] == "failed" and job["error"] == RESTART_REASON
        time.sleep(1.0)  # the restarted runner must not pick it up again
        assert http2.get(f"/jobs/{long_id}").json()["status"] == "failed"
        kept = http2.get(f"/jobs/{finished['id']}").json()
        assert kept["status"] == "done" and kept["result"] == finished["result"]
        png = http2.get(f"/jobs/{finished['id']}/artifact")
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
    finally:
        proc2.terminate()
        proc2.wait(timeout=30)
