"""Every job input is checked when the job is posted, by the checks its work runs: a value the work would refuse is a
422 naming the field, and no job is queued — never a 202 followed by a job that fails in its worker.

Each case below is an input the request models accept (the OpenAPI document cannot state it: a combination of
fields, or a field against the scene's own t_end) and that the job's work (:data:`flatbody_env.service.jobs.WORK`)
fails on, before this was checked at submission; a valid neighbour of it is accepted. The refused jobs fail before
any integration or computation, so the cases are fast.
"""

from __future__ import annotations

import pytest
from pydantic import TypeAdapter

from flatbody_env.service import models
from flatbody_env.service.jobs import WORK

from .cross_field import ANISOTROPIC, SCENE

PAPER = {**SCENE, "spin_convention": "paper"}
V2_SCENE = {**SCENE, "potential": {"name": "V2", "c": 1.0, "d": 2.0}}
V2_EVEN = {**SCENE, "potential": {"name": "V2", "c": 1.5, "d": 1.5}}
ANISO_SCENE = {**SCENE, "params": ANISOTROPIC["params"]}

CASES = [
    # (name, kind, refused params, field named, words of the detail, an accepted neighbour)
    (
        "times-and-samples",
        "simulate",
        {"t_end": 1.0, "times": [0.0, 1.0], "samples": 5},
        "params.times",
        ("not both",),
        {"t_end": 1.0, "times": [0.0, 1.0]},
    ),
    (
        "times-past-t_end",
        "simulate",
        {"t_end": 1.0, "times": [0.0, 2.0]},
        "params.times",
        ("[0, t_end] = [0, 1]",),
        {"t_end": 2.0, "times": [0.0, 2.0]},
    ),
    (
        "times-past-the-scenes-t_end",
        "simulate",
        {"scene": "default", "times": [0.0, 500.0]},  # no t_end: the scene's own (20)
        "params.times",
        ("[0, t_end] = [0, 20]",),
        {"scene": "default", "times": [0.0, 1.0]},
    ),
    (
        "times-not-increasing",
        "simulate",
        {"t_end": 1.0, "times": [1.0, 0.5]},
        "params.times",
        ("strictly increasing",),
        {"t_end": 1.0, "times": [0.5, 1.0]},
    ),
    (
        "step-with-method-auto",
        "simulate",
        {"t_end": 1.0, "step": 0.01},  # method defaults to auto
        "params.step",
        ("method='auto'",),
        {"t_end": 1.0, "step": 0.01, "method": "RK4"},
    ),
    (
        "fixed-step-method-without-step",
        "simulate",
        {"t_end": 1.0, "method": "RK4"},
        "params.step",
        ("fixed-step method",),
        {"t_end": 1.0, "method": "RK4", "step": 0.01},
    ),
    (
        "adaptive-method-with-step",
        "simulate",
        {"t_end": 1.0, "method": "DOP853", "step": 0.01},
        "params.step",
        ("adaptive",),
        {"t_end": 1.0, "method": "DOP853"},
    ),
    (
        "method-of-another-chart",
        "simulate",
        {"t_end": 1.0, "model": "regular", "method": "RK4", "step": 0.01},
        "params.method",
        ("two-polar chart",),
        {"t_end": 1.0, "model": "regular", "method": "RATTLE", "step": 0.01},
    ),
    (
        "paper-convention-in-the-regular-model",
        "simulate",
        {"t_end": 1.0, "scene": PAPER, "model": "regular"},
        "params.scene.spin_convention",
        ("'paper' needs a two-polar method",),
        {"t_end": 1.0, "scene": PAPER, "model": "two-polar"},
    ),
    (
        "splitting-of-an-anisotropic-body",
        "simulate",
        {"t_end": 1.0, "scene": ANISO_SCENE, "method": "splitting-strang", "step": 0.01},
        "params.scene.params",
        ("needs J1 = J2",),
        {"t_end": 1.0, "scene": ANISO_SCENE, "method": "RK4", "step": 0.01},
    ),
    (
        "rattle-with-V2-c-not-d",
        "simulate",
        {"t_end": 1.0, "scene": V2_SCENE, "method": "RATTLE", "step": 0.01},
        "params.scene.potential",
        ("needs c = d",),
        {"t_end": 1.0, "scene": V2_EVEN, "method": "RATTLE", "step": 0.01},
    ),
    (
        "record-step-with-method-auto",
        "record",
        {"t_end": 1.0, "samples": 11, "step": 0.01},
        "params.step",
        ("method='auto'",),
        {"t_end": 1.0, "samples": 11, "step": 0.01, "method": "RK4"},
    ),
    (
        "record-fixed-step-method-without-step",
        "record",
        {"t_end": 1.0, "samples": 11, "method": "RATTLE"},
        "params.step",
        ("fixed-step method",),
        {"t_end": 1.0, "samples": 11, "method": "RATTLE", "step": 0.01},
    ),
    (
        "record-paper-convention-in-the-regular-model",
        "record",
        {"t_end": 1.0, "samples": 11, "scene": PAPER, "model": "regular"},
        "params.scene.spin_convention",
        ("'paper' needs a two-polar method",),
        {"t_end": 1.0, "samples": 11, "scene": PAPER},
    ),
    (
        "map-without-a-shape-lambda-above-mu",
        "stability-map",
        {"grid": 4, "lam_range": [0.1, 0.2], "mu_range": [1.0, 2.0]},
        "params.lam_range",
        ("lambda > mu", "(1)"),
        {"grid": 4, "lam_range": [0.1, 1.5], "mu_range": [1.0, 2.0]},
    ),
]
IDS = [case[0] for case in CASES]


