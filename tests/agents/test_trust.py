"""Safe model loading: the numpy policy without pickle, a damaged policy.npz is an error (no silent
fall-back), and unpickling from outside the shipped agent and the user's runs needs ``--trust``."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from agents import numpy_policy as npp
from agents.evaluate import Agent, shipped_model_dir
from flatbody_env.cli.main import main


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
        shutil.copy(shipped_model_dir() / f, d / f)
    return d


def test_shipped_agent_loads_without_pickle(config_home):
    npp.require_trust(True)
    agent = Agent()
    assert agent.backend == "numpy" and agent.model is None and agent.vecnormalize is None


def test_damaged_policy_is_an_error_not_a_fallback(tmp_path, config_home):
    d = _copy(tmp_path, "run")
    (d / "policy.npz").write_bytes((shipped_model_dir() / "policy.npz").read_bytes()[:200])
    with pytest.raises(npp.DamagedPolicyError, match="damaged"):
        Agent(d)
    np.savez(d / "policy.npz", meta=np.array([{"x": 1}], dtype=object))  # pickled content is never loaded
    with pytest.raises(npp.DamagedPolicyError, match="allow_pickle"):
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
        ("algo: [x\n", "cannot read"),
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
