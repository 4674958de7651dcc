"""``flatbody sweep``: the same rows serially, on local worker processes and on a real Dask
cluster; resume after SIGKILL; failed tasks recorded; bad input in one line."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import time

import numpy as np
import pytest

from flatbody_env.cli.main import main

MAP = ["--grid", "10", "--lam-range", "1.02,3", "--mu-range", "0.3,3", "--potential", "V1", "--k", "1.3"]
SEEDS = [
    "--algo",
    "ppo",
    "--seeds",
    "0-1",
    "--n-timesteps",
    "128",
    "--n-envs",
    "2",
    "--episodes",
    "3",
    "--hyperparams",
    "n_steps=64",
    "batch_size=64",
]


def _ok(r):
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def test_stability_map_identical_serial_workers_and_cluster(cli, dask_cluster, tmp_path):
    serial = _ok(cli("stability-map", *MAP, "--json"))
    assert len(json.loads(serial)["rows"]) > 10
    modes = {
        "no-dask": ["--workers", "0"],
        "in-process": ["--workers", "1"],
        "2-processes": ["--workers", "2"],
        "cluster": ["--scheduler", dask_cluster],
    }
    for name, mode in modes.items():
        out = _ok(cli("sweep", "stability-map", *MAP, "--chunk", "3", "--out", str(tmp_path / name), *mode, "--json"))
        assert out == serial, name
    # the cluster's tasks ran on the cluster's workers, not in the client
    db = sqlite3.connect(tmp_path / "cluster" / "results.sqlite")
    workers = {w for (w,) in db.execute("SELECT worker FROM rows")}
    assert workers and all(w.startswith("tcp://127.0.0.1:") for w in workers)


@pytest.mark.slow  # trains agents: a training check (pytest -m slow)
def test_two_seed_training_sweep_identical_everywhere(cli, dask_cluster, tmp_path):
    runs = {}
    for name, mode in {
        "serial": ["--workers", "0"],
        "2-processes": ["--workers", "2"],
        "cluster": ["--scheduler", dask_cluster],
    }.items():
        runs[name] = json.loads(_ok(cli("sweep", "seeds", *SEEDS, "--out", str(tmp_path / name), *mode, "--json")))
    rows = runs["serial"]["rows"]
    assert [r["seed"] for r in rows] == [0, 1]
    assert runs["2-processes"] == runs["serial"] and runs["cluster"] == runs["serial"]
    for name in runs:
        for seed in (0, 1):
            assert (tmp_path / name / "models" / f"seed-{seed}" / "model.zip").exists()
    # the seed is the key's: two seeds train two different networks
    a, b = ((tmp_path / "serial" / "models" / f"seed-{s}" / "model.zip").read_bytes() for s in (0, 1))
    assert a != b
    # the summary is mean ± sample std over the seeds
    s = runs["serial"]["summary"]["final_distance"]
    fd = np.array([r["final_distance"] for r in rows])
    assert s["mean"] == pytest.approx(fd.mean()) and s["std"] == pytest.approx(fd.std(ddof=1)) and s["n"] == 2
    # a row is the evaluation 'flatbody evaluate' gives for that model on the same episodes
    ev = json.loads(
        _ok(
            cli(
                "evaluate",
                str(tmp_path / "serial" / "models" / "seed-1"),
                "--episodes",
                "3",
                "--seed",
                "10000",
                "--no-baselines",
                "--json",
            )
        )
    )
    assert {k: v for k, v in rows[1].items() if k not in ("seed", "model")} == ev["agent"]


def _count(db_path) -> int:
    if not db_path.exists():
        return 0
    try:
        with sqlite3.connect(db_path, timeout=5) as db:
            return db.execute("SELECT COUNT(*) FROM rows").fetchone()[0]
    except sqlite3.OperationalError:  # the table is not created yet
        return 0


@pytest.mark.slow  # resuming is also tested after Ctrl-C (test_sweep_interrupt.py)
def test_killed_sweep_resumes_without_duplicate_or_loss(cli, spawn, tmp_path):
    args = ["--grid", "40", "--chunk", "1"]
    out = tmp_path / "map"
    proc = spawn("sweep", "stability-map", *args, "--out", str(out), "--workers", "1", "--no-progress")
    db_path = out / "results.sqlite"
    deadline = time.monotonic() + 300
    while _count(db_path) < 3:
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline, "the sweep stored no rows in time"
        time.sleep(0.1)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    with sqlite3.connect(db_path) as db:
        before = dict(db.execute("SELECT key, finished_utc FROM rows"))
    assert 3 <= len(before) < 40
    r = cli("sweep", "stability-map", *args, "--out", str(out), "--workers", "1")
    assert r.returncode == 2 and "--resume" in r.stderr  # no silent restart over a stored sweep
    resumed = _ok(cli("sweep", "stability-map", *args, "--out", str(out), "--workers", "1", "--resume", "--json"))
    assert resumed == _ok(cli("stability-map", *args[:2], "--json"))
    with sqlite3.connect(db_path) as db:
        after = dict(db.execute("SELECT key, finished_utc FROM rows"))
        n, distinct = db.execute("SELECT COUNT(*), COUNT(DISTINCT key) FROM rows").fetchone()
    assert n == distinct == 40
    assert all(after[k] == v for k, v in before.items())  # rows stored before the kill were not run again


@pytest.mark.slow  # a long equality/training check (pytest -m slow); shorter ones of the same path run by default
def test_failure_study_rows_match_serial(cli, tmp_path):
    methods = ["--methods", "RK4", "DOP853-numba"]
    serial = json.loads(
        _ok(cli("failure-study", "--studies", "gap", "--quick", *methods, "--out", str(tmp_path / "s"), "--json"))
    )
    swept = json.loads(
        _ok(
            cli(
                "sweep",
                "failure-study",
                "--studies",
                "gap",
                "--quick",
                *methods,
                "--out",
                str(tmp_path / "p"),
                "--workers",
                "2",
                "--json",
            )
        )
    )
    strip = lambda rows: [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]  # noqa: E731  (timings differ)
    assert strip(swept["rows"]) == strip(serial["rows"])
    assert [r["method"] for r in serial["rows"]] == ["RK4"] * 4 + ["DOP853-numba"] * 4


def test_failing_family_is_recorded_and_the_sweep_goes_on(cli, tmp_path):
    # 'k' is a constant of V1 only: the V3 family fails, the V1 family is computed
    args = ["--bodies", "V1:k=1", "V3:kappa=1", "--vary", "k", "--ranges", "0.5,1.5", "--seeds", "2", "--grid", "40"]
    r = cli("sweep", "family", *args, "--out", str(tmp_path / "f"), "--workers", "0", "--json")
    assert r.returncode == 1 and "1 of 2 tasks failed" in r.stderr
    data = json.loads(r.stdout)
    assert [e["key"] for e in data["errors"]] == ["001-00-000"] and "not a constant" in data["errors"][0]["error"]
    (row,) = data["rows"]
    assert row["body"] == "V1:k=1" and (tmp_path / "f" / row["csv"]).exists()
    serial = json.loads(
        _ok(
            cli(
                "family",
                "--potential",
                "V1",
                "--k",
                "1",
                "--vary",
                "k",
                "--from",
                "0.5",
                "--to",
                "1.5",
                "--seeds",
                "2",
                "--grid",
                "40",
                "--json",
            )
        )
    )
    assert {k: v for k, v in row.items() if k not in ("body", "csv")} == {k: v for k, v in serial.items() if k != "csv"}


@pytest.mark.parametrize(
    "argv,field",
    [
        (["sweep", "stability-map", "--grid", "3", "--out", "X"], "--grid"),
        (["sweep", "stability-map", "--grid", "10", "--chunk", "11", "--out", "X"], "--chunk"),
        (["sweep", "stability-map", "--scheduler", "localhost", "--out", "X"], "scheduler"),
        (["sweep", "stability-map", "--workers", "2", "--scheduler", "tcp://h:1", "--out", "X"], "--scheduler"),
        (["sweep", "seeds", "--algo", "ppo", "--seeds", "5-2", "--out", "X"], "seeds"),
        (["sweep", "family", "--vary", "q", "--out", "X"], "--vary"),
        (["sweep", "family", "--bodies", "V4:k=1", "--out", "X"], "bodies"),
        (["sweep", "work-precision", "--workers", "4"], "stays serial"),
        (["sweep", "stability-map", "--out", "X", "--resume"], "resume"),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, tmp_path, monkeypatch, argv, field):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(argv))
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert field in err and err.count("\n") == 1 and "Traceback" not in err