def _validated(kind: str, params: dict) -> dict:
    """The params as the job's work gets them (validated by the request model, dumped by alias)."""
    job = TypeAdapter(models.JobRequest).validate_python({"kind": kind, "params": params})
    return job.params.model_dump(by_alias=True)


def _newest_job(client) -> str | None:
    jobs = client.get("/jobs", params={"limit": 1}).json()["jobs"]
    return jobs[0]["id"] if jobs else None


@pytest.mark.parametrize("name, kind, params, field, words, neighbour", CASES, ids=IDS)
def test_the_model_accepts_the_input_and_the_work_fails_on_it(name, kind, params, field, words, neighbour, tmp_path):
    """Each case is a finding: the request model lets it through, and the job's work raises on it (in-process)."""
    p = _validated(kind, params)
    folder = tmp_path / "job-0123456789abcdef"
    folder.mkdir()
    with pytest.raises(ValueError):
        WORK[kind](p, folder, lambda fraction, stage=None: None)


@pytest.mark.parametrize("name, kind, params, field, words, neighbour", CASES, ids=IDS)
def test_a_job_input_the_work_would_refuse_is_422_and_queues_nothing(
    client, name, kind, params, field, words, neighbour
):
    before = _newest_job(client)
    r = client.post("/jobs", json={"kind": kind, "params": params})
    if r.status_code == 202:  # not refused: do not leave the job running
        client.delete(f"/jobs/{r.json()['id']}")
    assert r.status_code == 422, (r.status_code, r.text[:300])
    data = r.json()
    assert data["kind"] == "validation" and data["field"] == field, data
    assert data["detail"].startswith(f"{field}: ") and "\n" not in data["detail"], data
    for word in words:
        assert word in data["detail"], data
    assert _newest_job(client) == before  # no job was created


@pytest.mark.parametrize("name, kind, params, field, words, neighbour", CASES, ids=IDS)
def test_the_valid_neighbour_is_accepted(client, name, kind, params, field, words, neighbour):
    r = client.post("/jobs", json={"kind": kind, "params": neighbour})
    assert r.status_code == 202, (r.status_code, r.text[:300])
    client.delete(f"/jobs/{r.json()['id']}")  # the check is the answer to the post, not the work
