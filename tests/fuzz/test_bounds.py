"""The hostile corpus of bounds and faults (``tests/fuzz/corpus.py``): 0 tracebacks, 0 hangs, 0 silent
accepts, no non-finite output. The default run takes every API case and a quarter of the CLI cases;
``-m slow`` runs them all. Hypothesis adds random sizes for the count flags and random env settings."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))

import corpus

FAST = settings(max_examples=20, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)


def _check(rows):
    problems = [(corpus.bad(r), r["name"], r["err"][-200:]) for r in rows if corpus.bad(r)]
    assert not problems, problems


def test_corpus_api_cases(tmp_path):
    _check([corpus.run(c) for c in corpus.api_cases(tmp_path)])


def test_corpus_cli_cases_sample(tmp_path):
    cases = corpus.cli_cases(tmp_path)
    _check([corpus.run(c) for c in cases[::4]])


@pytest.mark.slow
def test_corpus_all(tmp_path):
    counts, rows = corpus.run_all(tmp_path)
    _check(rows)
    assert counts["tracebacks"] == counts["hangs"] == counts["silent_accepts"] == counts["non_finite_outputs"] == 0


@FAST
@given(
    which=st.sampled_from(corpus.COUNT_FLAGS),
    value=st.integers(min_value=10**13, max_value=10**60) | st.integers(max_value=-1),
)
def test_every_count_flag_has_an_upper_bound(tmp_path_factory, which, value):
    prefix, flag = which
    tmp = str(tmp_path_factory.mktemp("c"))
    row = corpus.run(
        corpus.Case("cli", f"{flag} {value}", "refuse", [*(x.replace("{tmp}", tmp) for x in prefix), flag, str(value)])
    )
    assert corpus.bad(row) is None, row
    assert row["outcome"] == "refuse"


@FAST
@given(dt=st.floats(allow_nan=True, allow_infinity=True), step=st.none() | st.floats(min_value=-1.0, max_value=1.0))
def test_env_dt_and_step_are_bounded_or_refused(dt, step):
    kw = {"dt": dt} if step is None else {"dt": dt, "integrator": "RK4", "step": step}
    row = corpus.run(corpus.Case("api", str(kw), "clean", call=_one_step(kw)))
    assert corpus.bad(row) is None, row
    ok = 1e-4 <= dt <= 1.0 if math.isfinite(dt) else False
    if step is not None:
        ok = ok and 1e-6 <= step <= dt and math.ceil(dt / step) <= 100_000
    assert (row["outcome"] != "refuse") == ok, row


def _one_step(kw):
    def call():
        import gymnasium as gym

        import flatbody_env  # noqa: F401 - registers the env ids

        env = gym.make("FlatBody-v0", **kw)
        env.reset(seed=1)
        obs, *_ = env.step(env.action_space.sample() * 0)
        return {"obs": obs}

    return call


@FAST
@given(
    step=st.floats(allow_nan=True, allow_infinity=True, min_value=None, max_value=None),
    wall=st.floats(allow_nan=True, allow_infinity=True) | st.integers(min_value=-5, max_value=10**12),
    nfev=st.integers(min_value=-5, max_value=10**14) | st.booleans(),
)
def test_simulate_step_and_budget_are_bounded_or_refused(step, wall, nfev):
    from flatbody_env.simulation import simulate

    row = corpus.run(
        corpus.Case(
            "api",
            f"simulate step={step} wall={wall} nfev={nfev}",
            "clean",
            call=lambda: {
                "y": simulate(
                    "default", t_end=0.5, times=[0.0, 0.5], method="RK4", step=step, max_wall_time=wall, max_nfev=nfev
                ).y
            },
        )
    )
    assert corpus.bad(row) is None, row
    if row["outcome"] == "ok":  # accepted only within the documented bounds
        assert 1e-6 <= step <= 1e6 and 0 < wall <= 86_400 and not isinstance(nfev, bool) and 1 <= nfev <= 10**12
