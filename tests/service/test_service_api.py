"""The service through the real app (TestClient, lifespan and worker processes included).

Answers are compared with what the ``flatbody`` command prints for the same input (same keys, same
numbers), and checked against physics the code under test does not compute (the equations of
motion at a stationary ellipse, conservation along a trajectory). Every error path answers one
line naming the field and the range or limit, never a 500.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from flatbody_env.cli.main import main as cli
from flatbody_env.service.limits import DEFAULT_LIMITS
from service.conftest import DEFAULT_BODY, V1_BODY, wait_job

V1_FLAGS = ["--potential", "V1", "--k", "1.3", "--J", "1", "--J3", "0.7", "--a", "1", "--b", "1"]


def cli_json(capsys, *argv: str):
    capsys.readouterr()
    assert cli(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def without_wall_time(traj: dict) -> dict:
    out = dict(traj)
    out["meta"] = {k: v for k, v in traj["meta"].items() if k != "wall_time"}
    return out


def assert_error(r, status: int, field: str | None = None, *words: str) -> dict:
    assert r.status_code == status, r.text
    data = r.json()
    assert set(data) <= {"detail", "kind", "field", "when", "why", "method"}
    assert "\n" not in data["detail"] and "Traceback" not in data["detail"]
    if field is not None:
        assert data["field"] == field, data
        assert data["detail"].startswith(field), data
    for w in words:
        assert w in data["detail"], data
    return data


# ------------------------------------------------------------------------------------------------
# plain answers = the command's answers
# ------------------------------------------------------------------------------------------------
def test_health(client):
    from flatbody_env import __version__

    assert client.get("/health").json() == {"status": "ok", "version": __version__}


def test_scenes_and_methods_are_the_commands_json(client):
    # the command as a user runs it (a fresh process: other tests may register methods in this one)
    for name in ("scenes", "methods"):
        proc = subprocess.run(
            [sys.executable, "-m", "flatbody_env.cli", name, "--json"], capture_output=True, text=True, timeout=120
        )
        assert proc.returncode == 0, proc.stderr
        assert client.get(f"/{name}").json() == json.loads(proc.stdout)


def test_ellipses_is_the_commands_json_and_stationary(client, capsys):
    r = client.post("/ellipses", json={"body": V1_BODY, "s3": 2.0, "p_theta": 0.5})
    assert r.status_code == 200
    answer = r.json()
    assert answer == cli_json(capsys, "ellipses", *V1_FLAGS, "--s3", "2", "--p-theta", "0.5", "--json")
    assert len(answer["solutions"]) >= 1
    # independent check: the equations of motion (eq. (44)-(49) of the paper) leave the shape and
    # the momenta unchanged at each answer; only theta turns, at theta_dot
    from flatbody_env.physics.body import Body
    from flatbody_env.physics.equations import rhs
    from flatbody_env.physics.state import STATE_NAMES

    body = Body.from_dict(V1_BODY)
    for sol in answer["solutions"]:
        y = np.array([sol["state"][n] for n in STATE_NAMES])
        dy = rhs(0.0, y, None, body)
        assert np.max(np.abs(dy[:10])) < 1e-8
        assert dy[10] == pytest.approx(sol["theta_dot"], abs=1e-8)


def test_stability_is_the_commands_json(client, capsys):
    req = {"body": DEFAULT_BODY, "s3": 1.45, "p_theta": 1.77, "grid": 60}
    r = client.post("/stability", json=req)
    assert r.status_code == 200
    assert r.json() == cli_json(capsys, "stability", "--s3", "1.45", "--p-theta", "1.77", "--grid", "60", "--json")
    assert {s["classification"] for s in r.json()["solutions"]} <= {"elliptic", "hyperbolic", "degenerate"}


def test_simulate_is_the_commands_json_and_conserves(client, capsys):
    r = client.post("/simulate", json={"scene": "default", "t_end": 2.0, "samples": 9, "with_rotation": True})
    assert r.status_code == 200
    traj = r.json()
    expected = cli_json(capsys, "simulate", "--scene", "default", "--t-end", "2", "--samples", "9", "--with-rotation")
    assert without_wall_time(traj) == without_wall_time(expected)
    assert traj["t"] == pytest.approx(np.linspace(0, 2, 9).tolist(), abs=1e-15)
    # H, |s|^2 and p_theta are conserved (eqs. (41), (55) of the paper), R stays orthogonal
    for key in ("energy", "casimir", "p_theta"):
        assert np.ptp(traj[key]) < 1e-7
    R = np.array(traj["rotation"])
    assert np.max(np.abs(np.einsum("nij,nkj->nik", R, R) - np.eye(3))) < 1e-8


def test_simulate_takes_a_scene_object(client):
    scene = json.loads(json.dumps(client.get("/scenes").json()["stationary-v1"]))
    r = client.post("/simulate", json={"scene": scene, "t_end": 1.0, "samples": 5})
    assert r.status_code == 200
    lam = r.json()["state"]["lambda"]
    assert np.ptp(lam) < 1e-8  # the closed-form stationary ellipse keeps its shape


def test_invariants_of_a_posted_trajectory_is_the_commands_json(client, capsys, tmp_path):
    path = tmp_path / "traj.json"
    assert (
        cli(
            ["simulate", "--scene", "default", "--t-end", "1", "--samples", "11", "--with-rotation", "--out", str(path)]
        )
        == 0
    )
    data = json.loads(path.read_text())
    r = client.post("/invariants", json=data)
    assert r.status_code == 200, r.text
    assert r.json() == cli_json(capsys, "invariants", str(path), "--json")
    drift = {row["name"]: row for row in r.json()["drift"]}
    assert drift["energy"]["max_abs_drift"] < 1e-7 and drift["casimir"]["max_abs_drift"] < 1e-9
    # an explicit body gives the same H as the scene's body (the default scene's)
    r2 = client.post("/invariants", json={**data, "body": DEFAULT_BODY})
    assert r2.status_code == 200
    assert {x["name"]: x["initial"] for x in r2.json()["drift"]}["energy"] == pytest.approx(
        drift["energy"]["initial"], rel=1e-12
    )


def test_health_answers_while_a_slow_request_runs(client):
    # scipy's DOP853 at a tight tolerance: seconds of work whatever the machine (the compiled default would finish too soon)
    slow = {"scene": "regular", "t_end": 200.0, "samples": 2001, "rtol": 1e-13, "atol": 1e-13, "method": "DOP853"}
    done: dict = {}
    thread = threading.Thread(target=lambda: done.setdefault("r", client.post("/simulate", json=slow)))
    thread.start()
    time.sleep(0.05)
    answered_while_busy = 0
    while thread.is_alive():
        if client.get("/health").status_code == 200 and thread.is_alive():
            answered_while_busy += 1
        time.sleep(0.05)
    thread.join()
    assert done["r"].status_code == 200
    assert answered_while_busy >= 1


# ------------------------------------------------------------------------------------------------
# errors: 422 naming the field and range, 413 naming the limit, never a 500
# ------------------------------------------------------------------------------------------------
def test_bad_body_constant_names_the_field_and_range(client):
    bad = {**DEFAULT_BODY, "params": {"J": -1.0, "J3": 1.0}}
    assert_error(
        client.post("/ellipses", json={"body": bad, "s3": 2, "p_theta": 0.5}), 422, "body.params.J", "allowed range"
    )
    bad = {**DEFAULT_BODY, "potential": {"name": "V9"}}
    assert_error(
        client.post("/stability", json={"body": bad, "s3": 2, "p_theta": 0.5}), 422, "body.potential.name", "V1"
    )


def test_anisotropic_body_is_refused_by_the_analysis(client):
    body = {**DEFAULT_BODY, "params": {"J1": 1.2, "J2": 0.8, "J3": 1.0}}
    assert_error(
        client.post("/ellipses", json={"body": body, "s3": 2, "p_theta": 0.5}), 422, "body.params", "isotropic"
    )


@pytest.mark.filterwarnings("error::UserWarning")
def test_three_moment_bodies_serialize_without_pydantic_warnings(client):
    """``{"J1", "J2", "J3"}`` is serialized as what it is: pydantic calls the ``params`` union's discriminator on the
    model instance too, and a discriminator that read dicts only sent an ``Inertia`` to the isotropic member's
    serializer (a ``PydanticSerializationUnexpectedValue`` warning on every such request)."""
    import warnings

    from pydantic import TypeAdapter

    from flatbody_env.service import models

    three = {**DEFAULT_BODY, "params": {"J1": 1.2, "J2": 0.8, "J3": 1.0}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dumped = models.SpinsRequest.model_validate({"body": three, "s3": 2, "p_theta": 0.5}).model_dump(by_alias=True)
        assert dumped["body"]["params"] == three["params"]
        job = TypeAdapter(models.JobRequest).validate_python({"kind": "family", "params": {"body": three}})
        assert job.params.model_dump(by_alias=True)["body"]["params"] == three["params"]
        iso = models.SpinsRequest.model_validate({"body": DEFAULT_BODY, "s3": 2, "p_theta": 0.5}).model_dump(
            by_alias=True
        )
        assert iso["body"]["params"] == DEFAULT_BODY["params"]
        # the request end to end (a warning raised in the endpoint would be a 503, not the analysis' 422)
        assert_error(
            client.post("/stability", json={"body": three, "s3": 2, "p_theta": 0.5}), 422, "body.params", "isotropic"
        )


@pytest.mark.parametrize(
    "change, field",
    [
        ({"s3": "two"}, "s3"),
        ({"p_theta": None}, "p_theta"),
        ({"grid": 5000}, "grid"),
        ({"grid": 3}, "grid"),
        ({"lam_range": [3.0, 1.0]}, "lam_range"),
        ({"branch": "Z"}, "branch"),
        ({"colour": "red"}, "colour"),
    ],
)
def test_bad_fields_are_422_naming_the_field(client, change, field):
    req = {"body": DEFAULT_BODY, "s3": 2.0, "p_theta": 0.5, **change}
    data = assert_error(client.post("/ellipses", json=req), 422, field)
    if field == "grid":
        assert str(DEFAULT_LIMITS.sync_grid) in data["detail"] or "8" in data["detail"]


def test_nan_and_malformed_json_are_422(client):
    raw = f'{{"body": {json.dumps(DEFAULT_BODY)}, "s3": NaN, "p_theta": 0.5}}'
    assert_error(client.post("/ellipses", content=raw, headers={"content-type": "application/json"}), 422, "s3")
    r = client.post("/ellipses", content="{not json", headers={"content-type": "application/json"})
    assert_error(r, 422, None, "JSON")


def test_oversized_body_is_413(client):
    big = DEFAULT_LIMITS.max_trajectory_body_bytes  # a trajectory may be larger than other bodies
    r = client.post("/invariants", content=b" " * (big + 1), headers={"content-type": "application/json"})
    assert_error(r, 413, "body", str(big))
    r = client.post(
        "/ellipses", content=b" " * (DEFAULT_LIMITS.max_body_bytes + 1), headers={"content-type": "application/json"}
    )
    assert_error(r, 413, "body", str(DEFAULT_LIMITS.max_body_bytes))


@pytest.mark.parametrize(
    "req, field",
    [
        ({"t_end": 1000.0}, "t_end"),
        ({"t_end": 10.0, "samples": DEFAULT_LIMITS.sync_samples + 1}, "samples"),
        ({"t_end": 100.0, "method": "RK4", "step": 1e-5}, "step"),
    ],
)
def test_costly_simulations_are_413_naming_the_limit(client, req, field):
    data = assert_error(client.post("/simulate", json={"scene": "default", **req}), 413, field, "POST /jobs")
    assert data["kind"] == "too-large"


def test_integration_failure_is_422_with_when_and_why(client, capsys):
    req = {"scene": "small-rho-bounce", "method": "RK4", "step": 0.5, "t_end": 5.0, "samples": 5}
    data = assert_error(client.post("/simulate", json=req), 422, "scene")  # the scene whose trajectory failed
    assert data["kind"] == "integration" and data["method"] == "RK4"
    assert data["when"] > 0 and "energy" in data["why"]
    # the command says the same (exit 1, one line)
    capsys.readouterr()
    assert (
        cli(
            [
                "simulate",
                "--scene",
                "small-rho-bounce",
                "--method",
                "RK4",
                "--step",
                "0.5",
                "--t-end",
                "5",
                "--samples",
                "5",
            ]
        )
        == 1
    )
    assert data["why"] in capsys.readouterr().err


@pytest.mark.parametrize(
    "req, field",
    [
        ({"scene": "no-such-scene"}, "scene"),
        ({"scene": "/etc/hostname"}, "scene"),
        (
            {"scene": {"params": {"J": 1, "J3": 1}, "potential": {"name": "V3", "kappa": 1}, "thickness": None}},
            "scene.state",
        ),
        ({"method": "Euler"}, "method"),
        ({"method": "RK4"}, "step"),
        ({"rtol": -1}, "rtol"),
        ({"times": [0.0, 0.5, 0.25]}, "times"),
    ],
)
def test_bad_simulations_are_422(client, req, field):
    assert_error(client.post("/simulate", json={"t_end": 1.0, **req}), 422, field)


def test_bad_trajectory_is_422(client):
    assert_error(
        client.post("/invariants", json={"t": [0.0, 1.0], "state": {"s1": [0.0, 0.0]}}), 422, "trajectory.state.s2"
    )
    assert_error(client.post("/invariants", json={"state": {}}), 422, "t")


def test_unknown_paths_and_methods_are_not_500(client):
    assert client.get("/nowhere").status_code == 404
    assert client.put("/health").status_code == 405


# ------------------------------------------------------------------------------------------------
# jobs
# ------------------------------------------------------------------------------------------------
def test_simulate_job_matches_the_request_answer(client):
    params = {"scene": "default", "t_end": 1.0, "samples": 6}
    r = client.post("/jobs", json={"kind": "simulate", "params": params})
    assert r.status_code == 202
    job = wait_job(client.get, r.json()["id"])
    assert job["status"] == "done" and job["progress"] == 1.0 and job["error"] is None
    assert without_wall_time(job["result"]) == without_wall_time(client.post("/simulate", json=params).json())
    art = client.get(f"/jobs/{job['id']}/artifact")
    assert art.status_code == 200 and art.json() == job["result"]
    assert job["id"] in [j["id"] for j in client.get("/jobs").json()["jobs"]]


def test_family_and_stability_map_jobs_are_the_commands_answers(client, capsys):
    fam = client.post(
        "/jobs",
        json={"kind": "family", "params": {"body": V1_BODY, "from": 0.5, "to": 2.0, "seeds": 3, "p_theta": 0.5}},
    )
    smap = client.post("/jobs", json={"kind": "stability-map", "params": {"grid": 6}})
    fam_job, map_job = wait_job(client.get, fam.json()["id"]), wait_job(client.get, smap.json()["id"])
    assert fam_job["status"] == "done", fam_job["error"]
    expected = cli_json(
        capsys, "family", *V1_FLAGS, "--from", "0.5", "--to", "2", "--seeds", "3", "--p-theta", "0.5", "--json"
    )
    assert {k: v for k, v in fam_job["result"].items() if k not in ("csv", "plot")} == {
        k: v for k, v in expected.items() if k not in ("csv", "plot")
    }
    assert fam_job["artifacts"] == ["family.png", "family.csv"]
    png = client.get(f"/jobs/{fam_job['id']}/artifact")
    assert png.headers["content-type"] == "image/png" and png.content[:8] == b"\x89PNG\r\n\x1a\n"
    csv_text = client.get(f"/jobs/{fam_job['id']}/artifact", params={"name": "family.csv"}).text
    assert csv_text.count("\n") >= fam_job["result"]["points"]
    assert map_job["status"] == "done", map_job["error"]
    assert map_job["result"] == cli_json(capsys, "stability-map", "--grid", "6", "--json")


def test_record_job_writes_a_recording_that_reads_back(client, tmp_path):
    from flatbody_env.recording import read_recording

    r = client.post("/jobs", json={"kind": "record", "params": {"scene": "default", "t_end": 1.0, "samples": 11}})
    job = wait_job(client.get, r.json()["id"])
    assert job["status"] == "done", job["error"]
    name = f"flatbody-record-default-t1-{job['id'][:8]}.rrd"  # what it holds, not recording.rrd for every job
    assert job["result"]["open_with"] == f"rerun {name}" and job["result"]["download"] == name
    assert job["artifacts"] == ["recording.rrd", "preview.png", "trajectory.json"]
    art = client.get(f"/jobs/{job['id']}/artifact")
    assert art.status_code == 200
    assert f'filename="{name}"' in art.headers["content-disposition"]
    # the preview: four frames of the plate side by side, and the trajectory the page draws
    from PIL import Image

    preview = tmp_path / "preview.png"
    preview.write_bytes(client.get(f"/jobs/{job['id']}/artifact", params={"name": "preview.png"}).content)
    assert Image.open(preview).size == (4 * 256 + 3 * 8, 256)
    traj = client.get(f"/jobs/{job['id']}/artifact", params={"name": "trajectory.json"}).json()
    assert len(traj["t"]) == 11 and traj["meta"]["scene"] == "default"
    path = tmp_path / "got.rrd"
    path.write_bytes(art.content)
    rec = read_recording(path)
    longest = max(rec.entities.values(), key=lambda e: e.step.size)
    assert longest.step.size == 11
    assert longest.sim_time[-1] == pytest.approx(1.0)


def test_evaluate_job_reports_the_shipped_agent(client):
    from agents.evaluate import run_episodes, summarize, Agent

    r = client.post("/jobs", json={"kind": "evaluate", "params": {"episodes": 2, "seed": 7, "baselines": False}})
    job = wait_job(client.get, r.json()["id"], timeout=300)
    assert job["status"] == "done", job["error"]
    agent = Agent(None)
    expected = summarize(run_episodes(agent, episodes=2, seed=7, env_kwargs=agent.env_kwargs, env_id=agent.env_id))
    got = job["result"]["agent"]
    assert got.keys() == expected.keys()
    for key, value in expected.items():  # the interval is a (low, high) pair
        assert got[key] == pytest.approx(list(value) if isinstance(value, tuple) else value), key
    assert "baselines" not in job["result"]


def test_failed_job_keeps_the_integration_error(client):
    params = {"scene": "small-rho-bounce", "method": "RK4", "step": 0.5, "t_end": 5.0, "samples": 5}
    job = wait_job(client.get, client.post("/jobs", json={"kind": "simulate", "params": params}).json()["id"])
    assert job["status"] == "failed" and "integration failed at t =" in job["error"]
    assert_error(client.get(f"/jobs/{job['id']}/artifact"), 409, "job_id", "failed")


def test_cancel_a_running_job(client):
    params = {"scene": "long-horizon", "t_end": 10000.0, "samples": 20001, "rtol": 1e-13, "atol": 1e-13}
    job_id = client.post("/jobs", json={"kind": "simulate", "params": params}).json()["id"]
    deadline = time.monotonic() + 60
    while client.get(f"/jobs/{job_id}").json()["status"] == "queued" and time.monotonic() < deadline:
        time.sleep(0.1)
    assert client.get(f"/jobs/{job_id}").json()["status"] == "running"
    assert_error(client.get(f"/jobs/{job_id}/artifact"), 409, "job_id", "running")
    assert client.delete(f"/jobs/{job_id}").json() == {"id": job_id, "cancelled": True, "deleted": True}
    assert_error(client.get(f"/jobs/{job_id}"), 404, "job_id")
    # the runner has a free slot again: a small job still runs
    small = client.post("/jobs", json={"kind": "stability-map", "params": {"grid": 4}}).json()["id"]
    assert wait_job(client.get, small)["status"] == "done"


@pytest.mark.parametrize(
    "params, field, words",
    [
        ({"from": 3.0, "to": 1.0}, "params.to", ("must be greater than from (3)", "got 1")),
        ({"from": 2.0, "to": 2.0}, "params.to", ("must be greater than from (2)",)),
        ({"vary": "kappa", "from": 0.0, "to": 2.0}, "params.from", ("must lie in", "1e-06", "got 0")),
        ({"vary": "J", "from": 1e-7, "to": 1e6}, "params.from", ("must lie in", "1e-06", "got 1e-07")),
        ({"vary": "k", "from": 1.0, "to": 2.0}, "params.vary", ("not a constant of this body",)),
    ],
)
def test_a_family_range_is_checked_when_submitted_in_the_requests_words(client, params, field, words):
    """from > to (and a body constant's range beyond its allowed bounds) is refused at submission, naming
    from/to, never accepted and then failed inside the job as start/stop or J1."""
    before = len(client.get("/jobs").json()["jobs"])
    data = assert_error(client.post("/jobs", json={"kind": "family", "params": params}), 422, field, *words)
    assert "start" not in data["detail"] and "stop" not in data["detail"] and "J1" not in data["detail"]
    assert len(client.get("/jobs").json()["jobs"]) == before


def test_a_job_reports_its_progress_stage_and_times_while_it_runs(client):
    """A scipy integration reports the time it has reached: progress rises in steps while it runs (never
    falls), with what it is doing, the seconds elapsed and an estimate of those left."""
    params = {"scene": "default", "t_end": 800.0, "samples": 801, "method": "DOP853"}
    job_id = client.post("/jobs", json={"kind": "simulate", "params": params}).json()["id"]
    seen = []
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        job = client.get(f"/jobs/{job_id}").json()
        seen.append(job)
        if job["status"] in ("done", "failed"):
            break
        time.sleep(0.05)
    assert job["status"] == "done", job["error"]
    values = [j["progress"] for j in seen]
    assert values == sorted(values)
    running = [j for j in seen if j["status"] == "running" and 0 < j["progress"] < 1]
    assert len({j["progress"] for j in running}) >= 2, values
    assert any((j["stage"] or "").startswith("integrating: t = ") for j in running)
    assert all(j["elapsed"] is not None and j["elapsed"] >= 0 for j in running)
    assert any(j["remaining"] is not None for j in running)
    assert job["elapsed"] > 0 and job["remaining"] is None and job["progress"] == 1.0
    listed = next(j for j in client.get("/jobs").json()["jobs"] if j["id"] == job_id)
    assert listed["elapsed"] == pytest.approx(job["elapsed"]) and "stage" in listed


def test_a_data_dir_of_an_older_service_gets_the_new_columns(tmp_path):
    import sqlite3

    from flatbody_env.service.store import JobStore

    with sqlite3.connect(tmp_path / "jobs.sqlite3") as db:  # the first schema, without `stage`
        db.execute(
            "CREATE TABLE jobs (id TEXT PRIMARY KEY, kind TEXT NOT NULL, params TEXT NOT NULL, status TEXT NOT NULL, "
            "progress REAL NOT NULL DEFAULT 0, result TEXT, error TEXT, artifacts TEXT NOT NULL DEFAULT '[]', "
            "created REAL NOT NULL, started REAL, finished REAL, pid INTEGER)"
        )
        db.execute(
            "INSERT INTO jobs (id, kind, params, status, created) VALUES ('old', 'simulate', '{}', 'queued', 1.0)"
        )
    store = JobStore(tmp_path)
    job = store.get("old")
    assert job["stage"] is None and job["elapsed"] is None and job["status"] == "queued"


@pytest.mark.parametrize(
    "req, status, field",
    [
        ({"kind": "train", "params": {}}, 422, "kind"),
        ({"kind": "stability-map", "params": {"grid": 1000}}, 422, "params.grid"),
        (
            {"kind": "family", "params": {"body": {**DEFAULT_BODY, "thickness": {"a": 0, "b": 1}}}},
            422,
            "params.body.thickness.a",
        ),
        ({"kind": "simulate", "params": {"scene": "default", "t_end": 1e6}}, 413, "params.t_end"),
        ({"kind": "record", "params": {"scene": "nowhere"}}, 422, "params.scene"),
        ({"kind": "evaluate", "params": {"model": "/tmp/evil.zip"}}, 422, "params.model"),
    ],
)
def test_bad_jobs_are_refused_before_they_queue(client, req, status, field):
    before = len(client.get("/jobs").json()["jobs"])
    assert_error(client.post("/jobs", json=req), status, field)
    assert len(client.get("/jobs").json()["jobs"]) == before


def test_unknown_jobs_and_artifacts(client):
    assert_error(client.get("/jobs/0123"), 404, "job_id")
    assert_error(client.delete("/jobs/0123"), 404, "job_id")
    assert_error(client.get("/jobs/0123/artifact"), 404, "job_id")
    job = wait_job(client.get, client.post("/jobs", json={"kind": "stability-map", "params": {"grid": 4}}).json()["id"])
    assert_error(client.get(f"/jobs/{job['id']}/artifact", params={"name": "../jobs.sqlite3"}), 404, "name")


def test_the_page_and_its_files_are_served(client):
    page = client.get("/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    for ref in ('id="find-ellipses"', 'id="start-record"', "/page/page.js", "/page/page.css"):
        assert ref in page.text
    js = client.get("/page/page.js")
    assert js.status_code == 200 and "/ellipses" in js.text and "rerun " in js.text
    assert client.get("/page/page.css").status_code == 200
    doc = client.get("/openapi.json").json()
    assert {
        "/health",
        "/scenes",
        "/methods",
        "/ellipses",
        "/stability",
        "/simulate",
        "/invariants",
        "/jobs",
        "/jobs/{job_id}",
        "/jobs/{job_id}/artifact",
    } <= set(doc["paths"])
    assert client.get("/docs").status_code == 200


def test_the_page_colours_each_variable_as_the_recordings_do(client):
    """One colour per variable: the page's palette is the recordings' and the frames' (rendering.COLORS), set
    by the service as CSS properties; page.js and the ellipse's CSS take theirs from it and name none."""
    import re

    from flatbody_env.env.rendering import COLORS

    page = client.get("/").text
    served = dict(re.findall(r"--color-(\w+): (#[0-9a-f]{6});", page))
    assert served == {name: "#{:02x}{:02x}{:02x}".format(*rgb) for name, rgb in COLORS.items()}
    assert served["lambda"] == "#d62728" and served["mu"] == "#2ca02c"  # λ red, μ green (ϱ blue)
    js = client.get("/page/page.js").text
    assert not re.search(r"#[0-9a-fA-F]{6}\b|rgba?\(", js), "page.js names a colour of its own"
    used = set(re.findall(r'color: "(\w+)"', js))
    assert used == {"lambda", "mu", "rho", "s3", "energy"} and used <= set(COLORS)
    css = client.get("/page/page.css").text
    rules = re.findall(r"svg\.ellipse \.(?:now|axis-line) \{[^}]*\}", css)
    assert len(rules) == 2, rules
    for rule in rules:
        assert "#" not in rule and "rgb" not in rule and "var(--color-" in rule, rule


def test_docs_pages_load_their_scripts_from_the_service(client):
    """/docs (Swagger UI) and /redoc name no outside address: their scripts come from the service."""
    import re

    from flatbody_env.service.app import DOCS_ASSETS

    for page, assets in (("/docs", ("swagger-ui-bundle.js", "swagger-ui.css")), ("/redoc", ("redoc.standalone.js",))):
        html = client.get(page)
        assert html.status_code == 200 and html.headers["content-type"].startswith("text/html")
        assert not re.search(r"(src|href)=[\"']?(https?:)?//", html.text), page  # nothing fetched from elsewhere
        for name in assets:
            assert f"{DOCS_ASSETS}/{name}" in html.text
            got = client.get(f"{DOCS_ASSETS}/{name}")
            assert got.status_code == 200 and len(got.content) > 10_000
    assert "/openapi.json" in client.get("/docs").text
    assert (
        "cdn.redoc.ly" not in client.get(f"{DOCS_ASSETS}/redoc.standalone.js").text
    )  # ReDoc's footer logo, the one outside address


def test_favicon_is_served(client):
    r = client.get("/favicon.ico")
    assert r.status_code == 200 and r.headers["content-type"] == "image/x-icon"
    assert r.content[:4] == b"\x00\x00\x01\x00" and len(r.content) > 500
    assert 'rel="icon"' in client.get("/").text


def test_oversized_chunked_body_is_413(client):
    chunk = b" " * (1 << 20)

    def chunks():  # no content-length: the limit is counted as the body streams in
        for _ in range(DEFAULT_LIMITS.max_trajectory_body_bytes // len(chunk) + 1):
            yield chunk

    r = client.post("/invariants", content=chunks(), headers={"content-type": "application/json"})
    assert_error(r, 413, "body")


def test_a_used_up_integration_budget_is_413_with_when_and_why():
    from flatbody_env.integrators import IntegrationError
    from flatbody_env.service.answers import error_data

    budget = error_data(IntegrationError("wall-clock budget of 60 s used up", t=12.5, method="DOP853", kind="budget"))
    assert budget["kind"] == "too-large" and budget["when"] == 12.5 and "budget" in budget["why"]
    other = error_data(IntegrationError("non-finite state", t=1.0, method="RK4", kind="non-finite"))
    assert other["kind"] == "integration" and other["method"] == "RK4"
    # an answer names the field: the horizon the budget did not reach, the scene whose integration failed
    budget = error_data(
        IntegrationError("wall-clock budget of 60 s used up", t=12.5, method="DOP853", kind="budget"),
        endpoint="simulate",
    )
    assert (
        budget["field"] == "t_end"
        and budget["detail"].startswith("t_end: not reached")
        and "POST /jobs" in budget["detail"]
    )
    other = error_data(
        IntegrationError("non-finite state", t=1.0, method="RK4", kind="non-finite"), endpoint="simulate"
    )
    assert other["field"] == "scene" and other["detail"].startswith("scene: ")


@pytest.mark.parametrize(
    "endpoint, field",
    [
        ("simulate", "scene"),
        ("ellipses", "body"),
        ("stability", "body"),
        ("invariants-json", "trajectory"),
        ("check-job", "params"),
    ],
)
def test_a_computation_that_fails_names_its_input(endpoint, field):
    """No 4xx without a field: a failure no narrower field explains names what the endpoint computes with."""
    from flatbody_env.service.answers import error_data

    for exc in (ZeroDivisionError("float division by zero"), ValueError("singular matrix")):
        data = error_data(exc, endpoint=endpoint)
        assert data["field"] == field and data["detail"].startswith(f"{field}: ") and "\n" not in data["detail"], data
    named = error_data(ValueError("body.params.J: must lie in [1e-06, 1e+06]"), endpoint="ellipses")
    assert named["field"] == "body.params.J"  # a message that names its field keeps it
