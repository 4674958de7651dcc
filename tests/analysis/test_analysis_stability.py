"""Linear stability of stationary ellipses (NOTES §7) and its verification by simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatbody_env import Body, Inertia, ThicknessPotential, V1, V2, V3, default_body
from analysis.stability import (
    analyse_stability,
    hamiltonian_hessian,
    reduced_jacobian,
    sample_stable_target,
    stability_of,
    stability_of_shape,
)
from analysis.stationary import stationary_ellipses
from analysis.verification import verify_bounded, verify_growth, verify_stationary


def v1_body(k=1.0):
    return Body(inertia=Inertia.isotropic(1.0, 1.0), potential=V1(k=k), thickness=ThicknessPotential(a=1.0, b=1.0))


def has_eig(eigs, target, tol=1e-7):
    return min(abs(e - target) for e in eigs) < tol


def test_notes_example_v1_unstable_and_dual_stable():
    body = v1_body()
    unstable = analyse_stability(body, stationary_ellipses(body, 2.5, 1.5)[0])
    stable = analyse_stability(body, stationary_ellipses(body, 1.5, 2.5)[0])
    assert unstable.classification == "hyperbolic" and unstable.nonlinear == "unstable"
    assert stable.classification == "elliptic"
    # out-of-plane block: ±√q (NOTES §7); q for λ = 1.5, μ = 0.5, ϱ = 1, s3 = 2.5, ω3 = 1
    q = (2.5 / (1.5**2 + 1) - 1.0) * (1.0 - 2.5 / (0.5**2 + 1))
    assert unstable.out_of_plane_q == pytest.approx(q, rel=1e-12)
    assert unstable.max_real_part == pytest.approx(math.sqrt(q), rel=1e-9)
    # in-plane: ±2i√(k/J) doubled; thickness ±i√(3b/J3); two zero modes from |s|² and p_θ
    for r in (unstable, stable):
        assert sum(abs(e - 2j) < 1e-7 for e in r.eigenvalues) == 2
        assert has_eig(r.eigenvalues, 1j * math.sqrt(3.0))
        assert sorted(m.quantity for m in r.zero_modes) == ["casimir", "p_theta"]
        assert r.unexplained_zero_modes == 0
    assert stable.out_of_plane_q < 0 and has_eig(stable.eigenvalues, 1j * math.sqrt(-stable.out_of_plane_q))


@pytest.mark.parametrize("pot", [V3(kappa=1.0), V2(c=1.0, d=2.0)])
@pytest.mark.parametrize("s3, pt", [(2.0, 0.5), (0.5, 2.0), (1.0, 0.5), (3.0, 1.0)])
def test_out_of_plane_q_cross_check(pot, s3, pt):
    body = Body(inertia=Inertia.isotropic(1.0, 0.7), potential=pot, thickness=ThicknessPotential(a=1.0, b=1.3))
    for e in stationary_ellipses(body, s3, pt):
        r = analyse_stability(body, e)
        q = r.out_of_plane_q
        target = math.sqrt(q) if q > 0 else 1j * math.sqrt(-q)
        assert has_eig(r.eigenvalues, target, 1e-6)
        if q > 1e-6:
            assert r.classification == "hyperbolic"


def test_jacobian_equals_poisson_tensor_times_amended_hessian():
    """At a relative equilibrium Df = B · Hess(H − a|s|² − b p_θ): an independent check of the Jacobian."""
    body = default_body()
    for e in stationary_ellipses(body, 2.0, 0.5) + stationary_ellipses(body, 0.4, 1.7):
        y = e.y
        Jac = reduced_jacobian(body, y)
        s = y[:3]
        a = e.omega3 / (2.0 * e.s3)
        Hc = hamiltonian_hessian(body, y[:10])
        Hc[:3, :3] -= 2.0 * a * np.eye(3)
        B = np.zeros((10, 10))
        # ṡ = ω × s = −ŝ ω  (corrected bracket, NOTES E3)
        B[:3, :3] = -np.array([[0, -s[2], s[1]], [s[2], 0, -s[0]], [-s[1], s[0], 0]])
        for qi, pi in ((7, 4), (8, 5), (9, 6)):  # (λ, p_λ), (μ, p_μ), (ϱ, p_ϱ)
            B[qi, pi] = 1.0
            B[pi, qi] = -1.0
        assert np.max(np.abs(Jac - B @ Hc)) < 1e-7 * max(1.0, np.max(np.abs(Jac)))


def test_stationarity_by_simulation_v3_and_v2():
    for body, s3, pt in (
        (default_body(), 2.0, 0.5),
        (default_body(), 1.45, 1.77),
        (
            Body(
                inertia=Inertia.isotropic(1.0, 1.0),
                potential=V2(c=1.0, d=2.0),
                thickness=ThicknessPotential(a=1.0, b=1.0),
            ),
            2.0,
            0.5,
        ),
    ):
        for e in stationary_ellipses(body, s3, pt):
            check = verify_stationary(body, e, t_end=100.0)
            assert check.passed, check.drift
            assert check.max_drift <= 1e-8


def test_predicted_growth_rate_confirmed_by_simulation_v1():
    body = v1_body()
    r = analyse_stability(body, stationary_ellipses(body, 2.5, 1.5)[0])
    g = verify_growth(body, r)
    assert g.passed and g.relative_error < 0.10
    assert g.measured_rate == pytest.approx(math.sqrt(3.0 / 13.0), rel=0.10)


def test_predicted_growth_rate_confirmed_by_simulation_v3():
    body = default_body()
    r = stability_of(body, 3.0, 1.0)[0]
    assert r.classification == "hyperbolic"
    g = verify_growth(body, r)
    assert g.relative_error < 0.10, (g.predicted_rate, g.measured_rate)


def test_stable_ellipse_stays_bounded_and_unstable_does_not():
    body = v1_body()
    stable = analyse_stability(body, stationary_ellipses(body, 1.5, 2.5)[0])
    check = verify_bounded(body, stable, eps=1e-6, t_end=60.0)
    assert check.passed and check.max_ratio < 100
    unstable = analyse_stability(body, stationary_ellipses(body, 2.5, 1.5)[0])
    bad = verify_bounded(body, unstable, eps=1e-6, t_end=60.0)
    assert not bad.passed and bad.max_ratio > 1e3


def test_energy_casimir_certificate_on_default_body():
    body = default_body()
    circ = stability_of_shape(body, 1.4, 0.9)
    kinds = {r.ellipse.kind: r for r in circ}
    assert kinds["circulating"].nonlinear == "stable" and kinds["circulating"].energy_casimir == "definite"
    assert kinds["rigid"].classification == "hyperbolic"  # μ < ϱ* < λ: the intermediate axis (NOTES §7)
    assert min(kinds["circulating"].energy_casimir_eigenvalues) > 0


def test_sample_stable_target_is_stable_and_stationary():
    body = default_body()
    rng = np.random.default_rng(3)
    for kind in ("rigid", "circulating"):
        r = sample_stable_target(body, rng, kind=kind, require="stable")
        assert r.classification == "elliptic" and r.nonlinear == "stable" and r.ellipse.kind == kind
        assert r.ellipse.residual <= 1e-10
    with pytest.raises(ValueError, match="require"):
        sample_stable_target(body, rng, require="maybe")
