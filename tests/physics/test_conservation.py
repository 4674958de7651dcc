"""Conservation along tight integrations (NOTES §4), and the printed convention's failure."""

from __future__ import annotations

import numpy as np
import pytest

from flatbody_env import load_scene, simulate
from flatbody_env.physics.body import Body
from flatbody_env.physics.invariants import angular_momentum
from flatbody_env.physics.hamiltonian import velocities_from_momenta
from flatbody_env.physics.kinematics import configuration, configuration_rate


@pytest.fixture(scope="module")
def default_run():
    return simulate(load_scene("default"), t_end=100.0, rtol=1e-12, atol=1e-12, with_rotation=True)


def test_invariants_conserved_over_t100(default_run):
    drift = default_run.drift()
    assert drift["energy"] < 1e-9
    assert drift["casimir"] < 1e-9
    assert drift["p_theta"] == 0.0  # ṗ_θ = 0 exactly (eq. (46))
    assert drift["lab_spin"] < 1e-9
    # the motion is not trivial: the state moves by O(1)
    assert np.ptp(default_run.state["theta"]) > 10 and np.ptp(default_run.state["s1"]) > 0.1


def test_lab_spin_is_minus_physical_angular_momentum(default_run):
    """Σ_A J_A Φ_A × Φ̇_A (from matrices) = −R s (NOTES §4, sign from eq. (25))."""
    scene = load_scene("default")
    for k in (0, 37, 100):
        y = default_run.y[:, k]
        R = default_run.rotation[k]
        vel = velocities_from_momenta(y, scene.body)
        Phi = configuration(y[7], y[8], y[9], y[10], R)
        Phid = configuration_rate(y[7], y[8], y[9], y[10], vel, R)
        np.testing.assert_allclose(
            angular_momentum(Phi, Phid, scene.body.inertia), -default_run.lab_spin[k], atol=1e-10
        )


def test_printed_convention_breaks_lab_spin():
    """E4: the printed eqs. (44)–(46) keep H and |s|² but not R s (from a state with s1 ≠ 0)."""
    scene = load_scene("default")
    assert scene.state["s1"] != 0.0
    b = scene.body
    paper = Body(inertia=b.inertia, potential=b.potential, thickness=b.thickness, spin_convention="paper")
    data = scene.to_dict()
    data["spin_convention"] = "paper"
    run = simulate(data, t_end=20.0, rtol=1e-12, atol=1e-12, with_rotation=True)
    assert paper.spin_convention == "paper"
    drift = run.drift()
    assert drift["energy"] < 1e-9 and drift["casimir"] < 1e-9
    assert drift["lab_spin"] > 0.1
    good = simulate(scene, t_end=20.0, rtol=1e-12, atol=1e-12, with_rotation=True).drift()
    assert good["lab_spin"] < 1e-9


def test_anisotropic_conserves_h_casimir_lab_spin_not_p_theta():
    run = simulate(load_scene("anisotropic"), t_end=20.0, rtol=1e-12, atol=1e-12, with_rotation=True, model="two-polar")
    drift = run.drift()
    assert drift["energy"] < 1e-9 and drift["casimir"] < 1e-9 and drift["lab_spin"] < 1e-9
    assert drift["p_theta"] > 1e-2


@pytest.mark.parametrize("name", ["default", "anisotropic", "planar-v1-crossing"])
def test_hamiltonian_series_is_hamiltonian_column_by_column(name):
    """The column-wise H (isotropic bodies with a built-in potential) is the step-by-step H bit for bit."""
    from flatbody_env.physics.hamiltonian import hamiltonian, hamiltonian_series

    sc = load_scene(name)
    Y = simulate(sc, t_end=2.0, times=np.linspace(0.0, 2.0, 120)).y
    H = hamiltonian_series(Y, sc.body)
    np.testing.assert_array_equal(H, [hamiltonian(Y[:, k], sc.body) for k in range(Y.shape[1])])
