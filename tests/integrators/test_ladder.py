"""The ladder of models against the full model: the planar reduction, each rung's solution, the choice.

References are the full two-polar equations integrated by DOP853-numba at rtol = atol = 1e-13
(R by scipy's DOP853 on eqs. (44)–(49) + Ṙ = R W(ω)); the planar reduction is checked against an
independent Hamiltonian (tests/conftest.py) by finite differences.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatbody_env.cli.main import main
from flatbody_env.integrators import IntegrationError, Tolerances, get_method
from flatbody_env.integrators import ladder_kernels as lk
from flatbody_env.integrators.compiled_methods import kernel_params
from flatbody_env.integrators.ladder import (
    GAP_MIN,
    STATIONARY_TOL,
    check_rung,
    choose_rung,
    first_collapse_time,
    planar_gap_lower_bound,
    rung_model,
)
from flatbody_env.physics.body import Body, Inertia, default_body
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.equilibria import stationary_from_shape
from flatbody_env.physics.hamiltonian import velocities_from_momenta
from flatbody_env.physics.kinematics import configuration, configuration_rate
from flatbody_env.physics.potentials import V1, V2, ThicknessPotential
from flatbody_env.physics.state import pack
from flatbody_env.scene import load_scene
from flatbody_env.simulation import choose_model, simulate

from conftest import BODIES
from oracles import independent_hamiltonian

TIGHT = Tolerances(rtol=1e-13, atol=1e-13)
RUNG_TOL = Tolerances(rtol=1e-12, atol=1e-12)
T100 = np.linspace(0.0, 100.0, 201)
BV1 = Body(inertia=Inertia.isotropic(1.0, 0.7), potential=V1(k=1.3), thickness=ThicknessPotential(a=1.0, b=1.0))
BV2 = Body(inertia=Inertia.isotropic(0.9, 1.1), potential=V2(c=0.8, d=1.2), thickness=ThicknessPotential(a=0.5, b=2.0))


def _full(body, y, times=T100, u=None):
    return get_method("DOP853-numba").integrate(body, y, times, tol=TIGHT, u=u).Y


def _full_rotation(body, y, times=T100):
    return (
        get_method("DOP853")
        .integrate(body, y, times, tol=Tolerances(rtol=1e-12, atol=1e-13), with_rotation=True)
        .rotation
    )


def _rung(name, body, y, times=T100, u=None, with_rotation=False):
    return rung_model(name).integrate(body, y, times, tol=RUNG_TOL, u=u, with_rotation=with_rotation)


def _gap_state(gap: float) -> np.ndarray:
    """A planar V1 state (BV1) whose closest approach min|λ − μ| is ``gap``.

    z₋ = (λ−μ)/2·e^{i(θ−α)} moves on a centred ellipse (ladder docstring); starting at its apsis
    (p_λ = p_μ: no radial velocity) with semi-axis a = (λ−μ)/2, the other semi-axis is
    |σ₋|/(4Jaω) (angular momentum −σ₋/(4J)), so σ₋ = 4Jaω·gap/2.
    """
    w = math.sqrt(1.3)
    a = 0.25
    sm = 4.0 * a * w * 0.5 * gap
    return np.array([0.0, 0.0, 1.0 + sm, 1.0, 0.2, 0.2, 0.1, 1.3, 0.8, 1.0, 0.3])


# ------------------------------------------------------------------------------- the planar reduction
@pytest.mark.parametrize("name", ["V1", "V2", "V3"])
def test_planar_set_is_invariant_and_splits_into_two_systems(name):
    """At s1 = s2 = 0 the full rhs has ṡ = 0, ṗ_θ = 0; the in-plane rates ignore (ϱ, p_ϱ), the thickness rates ignore (λ, μ, p_λ, p_μ)."""
    body = BODIES[name]
    rng = np.random.default_rng(3)
    P = kernel_params(body)
    for _ in range(5):
        y = np.concatenate(
            [
                [0.0, 0.0],
                rng.normal(size=5),
                [rng.uniform(1.1, 1.8), rng.uniform(0.4, 0.9), rng.uniform(0.6, 1.4), rng.uniform(-3, 3)],
            ]
        )
        f = rhs(0.0, y, None, body)
        assert f[0] == 0.0 and f[1] == 0.0 and f[2] == 0.0 and f[3] == 0.0
        other = y.copy()
        other[9], other[6] = 1.7, -0.4  # different thickness
        g = rhs(0.0, other, None, body)
        np.testing.assert_allclose(g[[4, 5, 7, 8, 10]], f[[4, 5, 7, 8, 10]], rtol=1e-14, atol=1e-14)
        other = y.copy()
        other[7], other[8], other[4], other[5] = 1.25, 0.7, -0.3, 0.9
        g = rhs(0.0, other, None, body)
        np.testing.assert_allclose(g[[6, 9]], f[[6, 9]], rtol=1e-14, atol=1e-14)
        # the compiled sub-systems read exactly these rates, and α̇ = ω3
        x = np.array([y[7], y[8], y[4], y[5], y[10], 0.3])
        dx = np.empty(6)
        lk.sub_rhs(
            x,
            y,
            lk.INPLANE_STATE,
            lk.INPLANE_RATE,
            np.zeros(4),
            P,
            dx,
            np.empty(11),
            np.empty(12),
            np.empty(7),
            np.empty(4),
        )
        np.testing.assert_allclose(dx[:5], f[[7, 8, 4, 5, 10]], rtol=1e-13, atol=1e-13)
        assert dx[5] == pytest.approx(velocities_from_momenta(y, body)["omega3"], rel=1e-13)
        # an independent derivation: ṗ_λ = −∂H/∂λ, ṗ_μ = −∂H/∂μ, ṗ_ϱ = −∂H/∂ϱ with H built from matrices
        for k, idx in ((4, 7), (5, 8), (6, 9)):
            h = 1e-6
            yp, ym = y.copy(), y.copy()
            yp[idx] += h
            ym[idx] -= h
            dH = (independent_hamiltonian(yp, body) - independent_hamiltonian(ym, body)) / (2 * h)
            assert f[k] == pytest.approx(-dH, rel=1e-6, abs=1e-7)


# ------------------------------------------------------------------------------- rung 1
def _stationary_cases():
    body = default_body()
    out = [
        ("stationary-v1", load_scene("stationary-v1").body, pack(load_scene("stationary-v1").state)),
        ("stationary-ellipse", load_scene("stationary-ellipse").body, pack(load_scene("stationary-ellipse").state)),
    ]
    for branch in ("rotation", "circulation"):
        e = stationary_from_shape(body, 1.5, 1.0, branch=branch)
        y = pack(e.state)
        y[10] = -0.7
        out.append((f"V3-{branch}", body, y))
    e = stationary_from_shape(BV2, 1.6, 1.2)
    out.append(("V2-circulation", BV2, pack(e.state)))
    return out


@pytest.mark.parametrize("case", _stationary_cases(), ids=lambda c: c[0])
def test_stationary_rung_equals_full_model(case):
    _, body, y = case
    assert choose_rung(y, body).rung == "stationary"
    a = _rung("stationary", body, y, with_rotation=True)
    b = _full(body, y)
    assert np.max(np.abs(a.Y - b)) <= 1e-9


def test_stationary_rotation_equals_full_model():
    sc = load_scene("stationary-ellipse")
    y = pack(sc.state)
    a = _rung("stationary", sc.body, y, with_rotation=True)
    assert np.max(np.abs(a.rotation - _full_rotation(sc.body, y))) <= 1e-9


def test_stationary_rung_is_exact_at_t_1e6():
    sc = load_scene("stationary-ellipse")
    y = pack(sc.state)
    times = np.array([0.0, 1.0, 1e3, 1e6])
    a = _rung("stationary", sc.body, y, times=times, with_rotation=True)
    for k in range(10):
        assert np.all(a.Y[k] == y[k])  # λ, μ, ϱ, s, every momentum: bit for bit
    vel = velocities_from_momenta(y, sc.body)
    np.testing.assert_allclose(a.Y[10], y[10] + vel["theta_dot"] * times, rtol=4e-16, atol=0)
    R = a.rotation
    assert np.max(np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3))) < 1e-15
    np.testing.assert_array_equal(R[:, :, 2], np.broadcast_to([0.0, 0.0, 1.0], (4, 3)))
    # the laboratory spin R s is conserved and the angle is ω3 t exactly
    ang = np.arctan2(R[-1, 0, 1], R[-1, 0, 0])
    assert math.remainder(ang - vel["omega3"] * 1e6, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert np.all(a.stats["energy"] == a.stats["energy"][0])


# ------------------------------------------------------------------------------- rung 2
def _planar_cases():
    sc = load_scene("planar-v3")
    cr = load_scene("crossing")
    y_v2 = np.array([0.0, 0.0, 1.6, 1.1, 0.2, -0.3, 0.3, 1.5, 0.8, 1.1, 0.2])
    y_v3b = pack(sc.state)
    y_v3b[[4, 5, 6, 10]] = [-0.2, 0.25, -0.4, 1.0]
    return [
        ("planar-v3", sc.body, pack(sc.state)),
        ("V3-other", sc.body, y_v3b),
        ("crossing (sigma- = 0)", cr.body, pack(cr.state)),
        ("V2 c != d", BV2, y_v2),
    ]


@pytest.mark.parametrize("case", _planar_cases(), ids=lambda c: c[0])
def test_planar_rung_equals_full_model(case):
    _, body, y = case
    assert choose_rung(y, body).rung == "planar"
    a = _rung("planar", body, y)
    b = _full(body, y)
    assert np.max(np.abs(a.Y - b)) <= 1e-9
    assert np.all(a.Y[0] == 0.0) and np.all(a.Y[1] == 0.0) and np.all(a.Y[2] == y[2]) and np.all(a.Y[3] == y[3])
    if y[2] == y[3]:
        assert np.any(np.diff(np.sign(a.Y[7] - a.Y[8])) != 0)  # it does pass through λ = μ


def test_planar_rotation_equals_full_model():
    sc = load_scene("planar-v3")
    y = pack(sc.state)
    a = _rung("planar", sc.body, y, with_rotation=True)
    assert np.max(np.abs(a.rotation - _full_rotation(sc.body, y))) <= 1e-9


def test_planar_rung_under_dilatation_equals_full_model():
    """f_ϱ keeps the planar set (it enters only the thickness oscillator); the in-plane bound still holds."""
    sc = load_scene("planar-v3")
    y = pack(sc.state)
    u = np.array([0.0, 0.0, 0.0, 0.4])
    assert choose_rung(y, sc.body, u).rung == "planar"
    a = _rung("planar", sc.body, y, u=u)
    b = _full(sc.body, y, u=u)
    assert np.max(np.abs(a.Y - b)) <= 1e-9
    assert np.ptp(b[6]) > 0.1


def test_planar_gap_bound_is_rigorous():
    sc = load_scene("planar-v3")
    y = pack(sc.state)
    b = _full(sc.body, y, times=np.linspace(0, 100, 4001))
    bound = planar_gap_lower_bound(y, sc.body)
    assert GAP_MIN <= bound <= np.min(np.abs(b[7] - b[8]))


# ------------------------------------------------------------------------------- rung 3
def _v1_cases():
    sc = load_scene("planar-v1-crossing")
    return [
        ("planar-v1-crossing", sc.body, pack(sc.state)),
        ("generic", BV1, np.array([0.0, 0.0, 1.2, 0.9, 0.2, -0.1, 0.1, 1.3, 0.8, 1.0, 0.3])),
        ("lambda < mu", BV1, np.array([0.0, 0.0, 1.3, 1.5, 0.1, 0.2, -0.2, 0.8, 1.1, 0.9, 2.0])),
        ("gap 1e-6", BV1, _gap_state(1e-6)),
    ]


@pytest.mark.parametrize("case", _v1_cases(), ids=lambda c: c[0])
def test_planar_v1_rung_equals_full_model(case):
    name, body, y = case
    assert choose_rung(y, body).rung == "planar-V1"
    a = _rung("planar-V1", body, y)
    b = _full(body, y)
    assert np.max(np.abs(a.Y - b)) <= 1e-9
    fine = _rung("planar-V1", body, y, times=np.linspace(0.0, 100.0, 200_001)).Y
    gap = np.abs(fine[7] - fine[8])
    if name == "planar-v1-crossing":
        assert np.sum(np.diff(np.sign(fine[7] - fine[8])) != 0) >= 10  # through λ = μ, again and again
    if name == "gap 1e-6":
        assert 1e-6 <= gap.min() < 2e-6  # the closest approach is the one asked for
        assert np.ptp(fine[10]) > 1.0  # the chart's θ turns fast at each pass


def test_planar_v1_rotation_equals_full_model():
    sc = load_scene("planar-v1-crossing")
    y = pack(sc.state)
    a = _rung("planar-V1", sc.body, y, with_rotation=True)
    assert np.max(np.abs(a.rotation - _full_rotation(sc.body, y))) <= 1e-9


def test_planar_v1_in_plane_block_is_the_oscillator():
    """Φ₂(t) rebuilt from the rung's (λ, μ, θ, α) equals Φ₂(0) cos ωt + Φ̇₂(0) sin(ωt)/ω (matrices, no complex numbers)."""
    y = _v1_cases()[1][2]
    times = np.linspace(0.0, 30.0, 61)
    a = _rung("planar-V1", BV1, y, times=times, with_rotation=True)
    w = math.sqrt(1.3)
    vel = velocities_from_momenta(y, BV1)
    M0 = configuration(y[7], y[8], y[9], y[10])
    Md0 = configuration_rate(y[7], y[8], y[9], y[10], vel)
    for k, t in enumerate(times):
        Phi = configuration(a.Y[7, k], a.Y[8, k], a.Y[9, k], a.Y[10, k], a.rotation[k])
        np.testing.assert_allclose(
            Phi[:2, :2], M0[:2, :2] * math.cos(w * t) + Md0[:2, :2] * math.sin(w * t) / w, atol=1e-13
        )


