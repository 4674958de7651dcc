"""Schemathesis against the service's own OpenAPI document (the real service on loopback).

Every operation is called with generated requests, valid and invalid, under every schemathesis check:
no answer is a 500, every status code, header and content type is one the document declares, every
answer matches its declared schema, requests that break the schema are refused (4xx, 413 included),
unsupported methods get 405 with ``Allow``, and schema-valid requests are accepted unless what refused
them is beyond a schema (``cross_field.CROSS_FIELD``, each entry with a witness request tested in
``test_cross_field.py``; a failed integration, naming ``scene``, or one over its budget, naming ``t_end``; a
computation that fails, naming the endpoint's input) — every such refusal names its field, save a request
over the computing-time limit (``request``). Jobs that a generated request queues are cancelled at once (the
job endpoints are exercised, not the work).

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
from schemathesis.checks import CHECKS as REGISTRY, load_all_checks  # noqa: E402

load_all_checks()
ALL_CHECKS = list(REGISTRY.get_all())
"""Every check schemathesis has (``not_a_server_error`` … ``positive_data_acceptance``, ``unsupported_method``, …)."""
POSITIVE = next(c for c in ALL_CHECKS if getattr(c, "__name__", "") == "positive_data_acceptance")
CHECKS = [c for c in ALL_CHECKS if c is not POSITIVE]
EXAMPLES_PER_OPERATION = 25

from .cross_field import CROSS_FIELD, CROSS_FIELD_PREFIXES  # noqa: E402  (each entry shown a real refusal: test_cross_field.py)


INPUT_FIELDS = ("scene", "body", "trajectory", "params")
"""What a computation that fails names (``answers.INPUT_FIELDS``): the scene whose integration failed, the body of a failed
analysis, the trajectory of ``POST /invariants``, a job's ``params``."""


def _computed_refusal(response) -> bool:
    """A schema-valid request refused by what the schema cannot state (:data:`CROSS_FIELD`) or by the computation itself.
    Every such refusal names its field; the only one without a single field at fault is a request that took longer than
    the request time limit (413, ``field`` ``"request"``: ``request: took longer than ... s; send it as a job``)."""
    if response.status_code not in (413, 422):
        return False
    data = response.json()
    field, detail, kind = data.get("field"), data.get("detail", ""), data.get("kind")
    if not field or not detail.startswith(f"{field}:"):
        return False  # an HTTP 4xx names the field at fault, and its line starts with it
    if kind == "integration":  # a failed integration: the scene, with the time and the reason
        return field in INPUT_FIELDS and data.get("why") is not None
    if kind == "too-large" and field == "request":
        return detail.startswith("request: took longer than")
    if (
        kind == "too-large" and field == "t_end" and data.get("why") is not None
    ):  # the integration's budget ran out before t_end
        return True
    if field in INPUT_FIELDS and "the computation failed" in detail:
        return True
    return field in CROSS_FIELD or field.startswith(CROSS_FIELD_PREFIXES)


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory):
    from flatbody_env.service.launch import start_service, stop_service

    proc, url = start_service(tmp_path_factory.mktemp("schema-data"), workers=2)
    try:
        schema = schemathesis.openapi.from_url(url + "/openapi.json")
        # 413 (a body or work over a limit) refuses schema-breaking data as well as 400/422 do
        checks = schema.config.checks
        checks.negative_data_rejection.expected_statuses = [*checks.negative_data_rejection.expected_statuses, "413"]
        yield schema
    finally:
        stop_service(proc)


def _call(case) -> None:
    response = case.call(timeout=120)
    case.validate_response(response, checks=CHECKS)
    if not _computed_refusal(response):
        case.validate_response(response, checks=[POSITIVE])
    if case.method.upper() == "POST" and case.path == "/jobs" and response.status_code == 202:
        import httpx

        url = urlsplit(str(response.request.url))
        httpx.delete(f"{url.scheme}://{url.netloc}/jobs/{response.json()['id']}", timeout=60)


@pytest.mark.parametrize(
    "mode", ["positive", pytest.param("negative", marks=pytest.mark.slow)]
)  # negative inputs: also the HTTP corpus
def test_api_matches_its_openapi_document(api_schema, mode):
    operations = [result.ok() for result in api_schema.get_all_operations()]
    assert len(operations) >= 8, "the document lists the service's operations"
    generation_mode = schemathesis.GenerationMode(mode)
    tested = 0
    for operation in operations:
        strategy = operation.as_strategy(generation_mode=generation_mode)

        @settings(
            max_examples=EXAMPLES_PER_OPERATION,
            deadline=None,
            suppress_health_check=list(HealthCheck),
            derandomize=True,
            database=None,
        )
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
