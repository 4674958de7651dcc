"""The exported numpy policy: equal to SB3's actions, refused when stale, and no torch in demo/evaluate."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from agents.evaluate import MODELS_DIR, Agent, shipped_model_dir
from agents.numpy_policy import POLICY_FILE, StalePolicyError, export_policy, load_policy

ROOT = Path(__file__).resolve().parents[2]
V0_AGENT = MODELS_DIR / "ppo-FlatBody-v0"
"""A shipped SB3 agent with VecNormalize statistics (whose staleness the round trip checks)."""


@pytest.fixture(scope="module")
def observations():
    """Observations the agent meets (seeded episodes under its own actions) and uniform ones over the whole box."""
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    agent = Agent(backend="numpy")
    env = FlatBodyVectorEnv(num_envs=16)
    obs, _ = env.reset(seed=321)
    seen = [obs]
    for _ in range(60):
        obs, *_ = env.step(agent(obs))
        seen.append(obs)
    space = env.single_observation_space
    uniform = np.random.default_rng(5).uniform(space.low, space.high, size=(1000, space.shape[0])).astype(np.float32)
    return np.concatenate(seen), uniform


def test_shipped_export_is_current_and_equals_sb3(observations):
    pytest.importorskip("stable_baselines3")
    numpy_agent = Agent(backend="numpy")
    sb3_agent = Agent(backend="sb3")
    assert numpy_agent.backend == "numpy" and sb3_agent.backend == "sb3"
    seen, uniform = observations
    # SB3 runs the MLP (16-256-256-128-4) in float32, the export in float64: a few 1e-6 on the agent's own states;
    # uniform over the whole box the normalised inputs reach hundreds of standard deviations and float32's rounding of
    # the large hidden values leaves up to ≈5e-5 (measured) in the output
    for obs, atol in ((seen, 1e-5), (uniform, 1e-4)):
        np.testing.assert_allclose(numpy_agent.policy_actions(obs), sb3_agent.policy_actions(obs), rtol=0, atol=atol)
    # the executed action on observations of real episodes
    final = np.abs(numpy_agent(seen) - sb3_agent(seen)).max()
    assert final <= 1e-5, final


def test_export_roundtrip_and_staleness(tmp_path):
    pytest.importorskip("stable_baselines3")
    model = tmp_path / "model"
    shutil.copytree(V0_AGENT, model, ignore=shutil.ignore_patterns(POLICY_FILE))
    with pytest.raises(StalePolicyError, match="no policy.npz"):
        load_policy(model)
    path = export_policy(model)
    assert path == model / POLICY_FILE
    fresh = load_policy(model)
    shipped = load_policy(V0_AGENT)
    for a, b in zip(fresh.weights, shipped.weights):
        assert np.array_equal(a, b)
    assert fresh.meta["sources"] == shipped.meta["sources"]
    # a retrained model (here: the VecNormalize statistics replaced) is refused, never evaluated stale
    (model / "vecnormalize.pkl").write_bytes((model / "vecnormalize.pkl").read_bytes() + b"\0")
    with pytest.raises(StalePolicyError, match="vecnormalize.pkl changed"):
        load_policy(model)
    with pytest.raises(ValueError, match="flatbody export-policy"):
        Agent(model, backend="numpy")
    # model.zip changed: same
    (model / "vecnormalize.pkl").write_bytes((V0_AGENT / "vecnormalize.pkl").read_bytes())
    assert load_policy(model).meta["sources"] == shipped.meta["sources"]
    (model / "model.zip").write_bytes((model / "model.zip").read_bytes() + b"\0")
    with pytest.raises(StalePolicyError, match="model.zip changed"):
        load_policy(model)


def test_stale_export_falls_back_to_sb3_with_a_note(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    model = tmp_path / "model"
    shutil.copytree(shipped_model_dir(), model)
    meta = load_policy(model).meta
    data = dict(np.load(model / POLICY_FILE))
    meta["sources"]["model.zip"] = "0" * 64
    data["meta"] = np.array(json.dumps(meta))
    np.savez(model / POLICY_FILE, **data)
    agent = Agent(model)
    assert agent.backend == "sb3"
    assert "stale" in capsys.readouterr().err


def test_format_version_is_checked(tmp_path):
    model = tmp_path / "model"
    shutil.copytree(shipped_model_dir(), model)
    data = dict(np.load(model / POLICY_FILE))
    meta = json.loads(str(data["meta"]))
    meta["format"] = 999
    data["meta"] = np.array(json.dumps(meta))
    np.savez(model / POLICY_FILE, **data)
    with pytest.raises(StalePolicyError, match="format 999"):
        load_policy(model)


def test_an_unknown_activation_is_damage_never_a_fallback(tmp_path):
    from agents.numpy_policy import DamagedPolicyError

    model = tmp_path / "model"
    shutil.copytree(shipped_model_dir(), model)
    data = dict(np.load(model / POLICY_FILE))
    meta = json.loads(str(data["meta"]))
    meta["activation"] = "gelu"
    data["meta"] = np.array(json.dumps(meta))
    np.savez(model / POLICY_FILE, **data)
    with pytest.raises(DamagedPolicyError, match="activation: must be one of tanh, relu, elu, got 'gelu'"):
        load_policy(model)


def test_bad_backend_names_the_field():
    with pytest.raises(ValueError, match="backend"):
        Agent(backend="onnx")


@pytest.mark.parametrize("argv", [["demo", "--out", ""], ["evaluate", "--episodes", "2", "--no-baselines", "--json"]])
def test_demo_and_evaluate_do_not_import_torch(argv, tmp_path):
    code = (
        "import sys\n"
        "from flatbody_env.cli.main import main\n"
        f"rc = main({argv!r})\n"
        "bad = sorted(m for m in ('torch', 'stable_baselines3') if m in sys.modules)\n"
        "print('LOADED', bad)\n"
        "sys.exit(rc or (3 if bad else 0))\n"
    )
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    assert "LOADED []" in out.stdout