def test_planar_v1_collapse_found_exactly():
    """V1 has no barrier (erratum E10): det Φ₂ → 0 is reported at the time a dense matrix sampling finds."""
    y = np.array([0.0, 0.0, 0.05, 0.04, 0.0, -1.5, 0.0, 1.2, 0.6, 1.0, 0.4])
    w = math.sqrt(1.3)
    vel = velocities_from_momenta(y, BV1)
    M0 = configuration(y[7], y[8], y[9], y[10])[:2, :2]
    Md0 = configuration_rate(y[7], y[8], y[9], y[10], vel)[:2, :2]
    t = np.linspace(0.0, 10.0, 1_000_001)
    det = np.linalg.det(M0[None] * np.cos(w * t)[:, None, None] + Md0[None] * (np.sin(w * t) / w)[:, None, None])
    t_sampled = t[np.argmax(det <= 0.0)]
    with pytest.raises(IntegrationError) as exc:
        _rung("planar-V1", BV1, y, times=np.linspace(0, 10, 11))
    assert exc.value.kind == "domain"
    assert exc.value.t == pytest.approx(t_sampled, abs=2e-5)
    # circular orbits |z₊| = 1 > |z₋| = 0.1 never collapse; z₊ through 0 (σ₊ = 0, at rest) collapses at ωt = π/2
    assert first_collapse_time(1 + 0j, 1j, 0.1 + 0j, 0.1j, 1.0) == math.inf
    assert first_collapse_time(1 + 0j, 0j, 0.1 + 0j, 0j, 2.0) == pytest.approx(math.pi / 4, rel=1e-9)


