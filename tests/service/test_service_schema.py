"""Schemathesis against the service's own OpenAPI document (the real service on loopback).

Every operation is called with generated requests, valid and invalid: no answer is a 500, every
status code and content type is one the document declares, every answer matches its declared
schema, and requests that break the schema are refused. Jobs that a generated request queues are
cancelled at once (the job endpoints are exercised, not the work).

The cases come from schemathesis' public strategies (``APIOperation.as_strategy``) driven by a plain
hypothesis test, not from its pytest plugin: the plugin reaches into pytest's private attributes and
broke with pytest 9.2, while the strategies and checks are the stable part of its API.
"""

from __future__ import annotations

from urllib.parse import urlsplit

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable

schemathesis = pytest.importorskip("schemathesis", reason="needs schemathesis (pip install schemathesis)")
from schemathesis.checks import (  # noqa: E402
    content_type_conformance,
    negative_data_rejection,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)

CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance, negative_data_rejection]
EXAMPLES_PER_OPERATION = 25


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory):
    from flatbody_env.service.benchmark import start_service

    proc, url = start_service(tmp_path_factory.mktemp("schema-data"), workers=2)
    try:
        yield schemathesis.openapi.from_url(url + "/openapi.json")
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _call(case) -> None:
    response = case.call_and_validate(checks=CHECKS, timeout=120)
    if case.method.upper() == "POST" and case.path == "/jobs" and response.status_code == 202:
        import httpx

        url = urlsplit(str(response.request.url))
        httpx.delete(f"{url.scheme}://{url.netloc}/jobs/{response.json()['id']}", timeout=60)


@pytest.mark.parametrize("mode", ["positive", "negative"])
def test_api_matches_its_openapi_document(api_schema, mode):
    operations = [result.ok() for result in api_schema.get_all_operations()]
    assert len(operations) >= 8, "the document lists the service's operations"
    generation_mode = schemathesis.GenerationMode(mode)
    tested = 0
    for operation in operations:
        strategy = operation.as_strategy(generation_mode=generation_mode)

        @settings(max_examples=EXAMPLES_PER_OPERATION, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True, database=None)
        @given(case=strategy)
        def check(case):
            _call(case)

        try:
            check()
        except Unsatisfiable:
            # an operation with nothing to break (no parameters, no body) has no negative case
            assert mode == "negative", f"{operation.label}: no valid request could be generated"
            continue
        except Exception as exc:  # name the operation the failing case belongs to
            raise AssertionError(f"{operation.label} ({mode}): {exc}") from exc
        tested += 1
    assert tested >= len(operations) // 2, f"only {tested} of {len(operations)} operations had {mode} cases"
