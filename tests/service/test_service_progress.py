"""Every job kind reports its own progress on every path: a stream of values that rises through at least three
values strictly between 0 and 1 before the job is done (the store then sets 1), never falls, and says what it is
doing. The work functions run here in-process (:data:`flatbody_env.service.jobs.WORK`), with the job's own
:class:`~flatbody_env.service.jobs.Reporter` writing to a list instead of the job database."""

from __future__ import annotations

import pytest

from flatbody_env.service import models
from flatbody_env.service.jobs import WORK

JOBS = {
    "simulate-auto": ("simulate", {"scene": "default", "t_end": 2.0, "samples": 41}),  # the compiled default
    "simulate-scipy": ("simulate", {"scene": "default", "t_end": 50.0, "samples": 101, "method": "DOP853"}),
    "record": ("record", {"scene": "default", "t_end": 1.0, "samples": 11}),
    "family": ("family", {"from": 0.5, "to": 2.0, "seeds": 3}),
    "stability-map": ("stability-map", {"grid": 6}),
    "evaluate": ("evaluate", {"episodes": 1, "baselines": False}),
}


def _params(kind: str, params: dict) -> dict:
    from pydantic import TypeAdapter

    job = TypeAdapter(models.JobRequest).validate_python({"kind": kind, "params": params})
    return job.params.model_dump(by_alias=True)


def _run(kind: str, params: dict, folder) -> list[tuple[float, str | None]]:
    seen: list[tuple[float, str | None]] = []
    folder.mkdir(parents=True, exist_ok=True)
    WORK[kind](_params(kind, params), folder, lambda fraction, stage=None: seen.append((fraction, stage)))
    return seen


@pytest.mark.parametrize("name", list(JOBS))
def test_every_progress_stream_of_a_job_rises_through_three_values_before_done(name, tmp_path, monkeypatch):
    import flatbody_env.service.jobs as jobs

    monkeypatch.setattr(jobs, "REPORT_EVERY_S", 0.0)  # every report kept: the stream, not the machine's speed
    kind, params = JOBS[name]
    seen = _run(kind, params, tmp_path / "job-0123456789abcdef")
    values = [v for v, _ in seen]
    assert values == sorted(values), values  # never falls
    inside = sorted({v for v in values if 0.0 < v < 1.0})
    assert len(inside) >= 3, (name, seen)
    assert values[-1] < 1.0  # the last word is the store's (done), not a job claiming 100 % while it still writes
    assert all(stage for _, stage in seen), seen  # and it always says what it is doing


def test_the_compiled_default_reports_the_time_its_kernel_has_reached(tmp_path, monkeypatch):
    """A long simulation on ``auto`` (DOP853-numba, one call into compiled code) no longer sits at 2 % until done:
    the time the kernel has written is read while it runs (every report kept here, none thinned out)."""
    import flatbody_env.integrators.compiled_methods as compiled_methods
    import flatbody_env.service.jobs as jobs

    monkeypatch.setattr(jobs, "REPORT_EVERY_S", 0.0)
    watching = compiled_methods.watching_kernels  # read every 2 ms, not 50: the run takes ≈ 0.1 s on a fast machine
    monkeypatch.setattr(compiled_methods, "watching_kernels", lambda watch: watching(watch, every=0.002))
    params = {"scene": "long-horizon", "t_end": 10000.0, "samples": 20001, "rtol": 1e-13, "atol": 1e-13}
    seen = _run("simulate", params, tmp_path / "job-long")
    during = [(v, s) for v, s in seen if s and s.startswith("integrating: t = ")]
    assert len({v for v, _ in during}) >= 2, seen
    assert all(0.02 <= v <= 0.8 for v, _ in during), during
