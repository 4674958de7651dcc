"""simulate / load_scene / the CLI: shapes, stationary ellipse, failures and bad input."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from flatbody_env import IntegrationError, SceneError, STATE_NAMES, builtin_scenes, load_scene, simulate
from flatbody_env.cli.main import main
from flatbody_env.physics.kinematics import green_rate


def test_v1_closed_form_stationary_ellipse_stays_stationary():
    """NOTES §6: (λ+μ)⁴ = σ₊²/(kJ), (λ−μ)⁴ = σ₋²/(kJ), ϱ* = (a/b)^{1/3}; eqs. (52)–(54)."""
    k, J, a, b, s3, pt = 1.7, 0.8, 1.3, 0.9, 2.0, 0.7
    sp, sm = s3 + pt, s3 - pt
    u = (sp**2 / (k * J)) ** 0.25
    v = (sm**2 / (k * J)) ** 0.25
    state = dict(s1=0.0, s2=0.0, s3=s3, p_theta=pt, p_lambda=0.0, p_mu=0.0, p_rho=0.0, theta=0.4)
    state.update({"lambda": (u + v) / 2, "mu": (u - v) / 2, "rho": (a / b) ** (1 / 3)})
    scene = {
        "params": {"J": J, "J3": 0.6},
        "potential": {"name": "V1", "k": k},
        "thickness": {"a": a, "b": b},
        "state": state,
    }
    run = simulate(scene, t_end=50.0, rtol=1e-12, atol=1e-12)
    for name in ("lambda", "mu", "rho", "s1", "s2", "s3", "p_lambda", "p_mu", "p_rho"):
        assert np.ptp(run.state[name]) < 1e-9, name
    # θ̇ and ω3 constant: ω3 = ½√(k/J)(sgn σ₊ + sgn σ₋) = √(k/J) here, θ̇ = 0 (rigid rotation)
    np.testing.assert_allclose(np.diff(run.state["theta"]), 0.0, atol=1e-9)
    # G rotates only if θ̇ ≠ 0: at this rigid-rotation ellipse dG/dt = 0; the dual (s3 ↔ p_θ) has θ̇ = √(k/J)
    dual = dict(state, s3=pt, p_theta=s3)
    run2 = simulate(dict(scene, state=dual), t_end=10.0, rtol=1e-12, atol=1e-12)
    theta_dot = np.polyfit(run2.t, run2.state["theta"], 1)[0]
    assert math.isclose(abs(theta_dot), math.sqrt(k / J), rel_tol=1e-9)
    Gd = green_rate(dual["lambda"], dual["mu"], dual["rho"], 0.3, theta_dot)
    assert np.abs(Gd).max() > 0.1 and np.ptp(run2.state["lambda"]) < 1e-9


def test_trajectory_shape_and_json():
    run = simulate("default", t_end=2.0, times=[0.5, 1.0, 2.0])
    assert run.t.tolist() == [0.5, 1.0, 2.0]  # exactly the requested times (scipy's t_eval convention)
    assert set(run.state) == set(STATE_NAMES) and all(v.shape == (3,) for v in run.state.values())
    # the rows equal those of a run that also asks for t = 0; the initial state is metadata
    with_zero = simulate("default", t_end=2.0, times=[0.0, 0.5, 1.0, 2.0])
    assert with_zero.t.tolist() == [0.0, 0.5, 1.0, 2.0]
    for name in STATE_NAMES:
        np.testing.assert_allclose(run.state[name], with_zero.state[name][1:], rtol=0, atol=1e-12)
        assert run.initial_state[name] == with_zero.state[name][0] == load_scene("default").state[name]
    assert run.initial_energy == pytest.approx(with_zero.energy[0], abs=1e-14)
    assert run.drift()["energy"] == pytest.approx(with_zero.drift()["energy"], abs=1e-14)
    d = run.to_dict()
    assert {"t", "state", "energy", "casimir", "p_theta", "meta"} <= set(d)
    json.dumps(d)
    assert run.rotation is None
    assert simulate("default", t_end=1.0, with_rotation=True).rotation.shape == (101, 3, 3)


def test_builtin_scenes_load_and_round_trip():
    scenes = builtin_scenes()
    assert {
        "default",
        "regular",
        "close-approach",
        "small-rho-bounce",
        "long-horizon",
        "stationary-v1",
        "anisotropic",
        "crossing",
    } <= set(scenes)
    for sc in scenes.values():
        again = load_scene(sc.to_dict())
        assert again.state == sc.state and again.body == sc.body


@pytest.mark.parametrize(
    "patch, field",
    [
        ({"params": {"J": -1.0, "J3": 1.0}}, "params.J"),
        ({"params": {"J": 1.0}}, "params.J3"),
        ({"params": {"J1": 1.0, "J2": 0.0, "J3": 1.0}}, "params.J2"),
        ({"potential": {"name": "V4"}}, "potential.name"),
        ({"potential": {"name": "V2", "c": 1.0}}, "potential.d"),
        ({"potential": {"name": "V3", "kappa": float("nan")}}, "potential.kappa"),
        ({"thickness": {"a": 1.0, "b": -2.0}}, "thickness.b"),
        ({"bogus": 1}, "scene.bogus"),
        ({"state": {"lambda": 0.0}}, "state.lambda"),
        ({"state": {"rho": -1.0}}, "state.rho"),
        ({"state": {"mu": 1.4}}, "state.lambda"),  # λ = μ exactly
        ({"state": {"s1": float("inf")}}, "state.s1"),
        ({"state": {"extra": 1.0}}, "state.extra"),
        ({"state": {"theta": None}}, "state.theta"),
    ],
)
def test_bad_scenes_name_the_field(patch, field):
    data = load_scene("default").to_dict()
    for key, value in patch.items():
        if key == "state":
            data["state"] = dict(data["state"], **value)
        else:
            data[key] = value
    with pytest.raises(SceneError, match=field.replace(".", r"\.")):
        load_scene(data)


def test_missing_state_field():
    data = load_scene("default").to_dict()
    del data["state"]["p_mu"]
    with pytest.raises(ValueError, match=r"state\.p_mu: missing"):
        load_scene(data)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"t_end": -1.0}, "t_end"),
        ({"t_end": 1.0, "rtol": 0.0}, "rtol"),
        ({"t_end": 1.0, "times": [0.5, 0.2]}, "times"),
        ({"t_end": 1.0, "method": "nope"}, "method"),
        ({"t_end": 1.0, "model": "polar"}, "model"),
        ({"t_end": 1.0, "step": 0.1}, "step"),
    ],
)
def test_bad_simulate_arguments(kwargs, field):
    with pytest.raises(ValueError, match=field):
        simulate("default", **kwargs)


def test_collapse_is_reported_with_time_and_reason():
    """V1 has no barrier (NOTES E10): μ(t) = μ0 cos t − sin t reaches 0 at t = atan(μ0) (J = k = 1, s = p_θ = 0)."""
    mu0 = 0.5
    state = dict(s1=0.0, s2=0.0, s3=0.0, p_theta=0.0, p_lambda=0.0, p_mu=-1.0, p_rho=0.0, theta=0.0)
    state.update({"lambda": 1.0, "mu": mu0, "rho": 1.0})
    scene = {
        "params": {"J": 1.0, "J3": 1.0},
        "potential": {"name": "V1", "k": 1.0},
        "thickness": {"a": 1.0, "b": 1.0},
        "state": state,
    }
    # scipy's DOP853 locates the collapse with an event at the exact time
    with pytest.raises(IntegrationError) as info:
        simulate(scene, t_end=5.0, model="two-polar", method="DOP853")
    assert info.value.kind == "domain" and "mu" in info.value.reason
    assert math.isclose(info.value.t, math.atan(mu0), rel_tol=1e-6)
    # the default (method="auto": the compiled DOP853) detects it in the step that crosses it
    with pytest.raises(IntegrationError) as info:
        simulate(scene, t_end=5.0, model="two-polar")
    assert info.value.kind == "domain" and info.value.method == "DOP853-numba"
    assert math.atan(mu0) <= info.value.t <= math.atan(mu0) + 5.0 / 100


def test_chart_failure_detected_not_returned():
    """A coarse tolerance on the close approach in the two-polar chart: crossing λ = μ is caught."""
    with pytest.raises(IntegrationError) as info:
        simulate(
            "close-approach", t_end=20.0, method="RK23", rtol=1e-2, atol=1e-2, model="two-polar", energy_tol=math.inf
        )
    assert info.value.kind in {"chart-singularity", "step-collapse", "non-finite"}


def test_cli_simulate_json(tmp_path, capsys):
    assert main(["simulate", "--scene", "default", "--t-end", "1", "--times", "0.25,0.5,1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["t"] == [0.25, 0.5, 1.0]  # exactly the requested times; t = 0 only via --times 0,...
    assert set(out["state"]) == set(STATE_NAMES) and len(out["energy"]) == 3 and len(out["casimir"]) == 3
    assert out["initial_state"] == load_scene("default").state
    scene_file = tmp_path / "s.json"
    scene_file.write_text(json.dumps(load_scene("default").to_dict()))
    target = tmp_path / "out.json"
    assert main(["simulate", str(scene_file), "--t-end", "0.5", "--out", str(target)]) == 0
    assert len(json.loads(target.read_text())["t"]) == 101


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["simulate", "--scene", "nope"], "no built-in scene"),
        (["simulate", "--scene", "default", "--t-end", "-2"], "--t-end: must be"),
        (["simulate", "--scene", "default", "--method", "Euler"], "method"),
        (["simulate", "--scene", "default", "--times", "1,x"], "times"),
    ],
)
def test_cli_bad_input_exit_2_one_line(args, fragment, capsys):
    with pytest.raises(SystemExit) as info:
        raise SystemExit(main(args))
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert fragment in err and "\n" not in err and "Traceback" not in err


def test_cli_bad_scene_file(tmp_path):
    data = load_scene("default").to_dict()
    data["state"]["mu"] = -0.5
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    proc = subprocess.run(
        [sys.executable, "-m", "flatbody_env.cli", "simulate", str(path), "--t-end", "1"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "state.mu" in proc.stderr and "[1e-06, 1e+06]" in proc.stderr


def test_cli_listings(capsys):
    assert main(["methods", "--json"]) == 0
    methods = json.loads(capsys.readouterr().out)
    assert {"name", "adaptive", "order", "chart", "compiled", "preserves"} <= set(methods[0])
    assert {m["name"] for m in methods} >= {"RK45", "DOP853", "Radau", "LSODA"}
    assert main(["scenes"]) == 0
    assert "close-approach" in capsys.readouterr().out
