"""Kinematic identities: eqs. (21)–(27), (33)–(35), (51) of the paper, E7 of NOTES, and the inverse map."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import BODIES, random_state
from flatbody_env.physics.hamiltonian import velocities_from_momenta
from flatbody_env.physics.kinematics import (
    Decomposition,
    cauchy_rate,
    cauchy_tensor,
    configuration,
    configuration_rate,
    decompose,
    deformation_invariants,
    green_rate,
    green_tensor,
    kirchhoff_love_residual,
    omega_matrix,
)


def _samples(n=30, seed=5):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        y = random_state(rng)
        R = Rotation.random(random_state=rng).as_matrix()
        yield y, R


def test_kirchhoff_love_and_tensors():
    for y, R in _samples():
        lam, mu, rho, th = y[7:11]
        Phi = configuration(lam, mu, rho, th, R)
        np.testing.assert_allclose(kirchhoff_love_residual(Phi, lam, mu, rho), 0.0, atol=1e-13)
        G = green_tensor(lam, mu, rho, th)
        np.testing.assert_allclose(G, Phi.T @ Phi, atol=1e-13)
        np.testing.assert_allclose(G[2, :2], 0.0, atol=1e-15)  # eq. (33): block form
        np.testing.assert_allclose(deformation_invariants(G), np.sort([lam**2, mu**2, rho**2]), rtol=1e-12)
        C = cauchy_tensor(lam, mu, rho, R)
        Pinv = np.linalg.inv(Phi)
        np.testing.assert_allclose(C, Pinv.T @ Pinv, rtol=1e-11, atol=1e-12)  # E7: R D⁻² Rᵀ, not R D² Rᵀ
        assert np.abs(C - R @ np.diag([lam**2, mu**2, rho**2]) @ R.T).max() > 1e-2
        np.testing.assert_allclose(deformation_invariants(C), np.sort([lam**-2, mu**-2, rho**-2]), rtol=1e-11)


def test_rates_match_finite_differences():
    """Φ̇ (eq. (27)), dG/dt and dC/dt (eq. (51) with E7) against central differences along Ṙ = R W(ω)."""
    body = BODIES["V3"]
    h = 1e-6
    for y, R in _samples(10):
        vel = velocities_from_momenta(y, body)
        omega = np.array([vel["omega1"], vel["omega2"], vel["omega3"]])
        rates = np.array([vel["lambda_dot"], vel["mu_dot"], vel["rho_dot"], vel["theta_dot"]])

        def at(dt, y=y, rates=rates, R=R, omega=omega):
            lam, mu, rho, th = y[7:11] + dt * rates
            from scipy.linalg import expm

            Rt = R @ expm(dt * omega_matrix(omega))
            return configuration(lam, mu, rho, th, Rt), green_tensor(lam, mu, rho, th), cauchy_tensor(lam, mu, rho, Rt)

        (Pp, Gp, Cp), (Pm, Gm, Cm) = at(h), at(-h)
        Phid = configuration_rate(y[7], y[8], y[9], y[10], vel, R)
        np.testing.assert_allclose(Phid, (Pp - Pm) / (2 * h), atol=1e-7)
        Gd = green_rate(y[7], y[8], y[9], y[10], vel["theta_dot"], vel["lambda_dot"], vel["mu_dot"], vel["rho_dot"])
        np.testing.assert_allclose(Gd, (Gp - Gm) / (2 * h), atol=1e-7)
        Cd = cauchy_rate(y[7], y[8], y[9], R, omega, vel["lambda_dot"], vel["mu_dot"], vel["rho_dot"])
        np.testing.assert_allclose(Cd, (Cp - Cm) / (2 * h), atol=1e-6)


def test_inverse_map_round_trip():
    for y, R in _samples():
        lam, mu, rho, th = y[7:11]
        Phi = configuration(lam, mu, rho, th, R)
        ref = Decomposition(R=R, lam=lam, mu=mu, rho=rho, theta=th)
        # perturb the reference a little: continuity must still find the exact branch
        near = Decomposition(R=R, lam=lam * 1.01, mu=mu * 0.99, rho=rho, theta=th + 0.1)
        dec = decompose(Phi, near)
        np.testing.assert_allclose(dec.R, R, atol=1e-12)
        np.testing.assert_allclose([dec.lam, dec.mu, dec.rho, dec.theta], [lam, mu, rho, th], atol=1e-12)
        # without a reference: λ ≥ μ and the same Φ
        free = decompose(Phi)
        assert free.lam >= free.mu
        np.testing.assert_allclose(configuration(free.lam, free.mu, free.rho, free.theta, free.R), Phi, atol=1e-12)
        assert ref.R is R


def test_inverse_map_rejects_bad_matrices():
    Phi = configuration(1.2, 0.8, 1.0, 0.3)
    with pytest.raises(ValueError, match="det"):
        decompose(Phi @ np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="Kirchhoff"):
        bad = Phi.copy()
        bad[:, 2] += 0.1 * Phi[:, 0]
        decompose(bad)
    with pytest.raises(ValueError, match="parallel"):
        flat = Phi.copy()
        flat[:, 1] = 0.5 * flat[:, 0]
        decompose(flat)
