"""The regular matrix formulation (NOTES §5) against the two-polar chart."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import BODIES, random_state
from flatbody_env import load_scene, simulate
from flatbody_env.physics.equations import rhs_with_rotation
from flatbody_env.physics.hamiltonian import hamiltonian
from flatbody_env.physics.kinematics import Decomposition, configuration
from flatbody_env.physics.regular import (
    FrameTracker,
    constraint_residual,
    matrices,
    paper_from_regular,
    regular_energy,
    regular_from_paper,
    regular_rhs,
)
from flatbody_env.simulation import choose_model, gap_lower_bound


def test_conversions_round_trip(body):
    rng = np.random.default_rng(4)
    for _ in range(20):
        y = random_state(rng)
        z = regular_from_paper(y, body)
        np.testing.assert_allclose(constraint_residual(z), 0.0, atol=1e-14)
        ref = Decomposition(R=np.eye(3), lam=y[7], mu=y[8], rho=y[9], theta=y[10])
        back, _ = paper_from_regular(z, body, ref)
        np.testing.assert_allclose(back, y, rtol=1e-11, atol=1e-11)
        assert abs(regular_energy(z, body, y[7] > y[8]) - hamiltonian(y, body)) < 1e-11 * (
            1 + abs(hamiltonian(y, body))
        )


@pytest.mark.parametrize("scene_name", ["default", "anisotropic"])
def test_formulations_agree_over_t20(scene_name):
    """Φ(t) from the integrated paper state equals the integrated matrix formulation to ≤ 1e-8."""
    scene = load_scene(scene_name)
    times = np.linspace(0, 20, 41)
    paper = simulate(scene, t_end=20.0, times=times, model="two-polar", rtol=1e-12, atol=1e-12, with_rotation=True)
    z0 = regular_from_paper(np.array([scene.state[k] for k in paper.state]), scene.body)
    sol = solve_ivp(
        lambda t, z: regular_rhs(t, z, None, scene.body),
        (0, 20),
        z0,
        method="DOP853",
        t_eval=times,
        rtol=1e-12,
        atol=1e-12,
    )
    st = paper.state
    Phi_paper = configuration(st["lambda"], st["mu"], st["rho"], st["theta"], paper.rotation)
    Phi_regular = np.stack([matrices(sol.y[:, k])[0] for k in range(times.size)])
    assert np.max(np.abs(Phi_paper - Phi_regular)) < 1e-8


@pytest.mark.parametrize("scene_name", ["close-approach", "anisotropic", "crossing"])
def test_regular_model_reproduces_chart_state(scene_name):
    """simulate(model='regular') returns the paper's chart state (branch followed by continuity)."""
    scene = load_scene(scene_name)
    a = simulate(scene, t_end=20.0, model="regular", rtol=1e-11, atol=1e-11, with_rotation=True)
    b = simulate(scene, t_end=20.0, model="two-polar", rtol=1e-12, atol=1e-12, with_rotation=True)
    for name in a.state:
        np.testing.assert_allclose(a.state[name], b.state[name], atol=5e-8, err_msg=name)
    np.testing.assert_allclose(a.rotation, b.rotation, atol=5e-8)


def test_crossing_passes_through_lambda_equals_mu():
    run = simulate(load_scene("crossing"), t_end=20.0, model="regular", with_rotation=True)
    gap = run.state["lambda"] - run.state["mu"]
    assert gap.max() > 0 > gap.min()  # the labels swap: λ − μ changes sign smoothly
    drift = run.drift()
    assert drift["energy"] < 1e-8 and drift["lab_spin"] < 1e-8


def test_controls_equivalent_in_both_formulations():
    body = BODIES["V3"]
    rng = np.random.default_rng(9)
    y0 = random_state(rng)
    u = np.array([0.2, -0.1, 0.15, 0.3])
    s1 = solve_ivp(
        lambda t, z: rhs_with_rotation(t, z, u, body),
        (0, 5),
        np.concatenate([y0, np.eye(3).ravel()]),
        method="DOP853",
        rtol=1e-12,
        atol=1e-12,
    )
    z0 = regular_from_paper(y0, body)
    frame = FrameTracker(Decomposition(R=np.eye(3), lam=y0[7], mu=y0[8], rho=y0[9], theta=y0[10]))
    s2 = solve_ivp(
        lambda t, z: regular_rhs(t, z, u, body, y0[7] > y0[8], frame),
        (0, 5),
        z0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-12,
    )
    yf, Rf = s1.y[:11, -1], s1.y[11:, -1].reshape(3, 3)
    np.testing.assert_allclose(configuration(*yf[7:11], Rf), matrices(s2.y[:, -1])[0], atol=1e-9)


def test_gap_bound_is_rigorous_and_drives_model_choice():
    scene = load_scene("close-approach")
    bound = gap_lower_bound(scene.state, scene.body)
    run = simulate(scene, t_end=20.0)
    assert np.min(np.abs(run.state["lambda"] - run.state["mu"])) >= bound > 0
    assert choose_model(scene.state, scene.body) == "regular" and run.model == "regular"
    assert choose_model(load_scene("default").state, load_scene("default").body) == "two-polar"
    assert choose_model(load_scene("anisotropic").state, load_scene("anisotropic").body) == "regular"
