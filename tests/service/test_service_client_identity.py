"""Whose job is it: the per-client job quota counts the connection's address, over real HTTP (``flatbody serve`` on
loopback). A header any local client can set (``X-Forwarded-For``) does not choose the client unless the user named
the proxies in front of the service (``--trusted-proxies``)."""

from __future__ import annotations

import httpx
import pytest

from flatbody_env.cli.main import main
from flatbody_env.service.launch import start_service, stop_service

QUOTA = {"FLATBODY_LIMIT_MAX_QUEUED_PER_CLIENT": "3", "FLATBODY_LIMIT_MAX_QUEUED_JOBS": "40"}


def test_a_forwarded_for_header_does_not_dodge_the_per_client_quota(tmp_path):
    proc, url = start_service(tmp_path / "data", workers=1, env=QUOTA)
    try:
        with httpx.Client(base_url=url, timeout=60.0) as http:
            http.post("/jobs", json={"kind": "stability-map", "params": {"grid": 200}})  # holds the one worker
            statuses = []
            for i in range(8):  # each request claims another client
                r = http.post(
                    "/jobs",
                    json={"kind": "stability-map", "params": {"grid": 40}},
                    headers={"X-Forwarded-For": f"10.0.0.{i + 1}"},
                )
                statuses.append(r.status_code)
                if r.status_code == 429:
                    assert "per client" in r.json()["detail"]
        assert statuses.count(202) <= 3 and 429 in statuses, statuses
    finally:
        stop_service(proc)


@pytest.mark.parametrize("value", ["", "not-an-ip", "10.0.0.1,nope"])
def test_trusted_proxies_must_be_addresses(value, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["serve", "--trusted-proxies", value])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--trusted-proxies" in err[0]
