"""One run folder for every trainer (agents.runs): every algorithm trains on every v1 task and writes the same folder;
``--resume`` reads the task from the folder and refuses another; the printed resume command is complete and works;
``--config FOLDER/config.yml`` trains the same run again, bit for bit."""

from __future__ import annotations

import json
import shlex

import numpy as np
import pytest
import yaml

from agents.config import ALGOS, RunConfig
from agents.runs import KEEP_CHECKPOINTS, RunFolder
from flatbody_env.cli.main import main
from flatbody_env.env.registration import V1_IDS

TINY = {
    "ppo": ["n_envs=2", "n_steps=16", "batch_size=32", "n_epochs=1", "policy_kwargs.net_arch=[8]"],
    "sac": ["n_envs=2", "learning_starts=16", "batch_size=8", "buffer_size=1000", "policy_kwargs.net_arch=[8]"],
    "td3": ["n_envs=2", "learning_starts=16", "batch_size=8", "buffer_size=1000", "policy_kwargs.net_arch=[8]"],
    "rsl-ppo": ["n_envs=4", "num_steps_per_env=8", "num_mini_batches=2", "num_learning_epochs=1", "hidden_dims=[8]"],
}
"""Overrides that make a run of each algorithm a handful of steps."""
STEPS = 64


@pytest.fixture
def config_home(tmp_path, monkeypatch):
    home = tmp_path / "config"
    monkeypatch.setenv("FLATBODY_CONFIG_HOME", str(home))
    return home


def _train(algo, env_id, out, *extra):
    argv = ["train", "--algo", algo, "--env", env_id, "--out", str(out), "--n-timesteps", str(STEPS)]
    return main([*argv, "--no-progress", *extra, "--hyperparams", *TINY[algo]])


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("env_id", V1_IDS)
def test_every_algorithm_trains_on_every_v1_task_into_the_one_run_folder(tmp_path, config_home, algo, env_id):
    from agents.evaluate import Agent, run_episodes

    out = tmp_path / "run"
    assert _train(algo, env_id, out, "--checkpoint-freq", "0") == 0
    files = {p.name for p in out.iterdir()}
    assert {"config.yml", "run.json", "progress.csv", "model.zip", "policy.npz"} <= files
    assert ("rsl_model.pt" in files) == (algo == "rsl-ppo") and ("checkpoints" not in files)
    cfg = yaml.safe_load((out / "config.yml").read_text())
    assert cfg["format"] == 2 and cfg["algo"] == algo and cfg["env_id"] == env_id and cfg["env_version"] == 1
    assert cfg["prior"] is None and cfg["hyperparams"]["n_timesteps"] == STEPS == cfg["n_timesteps"]
    assert cfg["source"] == {"file": f"agents/hyperparams/{algo}.yml", "entry": env_id, "overrides": TINY[algo]}
    run = json.loads((out / "run.json").read_text())
    assert run["env_id"] == env_id and run["algo"] == algo and run["n_timesteps"] >= STEPS
    assert run["machine"]["cpu_count"] >= 1 and run["git_hash"] and run["command_line"] and run["wall_time_s"] >= 0
    assert run["versions"]["torch"] and run["machine"]["git"] == run["git_hash"]
    assert (out / "progress.csv").read_text().count("\n") >= 1
    agent = Agent(out)  # the numpy policy, no pickle
    assert agent.backend == "numpy" and agent.env_id == env_id and agent.residual_action is None
    (rec,) = run_episodes(agent, episodes=1, seed=10_000, env_id=env_id, env_kwargs=agent.env_kwargs)
    assert rec["length"] >= 1 and np.isfinite(rec["return"])


def test_checkpoints_rotate_and_the_folder_is_trusted_from_its_first_file(tmp_path, config_home):
    from agents import numpy_policy as npp

    out = tmp_path / "run"
    argv = ["--n-timesteps", "192", "--checkpoint-freq", "32", "--keep-checkpoints"]
    assert (
        main(["train", "--algo", "ppo", "--out", str(out), "--no-progress", *argv, "--hyperparams", *TINY["ppo"]]) == 0
    )
    kept = RunFolder(path=out).checkpoints()
    assert [c.steps for c in kept] == [192, 160, 128][:KEEP_CHECKPOINTS]
    assert all(c.vecnormalize is not None for c in kept)
    assert npp.trusted(out / "model.zip")
    assert (config_home / "trusted-runs.txt").read_text().splitlines() == [str(out.resolve())]


