"""CLI bounds and faults: negative numbers in any spelling, a port that cannot be bound, non-finite
invariants, the per-flag upper bounds (docs/reliability.md)."""

from __future__ import annotations

import json
import re
import socket

import pytest

from flatbody_env.cli.main import main
from flatbody_env.integrators import Tolerances


def test_negative_numbers_in_e_notation_are_values(capsys):
    assert main(["ellipses", "--s3", "-2e0", "--p-theta", "-1E+0", "--grid", "10", "--json"]) == 0
    assert main(["ellipses", "--s3", "-.5", "--p-theta", "-1", "--grid", "10", "--json"]) == 0


@pytest.mark.parametrize(
    "argv",
    [
        ["bench", "env", "--batch", "1000000000"],
        ["bench", "env", "--steps", "10000000000"],
        ["simulate", "--scene", "default", "--method", "RK4", "--step", "1e-30"],
        ["simulate", "--scene", "default", "--max-seconds", "1e9"],
        ["sweep", "stability-map", "--out", "x", "--grid", "-5"],
    ],
)
def test_sizes_beyond_the_bounds_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and ("must" in err or "allowed" in err)


def test_serve_exits_2_when_it_cannot_bind(tmp_path, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(["serve", "--data-dir", str(tmp_path / "d"), "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert "port" in err and len(err.strip().splitlines()) == 1


def test_invariants_refuse_non_finite_results(tmp_path, capsys):
    from flatbody_env.simulation import simulate

    d = simulate("default", t_end=0.2, times=[0.0, 0.1, 0.2], with_rotation=True).to_dict()
    d["state"]["mu"] = list(d["state"]["lambda"])  # lambda = mu: the two-polar velocities diverge
    (tmp_path / "eq.json").write_text(json.dumps(d))
    assert main(["invariants", str(tmp_path / "eq.json"), "--json", "--scene", "default"]) == 2
    assert "not finite" in capsys.readouterr().err
    d["state"]["lambda"][1] = 1e-7  # outside the documented range
    (tmp_path / "small.json").write_text(json.dumps(d))
    assert main(["invariants", str(tmp_path / "small.json"), "--json"]) == 2
    assert "trajectory.state.lambda" in capsys.readouterr().err


@pytest.mark.parametrize("extra", [[], ["--with-rotation"]])
def test_compiled_dop853_honours_the_wall_clock_budget(extra, capsys):
    """The clock, not ``max_nfev``, sets the evaluation budget that stops the run: exit 1 with one line saying so, after
    fewer evaluations than ``max_nfev`` (a kernel that ignored the clock ran t_end = 1e6 on to ``max_nfev``). Asserted
    on what the run reports, not on how long it took (the suite runs on shared machines)."""
    assert (
        main(["simulate", "--scene", "default", "--t-end", "1e6", "--max-seconds", "0.5", "--samples", "3", *extra])
        == 1
    )
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "(the wall-clock budget)" in err, err
    used = int(re.search(r"\((\d+) RHS evaluations", err).group(1))
    assert 0 < used < Tolerances().max_nfev, err


def test_compiled_fixed_step_refuses_a_run_predicted_past_the_wall_clock_budget(capsys):
    assert (
        main(
            [
                "simulate",
                "--scene",
                "default",
                "--t-end",
                "4e4",
                "--method",
                "RK4",
                "--step",
                "0.01",
                "--max-seconds",
                "0.2",
                "--samples",
                "3",
            ]
        )
        == 1
    )
    assert "predicted" in capsys.readouterr().err


def test_bench_gpu_backends_are_checked(tmp_path, capsys):
    """``--backends`` names backends; one not here (CUDA on a machine without a GPU) is one line, exit 2."""
    with pytest.raises(SystemExit) as exc:
        main(["bench", "gpu", "--backends", "gpu", "--out", str(tmp_path / "g.json")])
    assert exc.value.code == 2 and "backends" in capsys.readouterr().err
    from flatbody_env.integrators import cuda

    if cuda.is_available():
        pytest.skip("a CUDA GPU is here")
    assert main(["bench", "gpu", "--backends", "cuda", "--sizes", "8", "--out", str(tmp_path / "g.json")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "backends: none of cuda is here" in err
    assert not (tmp_path / "g.json").exists()


def test_bench_gpu_keeps_the_rows_it_measured_when_stopped(tmp_path, capsys, monkeypatch):
    """Each row is written to ``--out`` (marked partial) and printed as it is measured, so that a run stopped by a time
    limit keeps its figures; a completed run replaces the file with the whole report."""
    import json

    import flatbody_env.bench.gpu as gpu

    real = gpu.run

    def stopped(**kw):
        kw["progress"]({"what": "dynamics", "env": "", "backend": "cpu-serial", "method": "RK4", "n": 8,
                        "steps_per_s": 1.5e5, "device_name": "x"})  # fmt: skip
        raise KeyboardInterrupt

    monkeypatch.setattr(gpu, "run", stopped)
    out = tmp_path / "g.json"
    assert main(["bench", "gpu", "--sizes", "8", "--out", str(out)]) == 130  # Ctrl-C, or a time limit's signal
    saved = json.loads(out.read_text())
    assert saved["partial"] and [r["n"] for r in saved["rows"]] == [8]
    assert "dynamics - cpu-serial RK4 N=8: 1.5e+05 body-steps/s" in capsys.readouterr().err
    monkeypatch.setattr(gpu, "run", real)
    assert main(["bench", "gpu", "--sizes", "8", "--steps", "1", "--repeats", "1", "--no-dynamics", "--envs",
                 "FlatBodyTorque-v1", "--backends", "cpu-serial", "--out", str(out)]) == 0  # fmt: skip
    done = json.loads(out.read_text())
    assert "partial" not in done and [(r["env"], r["n"]) for r in done["rows"]] == [("FlatBodyTorque-v1", 8)]


@pytest.mark.parametrize(
    "argv",
    [
        ["bench", "env", "--out-dir"],
        ["bench", "train", "--out-dir"],
        ["bench", "recording", "--out-dir"],
        ["bench", "service", "--out-dir"],
        ["bench", "sweep", "--out"],
        ["bench", "integrators", "--out"],
    ],
)
def test_bench_output_folders_are_checked_before_measuring(argv, tmp_path, capsys):
    """A benchmark's output folder that cannot be one (an existing file, a read-only parent) is refused while the
    arguments are read (exit 2, one line naming the flag), not after minutes of measuring."""
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(SystemExit) as exc:
        main(argv + [str(afile)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and "is not a directory" in err
    assert afile.read_text() == "x"
