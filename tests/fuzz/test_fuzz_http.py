"""Fuzzing the HTTP service: hostile values for every field of every endpoint against a real ``flatbody serve``.

The service runs on loopback with small limits (:data:`http_corpus.SMALL_LIMITS`) and its log in a file. Two
suites, judged by the same oracle (:func:`http_corpus.judge`): the fixed corpus (:func:`http_corpus.fixed_cases`,
about 1 900 requests: every field × every hostile value of its kind, broken and oversized bodies, duplicate keys,
hostile query strings and job ids, bad ``Host`` headers, unsupported methods), whose tally must be 0 for
tracebacks in the server's log, hangs, silent accepts, 5xx (but a documented 503) and 4xx not naming the
field; and hypothesis-drawn values (any JSON value: floats with NaN/±inf, huge integers, unicode, nested
lists and objects) at a drawn field of a drawn endpoint. Every request has a timeout (:data:`TIMEOUT_S`); all
traffic goes to the service the test starts.

``pytest -m slow tests/fuzz/test_fuzz_http.py`` draws 20 times as many hypothesis examples.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import httpx
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))
import http_corpus as corpus  # noqa: E402

TIMEOUT_S = 30.0
"""Longest a request may take before it counts as a hang (the service's request limit is 20 s)."""
EXAMPLES = 80
SLOW_EXAMPLES = 1600


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    folder = tmp_path_factory.mktemp("http-fuzz")
    log = folder / "serve.log"
    proc, url = corpus.start_service(folder / "data", log)
    try:
        yield url, log, corpus.base_trajectory(url)
    finally:
        corpus.stop_service(proc)


def test_fixed_corpus(service, capsys):
    url, log, trajectory = service
    cases = corpus.fixed_cases(trajectory)
    assert len(cases) >= 500
    tally = corpus.run(url, cases, timeout=TIMEOUT_S)
    tally.tracebacks = corpus.count_tracebacks(log)
    with capsys.disabled():
        print("\n" + tally.report())
    counts = tally.counts()
    assert {k: v for k, v in counts.items() if k != "cases" and v} == {}, tally.report()
    assert tally.statuses[None] == 0


def json_values():
    """Any JSON value, hostile ones weighted in: NaN/±inf (sent as JSON tokens), huge and tiny numbers, unicode,
    nested lists and objects."""
    scalars = st.one_of(
        st.none(),
        st.booleans(),
        st.integers(min_value=-(10**30), max_value=10**30),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=40),
        st.sampled_from([1e308, -1e308, 10**400, 1e-308, 0, -1, 263.0, 263.5, "NaN", "inf", "", "é中😀"]),
    )
    return st.recursive(
        scalars,
        lambda inner: st.one_of(st.lists(inner, max_size=6), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
        max_leaves=12,
    )


def _choices(trajectory):
    return [(ep, path) for ep in corpus.endpoints(trajectory) for path in ep.fields]


def _drawn_cases(service, examples):
    url, log, trajectory = service
    choices = _choices(trajectory)

    @settings(max_examples=examples, deadline=None, suppress_health_check=list(HealthCheck), database=None)
    @given(choice=st.sampled_from(choices), value=json_values())
    def check(choice, value):
        ep, path = choice
        case = corpus.field_case(ep, path, value)
        with httpx.Client(base_url=url) as http:
            status, headers, text = corpus.send(http, case, TIMEOUT_S)
        found = corpus.judge(case, status, headers, text)
        assert not found, f"{found}: {case.name} ({ep.method} {ep.path}) -> {status} {text[:300]}"

    check()
    assert corpus.count_tracebacks(log) == 0, log.read_text()[-3000:]


def test_drawn_values_at_every_field(service):
    _drawn_cases(service, EXAMPLES)


@pytest.mark.slow
def test_drawn_values_at_every_field_long(service):
    _drawn_cases(service, SLOW_EXAMPLES)


def test_corpus_oracle_knows_the_bounds():
    """The oracle itself: out-of-range, non-finite and wrongly typed values must be refused, in-range ones may pass."""
    grid = corpus.integer(8, 401)
    assert corpus.in_bounds(263, grid) and corpus.in_bounds(corpus.Raw("263.0"), grid)
    assert not any(
        corpus.in_bounds(v, grid)
        for v in (corpus.Raw("263.5"), 7, 402, True, "263", None, corpus.Raw("1e999"), 10**400)
    )
    t_end = corpus.num(0, 200, gt=True, nullable=True)
    assert corpus.in_bounds(None, t_end) and corpus.in_bounds(200, t_end)
    assert not any(
        corpus.in_bounds(v, t_end)
        for v in (0, -1, corpus.Raw("NaN"), corpus.Raw("Infinity"), "1", 1e308, json.loads("1e999"))
    )
