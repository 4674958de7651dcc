"""Every ``flatbody`` sub-command runs with a tiny budget, exits 0 and writes output of the expected shape.

The list of commands is read from the parser (:func:`flatbody_env.cli.main.build_parser`): a new
command (or ``bench`` kind) without a case here fails :func:`test_every_command_has_a_smoke_case`.
The heavy ones (training, the integrator studies) carry the ``slow`` mark; their cases still have
to exist.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from flatbody_env.cli.main import build_parser, main

MODEL = str(Path(__file__).resolve().parents[2] / "agents" / "models" / "ppo-FlatBody-v0")


def _commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every leaf command path of the parser, e.g. ("simulate",), ("bench", "env")."""
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                nested = _commands(sub, prefix + (name,))
                out += nested or [prefix + (name,)]
    return out


def _json_out(out: str) -> dict | list:
    return json.loads(out)


def _files(*names):
    def check(tmp: Path, out: str) -> None:
        for name in names:
            path = tmp / name
            assert path.is_file() and path.stat().st_size > 0, name

    return check


def _simulate_check(tmp, out):
    data = _json_out(out)
    assert data["t"] == [0.5, 1.0]
    assert {"state", "energy", "casimir", "p_theta", "initial_state", "meta"} <= set(data)


def _json_keys(*keys):
    def check(tmp, out):
        data = _json_out(out)
        if isinstance(data, list):
            assert data and all(set(keys) <= set(row) for row in data)
        else:
            assert set(keys) <= set(data)

    return check


def _rows(key, *keys):
    def check(tmp, out):
        rows = _json_out(out)[key]
        assert rows and all(set(keys) <= set(row) for row in rows)

    return check


def _contains(text):
    def check(tmp, out):
        assert text in out

    return check


