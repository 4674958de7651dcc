"""Server faults over real HTTP: a missing or corrupt job database and a full disk answer 503 with one
line (never 422 "validation", never 500), /health stays up, and a job that fails to write its file
leaves no half-written file behind."""

from __future__ import annotations

import resource
import subprocess
import sys
import time

import httpx
import pytest

from flatbody_env.service.launch import start_service, stop_service


def _is_fault(r: httpx.Response) -> None:
    assert r.status_code == 503, (r.status_code, r.text[:300])
    data = r.json()
    assert data["kind"] == "unavailable" and "\n" not in data["detail"] and "Traceback" not in data["detail"], data


@pytest.mark.parametrize("damage", ["delete", "corrupt"])
def test_missing_or_corrupt_database_is_503(tmp_path, damage):
    data = tmp_path / "data"
    proc, url = start_service(data, workers=1)
    try:
        with httpx.Client(base_url=url, timeout=60) as http:
            job = http.post("/jobs", json={"kind": "stability-map", "params": {"grid": 4}}).json()["id"]
            for name in ("jobs.sqlite3", "jobs.sqlite3-wal", "jobs.sqlite3-shm"):
                path = data / name
                if damage == "delete":
                    path.unlink(missing_ok=True)
                elif path.exists() and name == "jobs.sqlite3":
                    path.write_bytes(b"this is not a database\n" * 512)
                else:
                    path.unlink(missing_ok=True)
            _is_fault(http.get("/jobs"))
            _is_fault(http.get(f"/jobs/{job}"))
            _is_fault(http.delete(f"/jobs/{job}"))
            _is_fault(http.post("/jobs", json={"kind": "stability-map", "params": {"grid": 4}}))
            assert http.get("/health").status_code == 200
            assert (
                http.post(
                    "/ellipses",
                    json={
                        "body": {"params": {"J": 1, "J3": 1}, "potential": {"name": "V1", "k": 1}},
                        "s3": 2,
                        "p_theta": 0.5,
                    },
                ).status_code
                == 200
            )
    finally:
        stop_service(proc)
    if damage == "corrupt":  # a service started on a corrupt database refuses with one line
        run = subprocess.run(
            [sys.executable, "-m", "flatbody_env.cli", "serve", "--port", "0", "--data-dir", str(data)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert run.returncode != 0 and "Traceback" not in run.stderr, run.stderr[-800:]
        assert "jobs.sqlite3" in run.stderr and len(run.stderr.strip().splitlines()) <= 3, run.stderr[-800:]


def _limit_files(size: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))

    return apply


def test_full_disk_is_503(tmp_path):
    data = tmp_path / "data"
    proc, url = start_service(
        data,
        workers=1,
        preexec_fn=_limit_files(1_500_000),
        env={"FLATBODY_LIMIT_MAX_QUEUED_PER_CLIENT": "200", "FLATBODY_LIMIT_MAX_QUEUED_JOBS": "200"},
    )
    try:
        with httpx.Client(base_url=url, timeout=120) as http:
            # jobs whose stored parameters fill the rest of the allowed size: 503 (one line), never 422 or 500
            n = 2001
            times = [i * (10.0 / (n - 1)) * (1 - 1e-13) for i in range(n)]
            seen = []
            for _ in range(120):
                r = http.post(
                    "/jobs", json={"kind": "simulate", "params": {"scene": "default", "t_end": 10.0, "times": times}}
                )
                seen.append(r.status_code)
                if r.status_code == 503:
                    _is_fault(r)
                    break
                assert r.status_code == 202, r.text[:300]
            assert seen[-1] == 503, seen
            assert http.get("/health").status_code == 200
            assert http.get("/jobs", params={"limit": 5}).status_code in (200, 503)
    finally:
        stop_service(proc)


def test_record_job_over_the_file_size_limit_fails_with_one_line(tmp_path):
    """A recording that goes over ``RLIMIT_FSIZE`` ends ``failed`` with one line, at once, and leaves no file.

    rerun's own file sink would wait for ever once a write failed (the job sat ``running``); the recorder copies
    rerun's stream to the file itself (flatbody_env.recording.sink), so the write fails with EFBIG in our code and
    the job fails with one line naming its file and the limit."""
    data = tmp_path / "data"
    proc, url = start_service(data, workers=1, preexec_fn=_limit_files(300_000))
    try:
        with httpx.Client(base_url=url, timeout=60) as http:
            r = http.post(
                "/jobs", json={"kind": "record", "params": {"scene": "default", "t_end": 50.0, "samples": 5001}}
            )
            assert r.status_code == 202, r.text[:300]
            job_id = r.json()["id"]
            deadline = time.monotonic() + 90
            while True:
                job = http.get(f"/jobs/{job_id}").json()
                if job["status"] in ("done", "failed") or time.monotonic() > deadline:
                    break
                time.sleep(0.3)
            assert job["status"] == "failed", job
            error = job["error"]
            assert "\n" not in error and "Traceback" not in error and "file-size limit" in error, error
            assert "'recording.rrd'" in error and str(data) not in error, error
            folder = data / "jobs" / job_id
            left = sorted(p.name for p in folder.iterdir()) if folder.exists() else []
            assert left == [], left  # no recording.rrd, no truncated temporary file
            r = http.get(f"/jobs/{job_id}/artifact")
            assert r.status_code == 409 and r.json()["kind"] == "conflict"
            assert http.get("/health").status_code == 200
    finally:
        stop_service(proc)
