"""Every ``workers`` argument of the library goes through one validator
(:func:`flatbody_env.physics.validation.workers`): an integer in [1, MAX_WORKERS] (or [0, ...] where 0 means "in this
process"), refused before any process starts with a ``ValueError`` that names ``workers`` and the range."""

from __future__ import annotations

import pytest

from flatbody_env.physics import validation

RANGE = f"(allowed range [1, {validation.MAX_WORKERS}])"


@pytest.mark.parametrize("value", [0, -1, validation.MAX_WORKERS + 1, 2.0, True, "2", None])
def test_the_workers_validator(value):
    with pytest.raises(ValueError, match=r"^workers: must be an integer \(allowed range \[1, 256\]\)"):
        validation.workers("workers", value)


def test_the_workers_validator_accepts_its_range():
    assert validation.workers("workers", 1) == 1
    assert validation.workers("workers", validation.MAX_WORKERS) == validation.MAX_WORKERS
    assert validation.workers("--workers", 0, low=0) == 0


def _refused(call) -> None:
    with pytest.raises(ValueError) as info:
        call()
    assert str(info.value).startswith("workers: must be an integer") and RANGE in str(info.value), str(info.value)


@pytest.mark.parametrize("workers", [0, -3, 10**6])
def test_library_entry_points_refuse_bad_workers_before_any_work(workers):
    from agents.heuristic import build_gain_table
    from agents.tune import shares
    from flatbody_env.env.targets import build_table

    _refused(lambda: shares(3, workers))
    _refused(lambda: build_table(workers=workers))  # before its process pool (it checked nothing before)
    _refused(lambda: build_gain_table(workers=workers))


def test_service_refuses_bad_workers(tmp_path):
    pytest.importorskip("fastapi")
    from flatbody_env.service.app import create_app
    from flatbody_env.service.jobs import JobRunner

    _refused(lambda: create_app(tmp_path / "data", workers=0))
    _refused(lambda: create_app(tmp_path / "data", workers=10**6))  # no upper bound before
    _refused(lambda: JobRunner(None, 0))
    _refused(lambda: JobRunner(None, 2.5))  # a float compared to 1 and kept before
