"""Fixtures of the service tests: the real app in-process (TestClient) and the real service on loopback."""

from __future__ import annotations

import time
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about its httpx-based test client
    from fastapi.testclient import TestClient

from flatbody_env.service.app import create_app

DEFAULT_BODY = {
    "params": {"J": 1.0, "J3": 1.0},
    "potential": {"name": "V3", "kappa": 1.0},
    "thickness": {"a": 1.0, "b": 1.0},
}
V1_BODY = {"params": {"J": 1.0, "J3": 0.7}, "potential": {"name": "V1", "k": 1.3}, "thickness": {"a": 1.0, "b": 1.0}}


@pytest.fixture(scope="package")
def client(tmp_path_factory):
    """The app with its lifespan (job runner, worker processes) on a fresh data dir."""
    app = create_app(tmp_path_factory.mktemp("service-data"), workers=2)
    with TestClient(app, base_url="http://localhost") as c:
        yield c


def wait_job(get, job_id: str, timeout: float = 180.0) -> dict:
    """Poll ``GET /jobs/{id}`` (``get`` is a client's get) until done or failed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = get(f"/jobs/{job_id}").json()
        if job["status"] in ("done", "failed"):
            return job
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} did not finish within {timeout:g} s (last: {job})")


@pytest.fixture
def live_service(tmp_path):
    """``flatbody serve`` in a subprocess on a free loopback port: ``(process, url, data_dir)``; stopped afterwards."""
    from flatbody_env.service.launch import start_service, stop_service

    data_dir = tmp_path / "data"
    proc, url = start_service(data_dir, workers=1)
    try:
        yield proc, url, data_dir
    finally:
        stop_service(proc)
