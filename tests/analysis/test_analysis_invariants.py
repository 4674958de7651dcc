"""Invariants along trajectories; eq. (51) of the paper with erratum E7 at a stationary ellipse."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flatbody_env import default_body, load_scene, simulate
from flatbody_env.physics.kinematics import material_rotation
from flatbody_env.scene import Scene
from analysis.invariants import invariants_along
from flatbody_env.simulation import Trajectory, read_trajectory
from flatbody_env.physics.state import STATE_NAMES
from analysis.stationary import stationary_ellipses


def stationary_run(t_end=10.0, samples=2001):
    body = default_body()
    e = stationary_ellipses(body, 2.0, 0.5)[0]
    scene = Scene(name="stationary", body=body, state=dict(e.state))
    traj = simulate(
        scene, t_end=t_end, times=np.linspace(0, t_end, samples), rtol=1e-12, atol=1e-12, with_rotation=True
    )
    return body, e, traj


def test_dG_dC_nonzero_while_invariants_constant_eq51():
    body, e, traj = stationary_run()
    rep = invariants_along(traj, body)
    drift = rep.drift_dict()
    for name in ("energy", "casimir", "p_theta", "lab_spin", "K1", "K2", "K3", "trace_G", "det_G"):
        assert drift[name] <= 1e-9, (name, drift[name])
    # G and C rotate: their rates are non-zero
    assert np.min(rep.series["dG/dt"]) > 0.1 and np.min(rep.series["dC/dt"]) > 0.1
    # ... and equal the finite differences of G(t), C(t) along the simulation
    dt = traj.t[1] - traj.t[0]
    fdG = (rep.G[2:] - rep.G[:-2]) / (2 * dt)
    fdC = (rep.C[2:] - rep.C[:-2]) / (2 * dt)
    assert np.max(np.abs(fdG - rep.G_rate[1:-1])) < 1e-4
    assert np.max(np.abs(fdC - rep.C_rate[1:-1])) < 1e-4
    # eq. (51): dG/dt = U(ϑD² − D²ϑ)U⁻¹ (no Ḋ term at a stationary ellipse)
    D2 = np.diag([e.lam**2, e.mu**2, e.rho**2])
    th = e.theta_dot * np.array([[0, -1, 0], [1, 0, 0], [0, 0, 0]])
    U = material_rotation(traj.state["theta"][7])
    assert np.allclose(U @ (th @ D2 - D2 @ th) @ U.T, rep.G_rate[7], atol=1e-10)
    # erratum E7: the printed dC/dt = R(ωD² − D²ω)R⁻¹ does not match the motion; R(W D⁻² − D⁻² W)R⁻¹ does
    R = traj.rotation[7]
    W = e.omega3 * np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 0]])
    Di2 = np.diag(1 / np.diag(D2))
    assert np.allclose(R @ (W @ Di2 - Di2 @ W) @ R.T, fdC[6], atol=1e-4)
    assert not np.allclose(R @ (W @ D2 - D2 @ W) @ R.T, fdC[6], atol=1e-2)


def test_generic_trajectory_conserves_invariants_but_not_deformation():
    scene = load_scene("default")
    traj = simulate(scene, t_end=10.0, rtol=1e-11, atol=1e-11, with_rotation=True)
    rep = invariants_along(traj, scene.body)
    drift = {r.name: r for r in rep.drift}
    for name in ("energy", "casimir", "p_theta", "lab_spin"):
        assert drift[name].conserved and drift[name].max_abs_drift < 1e-7
    assert drift["K3"].max_abs_drift > 1e-3 and not drift["K3"].conserved


def test_saved_json_gives_the_same_table(tmp_path):
    body, e, traj = stationary_run(t_end=5.0, samples=51)
    path = tmp_path / "traj.json"
    path.write_text(json.dumps(traj.to_dict()))
    a = invariants_along(traj, body).drift_dict()
    b = invariants_along(path, body).drift_dict()
    assert a.keys() == b.keys()
    for k in a:
        assert a[k] == pytest.approx(b[k], abs=1e-15)
    no_body = invariants_along(read_trajectory(path))
    assert no_body.G_rate is None and "energy" in no_body.series


def test_bad_trajectory_files(tmp_path):
    with pytest.raises(ValueError, match="no file"):
        read_trajectory(tmp_path / "missing.json")
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        read_trajectory(p)
    p.write_text(json.dumps({"t": [0, 1], "state": {"s1": [0, 0]}}))
    with pytest.raises(ValueError, match="trajectory.state.s2"):
        read_trajectory(p)


def test_trajectory_json_round_trip(tmp_path):
    """Trajectory.to_dict → JSON → read_trajectory gives back the same arrays and metadata."""
    body, e, traj = stationary_run(t_end=2.0, samples=11)
    path = tmp_path / "traj.json"
    path.write_text(json.dumps(traj.to_dict()))
    back = read_trajectory(path)
    assert isinstance(back, Trajectory)
    np.testing.assert_array_equal(back.t, traj.t)
    np.testing.assert_array_equal(back.y, traj.y)
    np.testing.assert_array_equal(back.rotation, traj.rotation)
    np.testing.assert_array_equal(back.energy, traj.energy)
    assert (back.method, back.model, back.nfev, back.scene) == (traj.method, traj.model, traj.nfev, traj.scene)
    assert back.initial_state == traj.initial_state and back.initial_energy == traj.initial_energy
    assert back.drift() == traj.drift()


@pytest.mark.parametrize(
    "change, field",
    [
        ({"t": 3.0}, "trajectory.t"),
        ({"state": None}, "trajectory.state"),
        ({"meta": []}, "trajectory.meta"),
        ({"t": [[[[0.0]]]]}, "trajectory.t"),
        ({"t": [0.0, 0.0]}, "trajectory.t"),
        ({"rotation": [[1.0]]}, "trajectory.rotation"),
        ({"energy": [True, 1.0]}, "trajectory.energy"),
        ({"extra": 1}, "trajectory.extra"),
    ],
)
def test_malformed_trajectory_names_the_field(change, field):
    good = {"t": [0.0, 1.0], "state": {n: [1.0, 1.1] for n in STATE_NAMES}}
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        Trajectory.from_dict({**good, **change})
