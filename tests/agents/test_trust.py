"""Safe model loading: the numpy policy without pickle, a damaged policy.npz is an error (no silent
fall-back), and unpickling from outside the shipped agent and the user's runs needs ``--trust``."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from agents import numpy_policy as npp
from agents.evaluate import MODELS_DIR, Agent
from flatbody_env.cli.main import main

V0_AGENT = MODELS_DIR / "ppo-FlatBody-v0"
"""A shipped SB3 agent with VecNormalize statistics (the pickles these tests plant and refuse)."""


@pytest.fixture
def config_home(tmp_path, monkeypatch):
    monkeypatch.setenv("FLATBODY_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.delenv("FLATBODY_TRUSTED_DIRS", raising=False)
    yield tmp_path / "config"
    npp.require_trust(False)


def _copy(tmp_path, name, files=("model.zip", "config.yml", "vecnormalize.pkl", "policy.npz")):
    d = tmp_path / name
    d.mkdir()
    for f in files:
        shutil.copy(V0_AGENT / f, d / f)
    return d


def test_shipped_agent_loads_without_pickle(config_home):
    npp.require_trust(True)
    agent = Agent()
    assert agent.backend == "numpy" and agent.model is None and agent.vecnormalize is None


def test_damaged_policy_is_an_error_not_a_fallback(tmp_path, config_home):
    d = _copy(tmp_path, "run")
    (d / "policy.npz").write_bytes((V0_AGENT / "policy.npz").read_bytes()[:200])
    with pytest.raises(npp.DamagedPolicyError, match="damaged"):
        Agent(d)
    np.savez(d / "policy.npz", meta=np.array([{"x": 1}], dtype=object))  # pickled content is never loaded
    with pytest.raises(npp.DamagedPolicyError, match="Python objects"):
        npp.load_policy(d)


def test_unpickling_outside_trusted_folders_needs_trust(tmp_path, config_home, capsys):
    d = _copy(
        tmp_path, "foreign", ("model.zip", "config.yml", "vecnormalize.pkl")
    )  # no policy.npz: only SB3 could load it
    assert main(["evaluate", str(d), "--episodes", "1", "--no-baselines"]) == 2
    assert "--trust" in capsys.readouterr().err
    assert main(["export-policy", str(d)]) == 2
    npp.remember_run(d)  # one of this user's runs (flatbody train records them)
    assert npp.trusted(d) and npp.trusted(d / "sub")
    npp.require_trust(True)
    npp.check_trusted(d, "model.zip")  # no error now


def test_env_var_trusted_dirs(tmp_path, config_home, monkeypatch):
    monkeypatch.setenv("FLATBODY_TRUSTED_DIRS", str(tmp_path / "mine"))
    assert npp.trusted(tmp_path / "mine" / "run1") and not npp.trusted(tmp_path / "other")


@pytest.mark.parametrize(
    "text,match",
    [
        ("- a\n- b\n", "mapping"),
        ("algo: [x\n", "not valid YAML"),
        ("hyperparams: 3\n", "hyperparams"),
        ("algo: 5\n", "algo"),
    ],
)
def test_bad_config_yml_is_one_line(tmp_path, config_home, text, match, capsys):
    d = _copy(tmp_path, "run", ("model.zip", "policy.npz"))
    (d / "config.yml").write_text(text)
    assert main(["evaluate", str(d), "--episodes", "1", "--no-baselines"]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1


def test_empty_model_zip_with_trust_is_one_line(tmp_path, config_home, capsys):
    d = _copy(tmp_path, "run", ("config.yml",))
    (d / "model.zip").write_bytes(b"")
    assert main(["evaluate", str(d), "--trust", "--episodes", "1", "--no-baselines"]) == 2
    assert "empty" in capsys.readouterr().err


# -- trust only the user grants -----------------------------------------------------------------------------------
class _Payload:
    """Unpickling it creates ``marker`` (``open(marker, "w")``): a stand-in for code a planted pickle runs."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _payload_zip(path, marker):
    """An SB3-looking ``model.zip`` whose ``data`` holds a cloudpickled payload (SB3 unpickles it on load)."""
    import base64
    import json
    import pickle
    import zipfile

    blob = base64.b64encode(pickle.dumps(_Payload(marker))).decode()
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("data", json.dumps({"policy_class": {":type:": "<class>", ":serialized:": blob}}))