# command path -> (argv after the command, with {tmp} for the case's folder; checker(tmp, stdout); slow?)
CASES = {
    ("simulate",): (["--scene", "default", "--t-end", "1", "--times", "0.5,1"], _simulate_check, False),
    ("scenes",): (["--json"], _json_keys(), False),
    ("methods",): (["--json"], _json_keys("name", "adaptive", "order", "chart"), False),
    ("record",): (
        ["--scene", "default", "--t-end", "0.5", "--samples", "11", "--out", "{tmp}/run.rrd"],
        _files("run.rrd"),
        False,
    ),
    ("record-env",): (
        ["--episodes", "1", "--max-steps", "5", "--policy", "random", "--out", "{tmp}/env.rrd"],
        _files("env.rrd"),
        False,
    ),
    ("record-info",): (["{tmp}/given.rrd", "--no-verify"], _contains("entity"), False),
    ("ellipses",): (
        ["--s3", "2", "--p-theta", "0.5", "--grid", "16", "--json"],
        _rows("solutions", "state", "omega3", "theta_dot", "energy", "residual"),
        False,
    ),
    ("stability",): (
        ["--s3", "2", "--p-theta", "0.5", "--grid", "16", "--json"],
        _rows("solutions", "state", "eigenvalues"),
        False,
    ),
    ("family",): (
        [
            "--vary",
            "s3",
            "--from",
            "1.5",
            "--to",
            "2",
            "--s3",
            "2",
            "--p-theta",
            "0.5",
            "--seeds",
            "2",
            "--grid",
            "16",
            "--out",
            "{tmp}/fam.csv",
            "--plot",
            "{tmp}/fam.png",
            "--json",
        ],
        _files("fam.csv", "fam.png"),
        False,
    ),
    ("stability-map",): (
        ["--grid", "4", "--out", "{tmp}/map.csv", "--plot", "{tmp}/map.png", "--json"],
        _files("map.csv", "map.png"),
        False,
    ),
    ("invariants",): (["{tmp}/given.json", "--json"], _json_keys("samples", "t_end", "drift", "rates"), False),
    ("chart",): (
        [
            "--quick",
            "--repeats",
            "1",
            "--max-run-s",
            "0.2",
            "--methods",
            "RK4",
            "--scenes",
            "regular",
            "--out",
            "{tmp}/chart",
        ],
        _files("chart/work_precision.png"),
        True,
    ),
    ("failure-study",): (
        ["--quick", "--max-run-s", "0.2", "--methods", "RK4", "--studies", "rho", "--out", "{tmp}/fs"],
        _files("fs/failure_study.csv", "fs/failure_study.png"),
        True,
    ),
    ("train",): (
        [
            "--algo",
            "ppo",
            "--n-timesteps",
            "64",
            "--n-envs",
            "1",
            "--hyperparams",
            "n_steps=32",
            "batch_size=32",
            "--checkpoint-freq",
            "0",
            "--no-progress",
            "--out",
            "{tmp}/train",
        ],
        _files("train/model.zip", "train/policy.npz"),
        True,
    ),
    ("curriculum",): (
        [
            "--env",
            "FlatBodySlow-v0",
            "--stages",
            "0.15,0",
            "--min-stage-steps",
            "1",
            "--max-stage-steps",
            "1",
            "--n-timesteps",
            "64",
            "--n-envs",
            "2",
            "--hyperparams",
            "n_steps=16",
            "batch_size=32",
            "n_epochs=1",
            "--checkpoint-freq",
            "0",
            "--no-progress",
            "--out",
            "{tmp}/cur",
        ],
        _files("cur/model.zip", "cur/config.yml", "cur/run.json"),
        True,
    ),
    ("imitate", "plan"): (
        [
            "--model",
            str(Path(MODEL).parent / "ppo-FlatBodySlow-v0"),
            "--seeds",
            "0:1",
            "--knots",
            "2",
            "--samples",
            "2",
            "--iterations",
            "1",
            "--elite",
            "1",
            "--no-progress",
            "--out",
            "{tmp}/plans.npz",
        ],
        _files("plans.npz"),
        True,
    ),
    ("imitate", "distill"): (
        ["--env", "FlatBodyTorque-v1", "--seeds", "0:1", "--rounds", "1", "--epochs", "1"]
        + ["--planner", "samples=2", "horizon=2", "--no-progress", "--out", "{tmp}/dist"],
        _files("dist/model.zip", "dist/config.yml", "dist/policy.npz", "dist/progress.csv"),
        False,
    ),
    ("evaluate",): (
        [MODEL, "--episodes", "1", "--no-baselines", "--json", "--out", "{tmp}/eval.json"],
        _files("eval.json"),
        False,
    ),
    ("demo",): (["--model", MODEL, "--out", "{tmp}/demo.rrd"], _files("demo.rrd"), False),
    ("export-policy",): (
        ["{tmp}/model", "--trust"],
        _files("model/policy.npz"),
        False,
    ),  # a copy outside the trusted folders
    ("bench", "recording"): (
        [
            "--steps",
            "50",
            "--sizes",
            "20",
            "--repeats",
            "1",
            "--block",
            "16",
            "--episode-repeats",
            "1",
            "--out-dir",
            "{tmp}/br",
        ],
        _files("br/recording.json", "br/recording.png"),
        False,
    ),
    ("bench", "env"): (
        [
            "--steps",
            "20",
            "--batch",
            "4",
            "--batch-steps",
            "2",
            "--episode-steps",
            "3",
            "--repeats",
            "1",
            "--out-dir",
            "{tmp}/be",
        ],
        _files("be/env_benchmark.json", "be/env_benchmark.png"),
        True,
    ),
    ("bench", "train"): (
        ["--timesteps", "64", "--hyperparams", "n_envs=2", "n_steps=32", "batch_size=32", "--out-dir", "{tmp}/bt"],
        _files("bt/train_benchmark.json", "bt/train_benchmark.png"),
        False,
    ),
    ("targets-table",): (
        ["--n-lambda", "4", "--n-aspect", "4", "--workers", "1", "--no-progress", "--out", "{tmp}/t.npz"],
        _files("t.npz"),
        False,
    ),
    ("lqr-table",): (
        ["--n-lambda", "2", "--n-w", "2", "--workers", "1", "--out", "{tmp}/k.npz"],
        _files("k.npz"),
        False,
    ),
    ("bench", "integrators"): (
        ["--quick", "--repeats", "1", "--max-run-s", "0.2", "--no-compile", "--out", "{tmp}/bi"],
        _files("bi/bench_integrators.json", "bi/bench_integrators.png"),
        True,
    ),
    ("bench", "service"): (
        ["--clients", "1", "--requests", "2", "--seconds", "2", "--workers", "1", "--out-dir", "{tmp}/bs"],
        _files("bs/service_benchmark.json", "bs/service_benchmark.png"),
        True,
    ),
    ("bench", "gpu"): (
        [
            "--sizes",
            "8,40",
            "--steps",
            "1",
            "--repeats",
            "1",
            "--methods",
            "RK4,DOP853-numba",
            "--out",
            "{tmp}/bg.json",
        ],
        _files("bg.json", "bg.png"),
        False,
    ),
    ("bench", "sweep"): (
        [
            "--grid",
            "4",
            "--chunk",
            "2",
            "--workers",
            "1",
            "--sim-workers",
            "1",
            "--noop-tasks",
            "10",
            "--out",
            "{tmp}/bw",
        ],
        _files("bw/scaling.json", "bw/scaling.csv", "bw/scaling.png"),
        True,
    ),
    ("bench", "compare"): (
        ["HEAD", "--figures", "simulate", "--rounds", "1", "--out-dir", "{tmp}/bc"],
        _files("bc/compare.json", "bc/compare.csv", "bc/compare.png"),
        True,
    ),
    ("sweep", "stability-map"): (
        ["--grid", "4", "--workers", "0", "--no-progress", "--out", "{tmp}/sm", "--json"],
        _json_keys(),
        False,
    ),
    ("sweep", "failure-study"): (
        [
            "--quick",
            "--max-run-s",
            "0.2",
            "--methods",
            "RK4",
            "--studies",
            "rho",
            "--workers",
            "0",
            "--no-progress",
            "--out",
            "{tmp}/sfs",
        ],
        _files("sfs/results.sqlite"),
        True,
    ),
    ("sweep", "family"): (
        [
            "--vary",
            "s3",
            "--ranges",
            "1.5,2",
            "--s3",
            "2",
            "--p-theta",
            "0.5",
            "--seeds",
            "2",
            "--grid",
            "16",
            "--workers",
            "0",
            "--no-progress",
            "--out",
            "{tmp}/sf",
            "--json",
        ],
        _files("sf/results.sqlite"),
        False,
    ),
    ("sweep", "seeds"): (
        [
            "--algo",
            "ppo",
            "--seeds",
            "0",
            "--n-timesteps",
            "64",
            "--n-envs",
            "1",
            "--hyperparams",
            "n_steps=32",
            "batch_size=32",
            "--episodes",
            "1",
            "--workers",
            "0",
            "--no-progress",
            "--out",
            "{tmp}/ss",
            "--json",
        ],
        _files("ss/results.sqlite"),
        True,
    ),
    ("benchmark",): (
        [
            "--algos",
            "ppo",
            "--envs",
            "FlatBody-v1",
            "--seeds",
            "0-1",
            "--budget",
            "ppo=4096",
            "--workers",
            "0",
            "--no-progress",
            "--out",
            "{tmp}/bm",
        ],
        _files("bm/results.sqlite", "bm/benchmark.json", "bm/benchmark.csv", "bm/benchmark_curves.png"),
        True,
    ),
    ("tune",): (
        [
            "--algo",
            "ppo",
            "--trials",
            "1",
            "--n-timesteps",
            "128",
            "--n-envs",
            "2",
            "--evaluations",
            "1",
            "--eval-episodes",
            "1",
            "--hyperparams",
            "n_steps=64",
            "batch_size=64",
            "--storage",
            "{tmp}/journal.log",
            "--out",
            "{tmp}/tune",
            "--json",
        ],
        _json_keys("trials", "best"),
        True,
    ),
}