# ------------------------------------------------------------------------------- the choice
def test_auto_picks_the_lowest_rung():
    expected = {
        "stationary-ellipse": "stationary",
        "stationary-v1": "stationary",
        "planar-v3": "planar",
        "planar-v1-crossing": "planar-V1",
        "crossing": "planar",
        "default": "two-polar",
        "close-approach": "regular",
        "anisotropic": "regular",
    }
    for name, rung in expected.items():
        sc = load_scene(name)
        assert choose_model(sc.state, sc.body) == rung, name
    assert (
        choose_model(load_scene("close-approach").state, load_scene("close-approach").body, ladder=False) == "regular"
    )


def test_controls_keep_only_the_rungs_they_leave_invariant():
    sc = load_scene("planar-v1-crossing")
    y = pack(sc.state)
    assert choose_rung(y, sc.body, [0.0, 0.0, 0.0, 0.3]).rung == "planar-V1"  # dilatation keeps planarity
    assert choose_rung(y, sc.body, [0.1, 0.0, 0.0, 0.0]) is None  # τ1 tilts the plane
    assert choose_rung(y, sc.body, [0.0, 0.0, 0.1, 0.0]) is None  # τ3 changes s3
    st = load_scene("stationary-ellipse")
    assert choose_rung(pack(st.state), st.body, [0.0, 0.0, 0.0, 0.3]).rung == "planar"
    y = pack(st.state)
    y[4] = 10 * STATIONARY_TOL
    assert choose_rung(y, st.body).rung == "planar"


