"""Stationary ellipses (eqs. (52)-(54) of the paper, NOTES §6): closed form, root finding, branch A, inverse."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatbody_env import Body, CustomPotential, Inertia, ThicknessPotential, V1, V2, V3, default_body
from analysis.stationary import (
    SearchBox,
    solve_branch,
    spins_for_shape,
    stationary_ellipses,
    steady_rotations,
    v1_closed_form,
)


def body_with(pot, J=1.0, J3=1.0, a=1.0, b=1.0):
    return Body(inertia=Inertia.isotropic(J, J3), potential=pot, thickness=ThicknessPotential(a=a, b=b))


def paper_eq52_53(lam, mu, s3, pt, J):
    """Right-hand sides of eqs. (52) and (53) exactly as printed in the paper."""
    den = J * (lam**2 - mu**2) ** 3
    r52 = (lam * (lam**2 + 3 * mu**2) * (s3**2 + pt**2) - 2 * mu * (mu**2 + 3 * lam**2) * s3 * pt) / den
    r53 = (2 * lam * (lam**2 + 3 * mu**2) * s3 * pt - mu * (mu**2 + 3 * lam**2) * (s3**2 + pt**2)) / den
    return r52, r53


@pytest.mark.parametrize("s3, pt", [(2.5, 1.5), (1.5, 2.5), (2.0, 1.0), (0.3, 3.0), (-2.0, -0.7)])
@pytest.mark.parametrize("k, J", [(1.0, 1.0), (2.5, 0.7)])
def test_v1_closed_form_equals_numeric_solver(s3, pt, k, J):
    body = body_with(V1(k=k), J=J)
    closed = v1_closed_form(body, s3, pt)
    numeric = stationary_ellipses(body, s3, pt, method="numeric")
    assert len(closed) == 1 and len(numeric) == 1
    c, n = closed[0], numeric[0]
    assert abs(c.lam - n.lam) < 1e-10 and abs(c.mu - n.mu) < 1e-10 and abs(c.rho - n.rho) < 1e-12
    # NOTES §6: (λ+μ)^4 = σ+²/(kJ), (λ−μ)^4 = σ−²/(kJ); ω3, θ̇ = ½√(k/J)(sgn σ+ ± sgn σ−)
    sp, sm = s3 + pt, s3 - pt
    assert math.isclose((c.lam + c.mu) ** 4, sp * sp / (k * J), rel_tol=1e-12)
    assert math.isclose((c.lam - c.mu) ** 4, sm * sm / (k * J), rel_tol=1e-12)
    w = 0.5 * math.sqrt(k / J)
    assert math.isclose(c.omega3, w * (np.sign(sp) + np.sign(sm)), abs_tol=1e-12)
    assert math.isclose(c.theta_dot, w * (np.sign(sp) - np.sign(sm)), abs_tol=1e-12)
    assert c.residual <= 1e-12 and n.residual <= 1e-10


def test_v1_needs_s3_p_theta_same_sign():
    body = body_with(V1(k=1.0))
    assert v1_closed_form(body, 2.0, -1.0) == []
    assert stationary_ellipses(body, 2.0, -1.0, method="numeric") == []


@pytest.mark.parametrize("pot", [V3(kappa=1.0), V3(kappa=2.3), V2(c=1.0, d=1.0), V2(c=1.0, d=2.0), V2(c=0.5, d=3.0)])
@pytest.mark.parametrize("s3, pt", [(2.0, 0.5), (1.45, 1.77), (0.2, 1.0), (3.0, 1.2)])
def test_numeric_solutions_satisfy_paper_equations(pot, s3, pt):
    body = body_with(pot)
    sols = stationary_ellipses(body, s3, pt)
    assert sols, "expected at least one stationary ellipse"
    for e in sols:
        assert e.residual <= 1e-10
        _, gl, gm, gr = body.potential_terms(e.lam, e.mu, e.rho)
        r52, r53 = paper_eq52_53(e.lam, e.mu, s3, pt, 1.0)
        assert abs(gl - r52) <= 1e-9 * max(1.0, abs(gl))
        assert abs(gm - r53) <= 1e-9 * max(1.0, abs(gm))
        assert abs(gr) <= 1e-12  # eq. (54)
        assert e.rho == pytest.approx(1.0)  # ϱ* = (a/b)^{1/3}
        assert e.state["s1"] == 0.0 and e.state["p_lambda"] == 0.0


def test_v2_unequal_constants_gives_two_ellipses():
    body = body_with(V2(c=1.0, d=2.0))
    sols = stationary_ellipses(body, 2.0, 0.5)
    assert len(sols) == 2
    assert (sols[0].lam - sols[0].mu) * (sols[1].lam - sols[1].mu) < 0  # the c-axis long or short
    # symmetric V2: only one (λ > μ)
    assert len(stationary_ellipses(body_with(V2(c=1.0, d=1.0)), 2.0, 0.5)) == 1


def test_duality_swaps_omega3_and_theta_dot():
    body = default_body()
    a = stationary_ellipses(body, 2.0, 0.5)[0]
    b = stationary_ellipses(body, 0.5, 2.0)[0]
    assert a.lam == pytest.approx(b.lam, abs=1e-10) and a.mu == pytest.approx(b.mu, abs=1e-10)
    assert a.omega3 == pytest.approx(b.theta_dot, abs=1e-10) and a.theta_dot == pytest.approx(b.omega3, abs=1e-10)
    assert a.kind == "rigid" and b.kind == "circulating"


def test_inverse_problem_round_trip_and_v3_existence():
    body = default_body()
    sols = spins_for_shape(body, 1.4, 0.9)
    assert len(sols) == 2 and {e.kind for e in sols} == {"rigid", "circulating"}
    for e in sols:
        assert e.residual <= 1e-10
        again = stationary_ellipses(body, e.s3, e.p_theta)
        assert any(abs(g.lam - 1.4) < 1e-9 and abs(g.mu - 0.9) < 1e-9 for g in again)
    # NOTES §6: for V3 a shape with λ > μ is stationary iff λμ ≥ 1
    assert spins_for_shape(body, 1.2, 0.8) == []
    assert len(spins_for_shape(body, 1.2, 0.85, include_reversed=True)) == 4


def test_branch_a_steady_rotation_v3_and_none_for_v1():
    body = default_body()
    rots = steady_rotations(body, 1.0)
    assert rots
    for e in rots:
        assert e.residual <= 1e-10
        assert e.p_theta == 0.0 and e.s3 == 0.0 and abs(e.theta_dot) < 1e-14 and abs(e.omega3) < 1e-14
        _, gl, gm, gr = body.potential_terms(e.lam, e.mu, e.rho)
        J, J3 = 1.0, 1.0
        if e.branch == "A1":
            I1 = J * e.mu**2 + J3 * e.rho**2
            s = e.state["s1"]
            assert abs(gl) < 1e-10 and gm == pytest.approx(J * e.mu * s * s / I1**2, abs=1e-10)
            assert gr == pytest.approx(J3 * e.rho * s * s / I1**2, abs=1e-10)
        else:
            I2 = J * e.lam**2 + J3 * e.rho**2
            s = e.state["s2"]
            assert abs(gm) < 1e-10 and gl == pytest.approx(J * e.lam * s * s / I2**2, abs=1e-10)
            assert gr == pytest.approx(J3 * e.rho * s * s / I2**2, abs=1e-10)
    assert steady_rotations(body_with(V1(k=1.0)), 1.0) == []


def test_custom_potential_with_coupled_rho_matches_builtin():
    def value(l, m, r):
        return 1.0 / (l * m) + 0.5 * (l * l + m * m)

    def gradient(l, m, r):
        return (l - 1.0 / (l * l * m), m - 1.0 / (l * m * m), 0.0)

    custom = Body(
        inertia=Inertia.isotropic(1.0, 1.0),
        potential=CustomPotential(value=value, gradient=gradient),
        thickness=ThicknessPotential(a=1.0, b=1.0),
    )
    box = SearchBox(lam=(0.3, 5.0), mu=(0.3, 5.0), rho=(0.3, 3.0), n=61, n_rho=16)
    got = stationary_ellipses(custom, 2.0, 0.5, box=box)
    ref = stationary_ellipses(default_body(), 2.0, 0.5)
    assert len(got) == len(ref) == 1
    assert got[0].lam == pytest.approx(ref[0].lam, abs=1e-9) and got[0].rho == pytest.approx(1.0, abs=1e-9)
    assert got[0].residual <= 1e-10


def test_circle_case_and_bad_input():
    rep = solve_branch(default_body(), "N", (1.0, 1.0))
    assert rep.solutions == () and any("circle" in n for n in rep.notes)
    aniso = Body(
        inertia=Inertia(J1=1.0, J2=2.0, J3=1.0), potential=V3(kappa=1.0), thickness=ThicknessPotential(a=1, b=1)
    )
    with pytest.raises(ValueError, match="J1 = J2"):
        stationary_ellipses(aniso, 2.0, 0.5)
    with pytest.raises(ValueError, match="s3"):
        stationary_ellipses(default_body(), float("nan"), 0.5)
    with pytest.raises(ValueError, match="box.lam"):
        SearchBox(lam=(2.0, 1.0))
    with pytest.raises(ValueError, match="spin"):
        steady_rotations(default_body(), 0.0)