# commands that cannot run here as a plain call returning 0, and the test that covers each instead
NOT_SMOKED = {
    ("serve",): "serves until stopped: tests/service/test_service_cli.py starts it as a process and talks HTTP",
    (
        "record-shots",
    ): "drives the real rerun viewer under Xvfb: tests/recording/test_viewer.py (skips with a reason without it)",
    ("sweep", "work-precision"): "a timing study refused on purpose (exit 2): tests/sweep/test_sweep_cli.py",
    ("sweep", "chart"): "a timing study refused on purpose (exit 2): tests/sweep/test_sweep_cli.py",
    ("imitate", "clone"): "needs a plans file of a residual agent: tests/agents/test_imitation.py plans and clones one",
}


def test_every_command_has_a_smoke_case():
    commands = set(_commands(build_parser()))
    missing = sorted(" ".join(c) for c in commands - set(CASES) - set(NOT_SMOKED))
    assert not missing, f"commands without a smoke case in tests/cli/test_smoke.py: {missing}"
    assert not (set(CASES) | set(NOT_SMOKED)) - commands, "smoke cases for commands that no longer exist"
    assert not set(CASES) & set(NOT_SMOKED)


@pytest.mark.parametrize("command", [c for c in NOT_SMOKED if c[0] == "sweep"], ids=" ".join)
def test_serial_timing_studies_are_refused_by_sweep(command, capsys):
    assert main(list(command)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "stays serial" in err[0]


@pytest.fixture(scope="module")
def given(tmp_path_factory):
    """A trajectory JSON and a recording made once, read by ``invariants`` and ``record-info``."""
    tmp = tmp_path_factory.mktemp("given")
    assert (
        main(
            [
                "simulate",
                "--scene",
                "default",
                "--t-end",
                "1",
                "--samples",
                "11",
                "--with-rotation",
                "--out",
                str(tmp / "given.json"),
            ]
        )
        == 0
    )
    assert (
        main(["record", "--scene", "default", "--t-end", "0.5", "--samples", "11", "--out", str(tmp / "given.rrd")])
        == 0
    )
    return tmp


@pytest.mark.parametrize(
    "command",
    [pytest.param(c, id=" ".join(c), marks=[pytest.mark.slow] if CASES[c][2] else []) for c in CASES],
)
def test_command_runs(command, tmp_path, given, capsys):
    argv, check, _ = CASES[command]
    for name in ("given.json", "given.rrd"):
        (tmp_path / name).write_bytes((given / name).read_bytes())
    if "{tmp}/model" in argv:  # a copy of the shipped model (export-policy writes beside it)
        import shutil

        shutil.copytree(MODEL, tmp_path / "model", ignore=shutil.ignore_patterns("policy.npz"))
    capsys.readouterr()
    code = main([*command, *(a.replace("{tmp}", str(tmp_path)) for a in argv)])
    out, err = capsys.readouterr()
    assert code == 0, err[-2000:]
    assert "Traceback" not in err
    check(tmp_path, out)