def _planted(tmp_path, name="planted"):
    """A foreign model folder whose every pickle runs a payload; (folder, marker)."""
    import pickle

    marker = tmp_path / f"{name}-RAN"
    d = tmp_path / name
    (d / "checkpoints").mkdir(parents=True)
    shutil.copy(V0_AGENT / "config.yml", d / "config.yml")
    _payload_zip(d / "model.zip", marker)
    (d / "vecnormalize.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    _payload_zip(d / "checkpoints" / "rl_model_128_steps.zip", marker)
    (d / "checkpoints" / "rl_model_vecnormalize_128_steps.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    return d, marker


def _plans(tmp_path):
    from agents.imitation import Plans

    p = tmp_path / "plans.npz"
    Plans(
        env_id="FlatBody-v0", model="m", seeds=np.array([1]), final_distance=np.zeros(1), knots=np.zeros((1, 2, 4))
    ).save(p)
    return p


def _loading_paths(d, tmp_path):
    """Every command that loads a pickle: (argv, the field its refusal names, runner)."""
    out = str(tmp_path / "new")
    return {
        "evaluate": (["evaluate", str(d), "--episodes", "1", "--no-baselines"], "model", "flatbody"),
        "evaluate --env": (["evaluate", str(d), "--env", "FlatBody-v0", "--episodes", "1"], "model", "flatbody"),
        "demo": (["demo", "--model", str(d), "--out", ""], "model", "flatbody"),
        "record --agent": (["record", "--agent", str(d), "--out", str(tmp_path / "a.rrd")], "model", "flatbody"),
        "export-policy": (["export-policy", str(d)], "model", "flatbody"),
        "train --resume": (
            ["train", "--algo", "ppo", "--resume", "--out", str(d), "--no-progress"],
            "resume",
            "flatbody",
        ),
        "train --trained-agent": (
            ["train", "--algo", "ppo", "--trained-agent", str(d), "--out", out, "--no-progress"],
            "trained_agent",
            "flatbody",
        ),
        "imitate plan": (
            ["imitate", "plan", "--model", str(d), "--seeds", "0:1", "--out", str(tmp_path / "p.npz")],
            "model",
            "flatbody",
        ),
        "imitate clone": (
            ["imitate", "clone", "--plans", str(_plans(tmp_path)), "--model", str(d), "--out", out],
            "model",
            "flatbody",
        ),
        "curriculum --trained-agent": (
            ["curriculum", "--env", "FlatBody-v0", "--out", out, "--stages", "0.1", "--trained-agent", str(d)],
            "trained_agent",
            "flatbody",
        ),
    }


def _run(runner, argv):
    return {"flatbody": main}[runner](argv)


@pytest.mark.parametrize(
    "path",
    [
        "evaluate",
        "evaluate --env",
        "demo",
        "record --agent",
        "export-policy",
        "train --resume",
        "train --trained-agent",
        "imitate plan",
        "imitate clone",
        "curriculum --trained-agent",
    ],
)
def test_a_planted_pickle_is_refused_on_every_loading_path(tmp_path, config_home, capsys, path):
    """A pickle planted in a foreign folder never runs without --trust, whichever command would load it: exit 2,
    one line naming the field, and the payload's marker never appears; the new run folder is not trusted."""
    d, marker = _planted(tmp_path)
    argv, field, runner = _loading_paths(d, tmp_path)[path]
    assert _run(runner, argv) == 2
    err = _one_line(capsys)
    assert f"{field}: " in err and "--trust" in err and "unpickles" in err, err
    assert not marker.exists()
    assert not npp.trusted(tmp_path / "new") and not (tmp_path / "new" / "config.yml").exists()


def test_the_payload_is_live_so_the_refusal_is_what_stops_it(tmp_path, config_home, capsys):
    """The control of the test above: with --trust the same folders do unpickle, and the payload runs (model.zip's
    on evaluate; vecnormalize.pkl's beside a real model.zip)."""
    d, marker = _planted(tmp_path)
    assert main(["evaluate", str(d), "--trust", "--episodes", "1", "--no-baselines"]) == 2  # not a real model after
    assert marker.exists()
    capsys.readouterr()
    d2, marker2 = _planted(tmp_path, "planted-vn")
    shutil.copy(V0_AGENT / "model.zip", d2 / "model.zip")
    assert main(["evaluate", str(d2), "--trust", "--backend", "sb3", "--episodes", "1", "--no-baselines"]) == 2
    assert marker2.exists()


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_a_refused_run_trusts_nothing(tmp_path, config_home, monkeypatch, capsys):
    """``flatbody train --out . --hyperparams n_steps=abc`` is refused before the run writes its first file, so the
    folder (and every pickle planted below it) stays untrusted; so does a refused rsl-ppo run."""
    d, marker = _planted(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert main(["train", "--algo", "ppo", "--out", ".", "--hyperparams", "n_steps=abc", "--no-progress"]) == 2
    _one_line(capsys)
    assert main(["train", "--algo", "rsl-ppo", "--out", ".", "--hyperparams", "nope=1", "--no-progress"]) == 2
    _one_line(capsys)
    assert not npp.trusted(tmp_path) and not npp.trusted(d)
    assert not (config_home / "trusted-runs.txt").exists()
    assert main(["evaluate", str(d), "--episodes", "1", "--no-baselines"]) == 2
    assert not marker.exists()


def test_a_run_is_trusted_once_its_first_file_is_written(tmp_path, config_home, monkeypatch):
    """The run's folder is recorded right after ``config.yml`` is in place (before the training itself)."""
    from agents import runs as runs_mod
    from agents import train as train_mod

    seen = []
    real = runs_mod.atomic_write

    def spy(path, data, **kw):
        out = real(path, data, **kw)
        seen.append((path.name, npp.trusted(path.parent)))
        return out

    monkeypatch.setattr(runs_mod, "atomic_write", spy)
    tiny = ["n_envs=2", "n_steps=16", "batch_size=32", "n_epochs=1", "policy_kwargs.net_arch=[8]"]
    train_mod.train("ppo", tmp_path / "run", n_timesteps=32, overrides=tiny, progress=False, checkpoint_freq=0)
    assert seen[0] == ("config.yml", False)  # not trusted before its first file ...
    assert npp.trusted(tmp_path / "run")  # ... and trusted once it is written
    assert (config_home / "trusted-runs.txt").read_text().splitlines() == [str((tmp_path / "run").resolve())]


def test_root_home_and_its_parents_are_never_trusted(tmp_path, config_home, monkeypatch, capsys):
    home = tmp_path / "home" / "user"
    home.mkdir(parents=True)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setattr(npp, "_homes", lambda: {home.resolve()})
    for folder in ("/", home, home.parent, tmp_path):
        with pytest.raises(ValueError, match=r"^out: .*never trusted"):
            npp.remember_run(folder)
    npp.remember_run(home / "runs" / "a")  # a folder of its own below the home folder is fine
    assert npp.trusted(home / "runs" / "a" / "model.zip") and not npp.trusted(home / "runs" / "b")
    with pytest.raises(ValueError, match="line break"):
        npp.remember_run(str(home / "x\n/"))
    # entries an earlier version wrote, or FLATBODY_TRUSTED_DIRS, naming / or the home folder are ignored
    with (config_home / "trusted-runs.txt").open("a") as fh:
        fh.write(f"/\n{home}\nrelative/folder\n")
    monkeypatch.setenv("FLATBODY_TRUSTED_DIRS", f"/{__import__('os').pathsep}{home.parent}")
    assert not npp.trusted(home / "elsewhere") and not npp.trusted("/etc")
    # the run itself refuses such an --out with one line naming out, before it writes anything
    for out in ("/", str(home)):
        assert main(["train", "--algo", "ppo", "--out", out, "--n-timesteps", "1", "--no-progress"]) == 2
        line = _one_line(capsys)
        assert line.startswith("flatbody train: error: out: ") and "folder of its own" in line, line
    assert not (home / "config.yml").exists()


def test_a_planted_link_or_fifo_as_the_trust_list_is_never_followed(tmp_path, config_home, capsys):
    """The list of trusted folders is read and appended through the doors: a FIFO in its place is not read (no
    hang) and a link in its place is not written through (the run says so in one note and goes on)."""
    import os

    config_home.mkdir(parents=True)
    os.mkfifo(config_home / "trusted-runs.txt")
    assert not npp.trusted(tmp_path)
    os.remove(config_home / "trusted-runs.txt")
    victim = tmp_path / "victim.txt"
    victim.write_text("unchanged\n")
    os.symlink(victim, config_home / "trusted-runs.txt")
    assert npp.remember_run(tmp_path / "run") is False
    assert "not recorded as trusted" in _one_line(capsys)
    assert victim.read_text() == "unchanged\n"
