"""``method="auto"`` (the default of simulate): what it picks, that it meets the tolerance, and that the
pick is the work-precision chart's fastest method in the scene's chart."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from flatbody_env import simulate
from flatbody_env.integrators import Tolerances, get_method
from flatbody_env.integrators.auto import RATTLE_AUTO, auto_method
from flatbody_env.scene import load_scene
from flatbody_env.simulation import explain_model

from tests.conftest import BODIES

CHART = Path(__file__).resolve().parents[2] / "docs" / "img" / "work_precision.csv"


def _chart_fastest(scene: str, target: float, chart: str) -> str:
    """The method with the least wall time at final error ≤ target on ``scene`` among the chart's runs in ``chart``."""
    best: dict[str, float] = {}
    with CHART.open() as fh:
        for row in csv.DictReader(fh):
            if row["scene"] != scene or row["status"] != "ok" or row["chart"] != chart or float(row["error"]) > target:
                continue
            best[row["method"]] = min(best.get(row["method"], np.inf), float(row["wall_time"]))
    return min(best, key=best.get)


@pytest.mark.parametrize("scene", ["regular", "small-rho-bounce", "long-horizon", "close-approach"])
@pytest.mark.parametrize("target", [1e-6, 1e-9])
def test_auto_picks_what_the_work_precision_chart_says(scene, target):
    sc = load_scene(scene)
    rung = explain_model(sc.state, sc.body, ladder=False).rung
    assert auto_method(rung, sc.body).method == _chart_fastest(scene, target, rung)


@pytest.mark.parametrize(
    "scene, method, model",
    [
        ("default", "DOP853-numba", "two-polar"),
        ("regular", "DOP853-numba", "two-polar"),
        ("close-approach", RATTLE_AUTO, "regular"),
        ("anisotropic", RATTLE_AUTO, "regular"),
        ("stationary-ellipse", "ladder-stationary", "stationary"),
        ("planar-v3", "ladder-planar", "planar"),
    ],
)
def test_simulate_default_is_auto_and_names_the_choice(scene, method, model):
    traj = simulate(scene, t_end=2.0)
    assert traj.method == method and traj.model == model
    meta = traj.to_dict()["meta"]
    assert meta["method_requested"] == "auto" and meta["method_reason"].startswith("auto:")
    assert meta["rung"] == model and meta["rung_invariant"]
    if method == RATTLE_AUTO:
        assert 0 < meta["auto_step"] <= 0.1 and meta["auto_error_estimate"] <= 1.0


@pytest.mark.parametrize("scene", ["default", "close-approach", "anisotropic"])
def test_auto_meets_the_tolerance_against_a_tight_reference(scene):
    sc = load_scene(scene)
    times = np.linspace(0.0, 5.0, 11)
    rtol = atol = 1e-8
    traj = simulate(sc, t_end=5.0, times=times, rtol=rtol, atol=atol)
    ref = simulate(sc, t_end=5.0, times=times, method="DOP853-regular", model="regular", rtol=1e-13, atol=1e-13)
    err = np.abs(traj.y - ref.y)
    # within a small multiple of the requested tolerance everywhere (adaptive control is local; RATTLE's is estimated)
    assert np.all(err <= 20 * (atol + rtol * np.abs(ref.y))), float(np.max(err / (atol + rtol * np.abs(ref.y))))


def test_auto_is_faster_than_scipy_dop853_on_a_full_model_scene():
    """A count, not a clock: the same steps as scipy's DOP853 (RHS evaluations agree), compiled."""
    sc = load_scene("regular")
    times = np.linspace(0.0, 20.0, 3)
    a = simulate(sc, t_end=20.0, times=times)
    b = simulate(sc, t_end=20.0, times=times, method="DOP853")
    assert a.method == "DOP853-numba" and b.method == "DOP853"
    assert np.max(np.abs(a.y - b.y)) < 1e-8
    assert abs(a.nfev - b.nfev) <= 12  # scipy's dense-output evaluations at the output times


def test_auto_falls_back_where_the_compiled_methods_do_not_apply():
    custom = BODIES["custom"]
    assert auto_method("two-polar", custom).method == "DOP853"
    # V2 with c != d: RATTLE refuses it, the regular chart runs scipy's DOP853-regular
    sc = load_scene("close-approach")
    from flatbody_env.scene import Scene

    v2 = Scene(name="v2-close", body=BODIES["V2"], state=sc.state, t_end=1.0)
    traj = simulate(v2, t_end=0.5, times=[0.25, 0.5], model="regular")
    assert traj.method == "DOP853-regular"
    assert "does not apply" in traj.extra["method_reason"]
    y0 = np.array([v2.state[k] for k in traj.state])
    ref = get_method("DOP853-regular").integrate(
        BODIES["V2"], y0, np.array([0.0, 0.25, 0.5]), tol=Tolerances(rtol=1e-10, atol=1e-10)
    )
    assert np.allclose(traj.y, ref.Y[:, 1:], rtol=0, atol=1e-12)


def test_auto_refuses_a_step_naming_the_field():
    with pytest.raises(ValueError, match="^step:"):
        simulate("default", t_end=1.0, step=0.01)


def test_auto_with_rotation_returns_R_from_the_compiled_method():
    traj = simulate("default", t_end=2.0, with_rotation=True)
    assert traj.method == "DOP853-numba" and traj.rotation.shape == (101, 3, 3)
    assert traj.drift()["lab_spin"] < 1e-8
