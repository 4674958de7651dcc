"""``flatbody train`` and its output folder: it never overwrites a run (or the shipped agent) unless
``--force``; it says when ``--n-timesteps`` rounds up; Ctrl-C keeps a checkpoint that ``--resume``
continues from."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from processes import interrupt

from flatbody_env.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "agents" / "models" / "ppo-FlatBody-v0"
TINY = [
    "--algo",
    "ppo",
    "--n-envs",
    "2",
    "--hyperparams",
    "n_steps=64",
    "batch_size=64",
    "n_epochs=1",
    "--checkpoint-freq",
    "0",
    "--no-progress",
]


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_train_refuses_a_folder_holding_a_run_and_the_shipped_agent(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    default = tmp_path / "runs" / "ppo-FlatBody-v1-seed0"  # where two runs without --out would meet
    default.mkdir(parents=True)
    (default / "model.zip").write_bytes(b"an earlier run")
    # a bad override after the folder: the refusal comes first (and the test never trains for long)
    assert main(["train", "--algo", "ppo", "--hyperparams", "not-an-override"]) == 2
    line = _one_error_line(capsys)
    assert "runs/ppo-FlatBody-v1-seed0" in line and "--force overwrites" in line
    assert (default / "model.zip").read_bytes() == b"an earlier run"

    before = {p.name: p.stat().st_mtime_ns for p in SHIPPED.iterdir()}
    # docs/agents.md's reproducibility command, with the bad override that keeps it from training if it is not refused
    argv = ["train", "--algo", "ppo", "--env", "FlatBody-v0", "--seed", "0", "--out", str(SHIPPED)]
    assert main([*argv, "--hyperparams", "not-an-override"]) == 2
    line = _one_error_line(capsys)
    assert str(SHIPPED) in line and "shipped agent" in line and "--force overwrites" in line
    assert {p.name: p.stat().st_mtime_ns for p in SHIPPED.iterdir()} == before


def test_rounding_up_is_said_and_force_overwrites(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", *TINY, "--n-timesteps", "100", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    notes = [line for line in err.splitlines() if "rounds up" in line]
    assert notes == [
        "flatbody: note: n_timesteps 100 rounds up to 128 (PPO trains whole rollouts of n_envs x n_steps = 2 x 64 = 128 steps)"
    ]
    assert json.loads((out / "run.json").read_text())["n_timesteps"] == 128

    assert main(["train", *TINY, "--n-timesteps", "128", "--out", str(out)]) == 2
    assert "--force" in _one_error_line(capsys)
    (out / "checkpoints").mkdir()
    (out / "checkpoints" / "rl_model_999_steps.zip").write_bytes(b"an old run's")  # would be what --resume continues
    assert main(["train", *TINY, "--n-timesteps", "256", "--out", str(out), "--force"]) == 0
    assert "rounds up" not in capsys.readouterr().err  # a whole rollout: nothing to say
    assert json.loads((out / "run.json").read_text())["n_timesteps"] == 256
    assert not (out / "checkpoints").exists()


@pytest.mark.slow  # two training processes (~10 s)
def test_ctrl_c_keeps_a_checkpoint_that_resume_continues(tmp_path):
    out = tmp_path / "run"
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", FLATBODY_PROGRESS_S="0")
    argv = [
        sys.executable,
        "-m",
        "flatbody_env.cli",
        "train",
        "--algo",
        "ppo",
        "--n-envs",
        "2",
        "--hyperparams",
        "n_steps=64",
        "batch_size=64",
        "n_epochs=1",
        "--out",
        str(out),
    ]
    proc = subprocess.Popen(
        [*argv, "--n-timesteps", "1000000"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    for line in proc.stderr:  # progress lines (FLATBODY_PROGRESS_S=0: one per update)
        if line.startswith("train: ") and int(line.split()[1].split("/")[0]) >= 200:
            break
    _, rest = interrupt(proc)
    assert proc.returncode == 130, rest[-3000:]
    last = rest.strip().splitlines()[-1]
    assert (
        "Traceback" not in rest
        and last.startswith("flatbody train: interrupted (training stopped at ")
        and f"flatbody train --algo ppo --env FlatBody-v1 --out {out} --resume continues" in last
    ), rest
    (kept,) = (out / "checkpoints").glob("rl_model_*_steps.zip")
    steps = int(kept.name.split("_")[2])
    assert steps >= 200 and (out / "checkpoints" / f"rl_model_vecnormalize_{steps}_steps.pkl").exists()
    assert not (out / "model.zip").exists()  # no model of an unfinished run under the final name
    r = subprocess.run(  # the command as printed, with a larger budget
        [*argv[:3], "train", "--out", str(out), "--resume", "--n-timesteps", str(steps + 128), "--no-progress"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert f"resumed from {steps} steps" in r.stdout
    assert json.loads((out / "run.json").read_text())["n_timesteps"] == steps + 128


def test_checkpoints_are_atomic_rotated_and_resume_falls_back_past_a_truncated_one(tmp_path, capsys):
    """The checkpoint callback writes each checkpoint through the writing door and keeps the newest three; a newest
    checkpoint truncated by a crash is passed over by --resume with a one-line note (the next good one continues)."""
    from agents.runs import KEEP_CHECKPOINTS, RunFolder

    out = tmp_path / "run"
    argv = ["train", *TINY[:-3], "--checkpoint-freq", "128", "--no-progress", "--out", str(out)]
    assert main([*argv, "--n-timesteps", "640", "--keep-checkpoints"]) == 0
    kept = RunFolder(path=out).checkpoints()
    assert [c.steps for c in kept] == [640, 512, 384][:KEEP_CHECKPOINTS]
    assert all(c.vecnormalize is not None for c in kept)  # each with its VecNormalize statistics
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == sorted(
        name for s in (384, 512, 640) for name in (f"rl_model_{s}_steps.zip", f"rl_model_vecnormalize_{s}_steps.pkl")
    )  # nothing else: no temporary, no older checkpoint
    newest = out / "checkpoints" / "rl_model_640_steps.zip"
    newest.write_bytes(newest.read_bytes()[:1000])  # a crash while the disk wrote it
    capsys.readouterr()
    assert main([*argv, "--resume", "--n-timesteps", "768"]) == 0
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if "cannot be loaded" in line]
    assert (
        len(notes) == 1 and "rl_model_640_steps.zip" in notes[0] and "resuming from rl_model_512_steps.zip" in notes[0]
    )
    assert "resumed from 512 steps" in captured.out
    assert json.loads((out / "run.json").read_text())["n_timesteps"] == 768
    rows = list(csv.DictReader((out / "resumed-512" / "progress.csv").open()))  # the logger of ours wrote it
    assert [int(r["time/total_timesteps"]) for r in rows] == [640, 768]


def test_progress_csv_is_written_through_the_door_never_through_a_planted_link(tmp_path, capsys):
    """SB3's logger writes progress.csv through a format of ours (atomic, no link followed): a link planted there
    before the run is refused with one line naming the file, and its target is left alone."""
    import os

    out = tmp_path / "run"
    out.mkdir()
    victim = tmp_path / "victim.csv"
    victim.write_text("unchanged\n")
    os.symlink(victim, out / "progress.csv")
    assert main(["train", *TINY, "--n-timesteps", "128", "--out", str(out)]) == 1
    line = _one_error_line(capsys)
    assert "progress.csv" in line and "symbolic link" in line, line
    assert victim.read_text() == "unchanged\n"
    out2 = tmp_path / "run2"
    assert main(["train", *TINY, "--n-timesteps", "256", "--out", str(out2)]) == 0
    rows = list(csv.DictReader((out2 / "progress.csv").open()))
    assert [int(r["time/total_timesteps"]) for r in rows] == [128, 256]
    assert not any(p.name.startswith(".") for p in out2.iterdir())  # no temporary left