@pytest.mark.parametrize(
    "scene, rung, words",
    [
        ("default", "planar", "s1, s2"),
        ("planar-v3", "stationary", "residual"),
        ("planar-v3", "planar-V1", "not V1"),
        ("close-approach", "planar", "guarantees"),
        ("anisotropic", "planar", "J1"),
    ],
)
def test_forcing_a_rung_outside_its_invariant_set_is_refused(scene, rung, words):
    with pytest.raises(ValueError, match=f"'{rung}' rung.*{words}"):
        simulate(scene, t_end=1.0, model=rung)
    with pytest.raises(ValueError, match="rung"):
        check_rung(rung, pack(load_scene(scene).state), load_scene(scene).body)


def test_simulate_meta_names_the_rung_and_why():
    run = simulate("planar-v3", t_end=10.0)
    meta = run.to_dict()["meta"]
    assert run.model == meta["rung"] == "planar" and meta["method"] == "ladder-planar"
    assert "s1 = s2 = 0" in meta["rung_invariant"] and meta["rung_measured"]["gap_lower_bound"] >= GAP_MIN
    run = simulate("default", t_end=1.0)
    assert (
        run.to_dict()["meta"]["rung"] == "two-polar"
        and run.to_dict()["meta"]["rung_measured"]["gap_lower_bound"] >= GAP_MIN
    )
    forced = simulate("planar-v3", t_end=10.0, model="two-polar", rtol=1e-12, atol=1e-12)
    again = simulate("planar-v3", t_end=10.0, rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(forced.y - again.y)) < 1e-9
    with pytest.raises(ValueError, match="step"):
        simulate("planar-v3", t_end=1.0, model="planar", method="RK4", step=0.01)


@pytest.mark.parametrize(
    "scene, rung", [("stationary-ellipse", "stationary"), ("planar-v3", "planar"), ("planar-v1-crossing", "planar-V1")]
)
def test_cli_simulate_reports_the_rung(scene, rung, capsys):
    assert main(["simulate", "--scene", scene, "--t-end", "5", "--summary"]) == 0
    assert f"rung: {rung} --" in capsys.readouterr().out


def test_cli_forcing_a_rung_is_one_line_exit_2(capsys):
    assert main(["simulate", "--scene", "default", "--t-end", "1", "--model", "stationary"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'stationary' rung" in err[0]