@pytest.mark.parametrize("algo", ["ppo", "rsl-ppo"])
def test_resuming_a_completed_run_without_checkpoints_says_how_to_keep_them(tmp_path, config_home, capsys, algo):
    out = tmp_path / "run"
    assert _train(algo, "FlatBody-v1", out) == 0
    capsys.readouterr()
    assert main(["train", "--out", str(out), "--resume", "--n-timesteps", "4096", "--no-progress"]) == 2
    line = _one_line(capsys)
    assert line.startswith("flatbody train: error: resume: no checkpoint in ") and "--keep-checkpoints" in line, line


def test_a_new_run_refuses_a_folder_holding_one_and_force_replaces_it(tmp_path, config_home, capsys):
    out = tmp_path / "run"
    assert _train("ppo", "FlatBody-v1", out) == 0
    capsys.readouterr()
    assert _train("sac", "FlatBody-v1", out) == 2
    assert "already holds a training run" in _one_line(capsys)
    assert _train("sac", "FlatBody-v1", out, "--force") == 0
    assert yaml.safe_load((out / "config.yml").read_text())["algo"] == "sac"


@pytest.mark.parametrize("algo", ["ppo", "rsl-ppo"])
def test_resume_reads_the_task_from_the_folder_and_refuses_another(tmp_path, config_home, capsys, algo):
    """``--resume`` continues on the run's own task: a conflicting --env (or --algo) is refused naming it, and without
    --env it continues the task config.yml names, to the larger budget, which config.yml then says."""
    out = tmp_path / "run"
    assert _train(algo, "FlatBodySlow-v1", out, "--checkpoint-freq", "32", "--keep-checkpoints") == 0
    capsys.readouterr()
    for flag, value in (("--env", "FlatBody-v1"), ("--algo", "sac" if algo == "ppo" else "ppo")):
        assert main(["train", flag, value, "--out", str(out), "--resume", "--no-progress"]) == 2
        line = _one_line(capsys)
        assert line.startswith(f"flatbody train: error: {flag}: must be ") and "FlatBodySlow-v1" in line, line
    assert main(["train", "--out", str(out), "--resume", "--hyperparams", "gamma=0.9"]) == 2
    assert "--hyperparams" in _one_line(capsys)
    assert main(["train", "--out", str(out), "--resume", "--n-timesteps", "128", "--no-progress"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["env_id"] == "FlatBodySlow-v1" and run["resumed_from"] == 64 and run["n_timesteps"] >= 128
    assert RunConfig.read(out).n_timesteps == 128


@pytest.mark.parametrize("algo", ["ppo", "sac", "rsl-ppo"])
def test_the_command_printed_after_ctrl_c_is_complete_and_continues_the_run(tmp_path, config_home, capsys, algo,
                                                                             monkeypatch):  # fmt: skip
    """Ctrl-C keeps a checkpoint and prints (exit 130) the whole command that continues the run: its algorithm, its
    task, its folder; run as printed, from another directory, it continues on the same task."""
    out = tmp_path / "run"
    calls = {"n": 0}
    if algo == "rsl-ppo":
        import agents.rsl as rsl

        real = rsl.RslVecEnv.step

        def step(self, actions):
            calls["n"] += 1
            if calls["n"] == 20:
                raise KeyboardInterrupt
            return real(self, actions)

        monkeypatch.setattr(rsl.RslVecEnv, "step", step)
    else:
        import agents.vec_env as ve

        real = ve.FlatBodySB3VecEnv.step_wait

        def step_wait(self):
            calls["n"] += 1
            if calls["n"] == 40:
                raise KeyboardInterrupt
            return real(self)

        monkeypatch.setattr(ve.FlatBodySB3VecEnv, "step_wait", step_wait)
    assert _train(algo, "FlatBodyHoldUnstable-v1", out, "--n-timesteps", "256") == 130
    line = _one_line(capsys)
    assert line.startswith("flatbody train: interrupted (training stopped at "), line
    command = line.split(": ", 2)[-1].removesuffix(" continues)")
    argv = shlex.split(command)
    assert argv[:2] == ["flatbody", "train"] and "--resume" in argv
    assert argv[argv.index("--algo") + 1] == algo and argv[argv.index("--env") + 1] == "FlatBodyHoldUnstable-v1"
    monkeypatch.undo()
    monkeypatch.setenv("FLATBODY_CONFIG_HOME", str(config_home))
    monkeypatch.chdir(tmp_path.parent)
    assert main([*argv[1:], "--no-progress"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["env_id"] == "FlatBodyHoldUnstable-v1" and run["resumed_from"] > 0 and run["n_timesteps"] >= 256


def _policy_arrays(folder):
    with np.load(folder / "policy.npz") as z:
        return {k: z[k] for k in z.files if k != "meta"}


@pytest.mark.parametrize("algo", ALGOS)
def test_config_trains_the_same_run_again_bit_for_bit(tmp_path, config_home, capsys, algo):
    """``flatbody train --config A/config.yml --out B`` reproduces run A: the same algorithm, task, seed and
    hyperparameters, and (one torch thread) the same weights, bit for bit; another seed does not."""
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    assert _train(algo, "FlatBody-v1", a, "--seed", "3") == 0
    assert main(["train", "--config", str(a / "config.yml"), "--out", str(b), "--no-progress"]) == 0
    ca, cb = RunConfig.read(a), RunConfig.read(b)
    assert (ca.algo, ca.env_id, ca.seed, ca.hyperparams) == (cb.algo, cb.env_id, cb.seed, cb.hyperparams)
    pa, pb = _policy_arrays(a), _policy_arrays(b)
    assert pa.keys() == pb.keys() and all(np.array_equal(pa[k], pb[k]) for k in pa)
    assert main(["train", "--config", str(a / "config.yml"), "--out", str(c), "--seed", "4", "--no-progress"]) == 0
    pc = _policy_arrays(c)
    assert not all(np.array_equal(pa[k], pc[k]) for k in pa)
    capsys.readouterr()
    assert main(["train", "--config", str(a / "config.yml"), "--env", "FlatBodySlow-v1", "--out", str(c)]) == 2
    assert _one_line(capsys).startswith("flatbody train: error: --env: must be FlatBody-v1")


def test_evaluate_refuses_another_task_than_the_agents_and_checks_out_first(tmp_path, config_home, capsys):
    out = tmp_path / "run"
    assert _train("ppo", "FlatBodySlow-v1", out) == 0
    capsys.readouterr()
    assert main(["evaluate", str(out), "--env", "FlatBody-v1", "--episodes", "1"]) == 2
    line = _one_line(capsys)
    assert line.startswith("flatbody evaluate: error: --env: must be FlatBodySlow-v1") and "config.yml" in line
    for flag in ("--out", "--out-dir"):  # refused while the arguments are read, before any episode runs
        bad = str(tmp_path / "missing" / "x") if flag == "--out" else str(out / "model.zip")  # no folder; not a folder
        with pytest.raises(SystemExit) as exit_:
            main(["evaluate", str(out), flag, bad])
        assert exit_.value.code == 2
        assert _one_line(capsys).split(": error: ")[1].startswith(f"{flag}: ")
    assert main(["evaluate", str(out), "--env", "FlatBodySlow-v1", "--episodes", "1", "--no-baselines"]) == 0


def test_a_clone_config_is_not_retrained_by_config(tmp_path, config_home, capsys):
    from agents.numpy_policy import MODELS_DIR

    config = RunConfig.read(MODELS_DIR / "ppo-FlatBody-v0")
    folder = RunFolder(path=tmp_path / "clone")
    folder.path.mkdir()
    folder.write_config(config.replace(imitation={"plans": ["p.npz"]}))
    assert main(["train", "--config", str(folder.path / "config.yml"), "--out", str(tmp_path / "o")]) == 2
    assert "imitate clone" in _one_line(capsys)
    folder.write_config(
        config.replace(imitation={"method": "distill"})
    )  # a distilled policy: the command that repeats it
    assert main(["train", "--config", str(folder.path / "config.yml"), "--out", str(tmp_path / "o")]) == 2
    assert "imitate distill --config" in _one_line(capsys)


@pytest.mark.parametrize("algo", ["ppo", "rsl-ppo"])
def test_eval_freq_evaluates_the_policy_on_held_out_episodes_along_the_run(tmp_path, config_home, capsys, algo):
    """``--eval-freq N``: a row of ``evaluations.csv`` each time the run passes a multiple of N (and a line on stderr),
    the success inside its interval; a resumed run evaluates only the marks it had not passed, into its own table. For
    rsl-ppo the last row is the final policy's: ``flatbody evaluate`` of the saved run gives the same figures."""
    import csv

    from agents.evaluate import EVAL_COLUMNS

    out = tmp_path / "run"
    flags = ["--eval-freq", "32", "--eval-episodes", "3", "--eval-seed", "20000", "--checkpoint-freq", "32"]
    assert _train(algo, "FlatBody-v1", out, *flags, "--keep-checkpoints", "--n-timesteps", "128") == 0
    rows = list(csv.DictReader((out / "evaluations.csv").open()))
    assert [int(r["env_steps"]) for r in rows] == [32, 64, 96, 128]
    assert list(rows[0]) == list(EVAL_COLUMNS)
    for r in rows:
        lo, rate, hi = (float(r[k]) for k in ("success_lo", "success_rate", "success_hi"))
        assert 0.0 <= lo <= rate <= hi <= 1.0
        assert int(r["episodes"]) == 3 and float(r["final_distance"]) > 0
    err = capsys.readouterr().err
    assert err.count("flatbody: evaluation at ") == 4 and "on 3 held-out episodes (seeds 20000+)" in err
    if algo == "rsl-ppo":
        assert main(["evaluate", str(out), "--env", "FlatBody-v1", "--episodes", "3", "--seed", "20000",
                     "--no-baselines", "--json"]) == 0  # fmt: skip
        final = json.loads(capsys.readouterr().out)["agent"]
        assert final["success_rate"] == float(rows[-1]["success_rate"])
        assert final["final_distance"] == pytest.approx(float(rows[-1]["final_distance"]), rel=1e-3)
    resumed = ["train", "--out", str(out), "--resume", "--n-timesteps", "192", "--no-progress", *flags[:6]]
    assert main(resumed) == 0
    rows = list(csv.DictReader((out / "evaluations-resumed-128.csv").open()))
    assert [int(r["env_steps"]) for r in rows] == [160, 192]


def test_eval_flags_are_checked_before_anything_runs(tmp_path, config_home, capsys):
    out = tmp_path / "run"
    for flag in ("--eval-seed", "--eval-episodes"):  # nothing to apply them to: refused, not ignored
        assert _train("ppo", "FlatBody-v1", out, flag, "5") == 2
        line = _one_line(capsys)
        assert flag.lstrip("-").replace("-", "_") in line and "--eval-freq" in line, line
    assert not (out / "config.yml").exists()
    assert _train("ppo", "FlatBody-v1", out, "--eval-freq", "1", "--n-timesteps", "1000000000") == 2
    line = _one_line(capsys)  # a million evaluations: refused before any is listed
    assert line.startswith("flatbody train: error: eval_freq: must be an integer (allowed range [1e+06, "), line
    for flag, value in (("--eval-freq", "-1"), ("--eval-episodes", "0")):
        with pytest.raises(SystemExit) as refused:
            _train("ppo", "FlatBody-v1", tmp_path / "other", flag, value)
        assert refused.value.code == 2 and _one_line(capsys).startswith(f"flatbody train: error: {flag}: must be")


@pytest.mark.parametrize("algo", ["sac", "rsl-ppo"])
def test_an_evaluation_that_says_stop_ends_the_run_there(tmp_path, config_home, algo):
    """``HeldOutEvaluations(then=...)`` returning False (a pruner) stops the training at that evaluation; the run is
    saved as a completed one of the steps it reached."""
    from agents.evaluate import HeldOutEvaluations
    from agents.train import train

    seen = []
    evaluations = HeldOutEvaluations("FlatBody-v1", [32, 64, 96], episodes=2, then=lambda p: bool(seen.append(p)))
    overrides = [o for o in TINY[algo] if not o.startswith("n_envs")]
    result = train(algo, tmp_path / "run", env_id="FlatBody-v1", n_timesteps=128, n_envs=4 if algo == "rsl-ppo" else 2,
                   overrides=overrides, checkpoint_freq=0, progress=False, notes=False, evaluations=evaluations)  # fmt: skip
    assert [p["env_steps"] for p in seen] == [32] and evaluations.stop
    assert result.timesteps < 128 and json.loads((tmp_path / "run" / "run.json").read_text())["n_timesteps"] < 128
