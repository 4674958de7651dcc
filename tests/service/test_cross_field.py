"""Every field the schemathesis test accepts as refused beyond the schema (``cross_field.CROSS_FIELD``) is a real
refusal: its witness request is valid under the service's OpenAPI document, and the service answers it with the
status given and the field named, in one line."""

from __future__ import annotations

import pytest

from .cross_field import CROSS_FIELD, CROSS_FIELD_PREFIXES, PREFIX_WITNESSES, WITNESSES


@pytest.fixture(scope="module")
def document(client):
    return client.get("/openapi.json").json()


CASES = WITNESSES + [w[1:] for w in PREFIX_WITNESSES]


@pytest.mark.parametrize("field, status, path, request_body, why", CASES, ids=[f"{w[0]}:{w[4]}" for w in CASES])
def test_each_cross_field_refusal_is_real(client, document, field, status, path, request_body, why):
    jsonschema_rs = pytest.importorskip("jsonschema_rs", reason="checks the witness against the OpenAPI document")
    schema = document["paths"][path]["post"]["requestBody"]["content"]["application/json"]["schema"]
    validator = jsonschema_rs.validator_for({**schema, "components": document["components"]})
    assert validator.is_valid(request_body), f"the witness of {field} ({why}) breaks the schema itself: {request_body}"
    r = client.post(path, json=request_body)
    if r.status_code == 202:  # not refused: do not leave the job running
        client.delete(f"/jobs/{r.json()['id']}")
    assert r.status_code == status, (field, r.status_code, r.text[:300])
    data = r.json()
    assert data["field"] == field, data
    assert data["detail"].startswith(field) and "\n" not in data["detail"], data


def test_cross_field_list_is_derived_from_the_witnesses():
    assert {w[0] for w in WITNESSES} == CROSS_FIELD
    assert len(CROSS_FIELD) >= 15
    assert CROSS_FIELD_PREFIXES == ("trajectory.",)
    assert all(field.startswith(prefix) for prefix, field, *_ in PREFIX_WITNESSES)
