"""Schemathesis against the service's own OpenAPI document (the real service on loopback).

Every operation is called with generated requests: no answer is a 500, every status code and
content type is one the document declares, and every answer matches its declared schema. Jobs that
a generated request queues are cancelled at once (the job endpoints are exercised, not the work).
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, settings

schemathesis = pytest.importorskip("schemathesis", reason="needs schemathesis (pip install schemathesis)")
from schemathesis.checks import (  # noqa: E402
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)

CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance]


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory):
    from flatbody_env.service.benchmark import start_service

    proc, url = start_service(tmp_path_factory.mktemp("schema-data"), workers=2)
    try:
        yield schemathesis.openapi.from_url(url + "/openapi.json")
    finally:
        proc.terminate()
        proc.wait(timeout=30)


schema = schemathesis.pytest.from_fixture("api_schema")


@schema.parametrize()
@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
def test_api_matches_its_openapi_document(case):
    response = case.call_and_validate(checks=CHECKS, timeout=120)
    if case.method.upper() == "POST" and case.path == "/jobs" and response.status_code == 202:
        from urllib.parse import urlsplit

        import httpx

        url = urlsplit(str(response.request.url))
        httpx.delete(f"{url.scheme}://{url.netloc}/jobs/{response.json()['id']}", timeout=60)
