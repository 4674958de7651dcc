"""Legendre transform and kinetic energy (eqs. (28)–(32) of the paper, E1 of NOTES)."""

from __future__ import annotations

import math

import numpy as np

from conftest import BODIES, random_state
from oracles import independent_mass_matrix
from flatbody_env.physics.hamiltonian import (
    VELOCITY_NAMES,
    kinetic_energy,
    mass_matrix,
    momenta_from_velocities,
    velocities_from_momenta,
)
from flatbody_env.physics.kinematics import configuration_rate


def test_legendre_round_trip(body):
    rng = np.random.default_rng(1)
    for _ in range(50):
        y = random_state(rng)
        vel = velocities_from_momenta(y, body)
        p = momenta_from_velocities(vel, lam=y[7], mu=y[8], rho=y[9], theta=y[10], inertia=body.inertia)
        np.testing.assert_allclose(
            [p[k] for k in ("s1", "s2", "s3", "p_theta", "p_lambda", "p_mu", "p_rho")], y[:7], rtol=1e-11, atol=1e-11
        )


def test_kinetic_energy_three_ways(body):
    """½ Tr(J Φ̇ᵀ Φ̇) from matrices = ½ vᵀ M v (eq. (30) corrected / eq. (31)) = 𝒯(p) (eq. (32))."""
    rng = np.random.default_rng(2)
    for _ in range(50):
        y = random_state(rng)
        vel = velocities_from_momenta(y, body)
        v = np.array([vel[k] for k in VELOCITY_NAMES])
        Phid = configuration_rate(y[7], y[8], y[9], y[10], vel)
        t_matrix = 0.5 * np.trace(body.inertia.matrix @ Phid.T @ Phid)
        t_eq30 = 0.5 * v @ mass_matrix(y[7], y[8], y[9], y[10], body.inertia) @ v
        t_eq32 = kinetic_energy(y, body)
        assert math.isclose(t_matrix, t_eq30, rel_tol=1e-11)
        assert math.isclose(t_matrix, t_eq32, rel_tol=1e-11)
        np.testing.assert_allclose(
            mass_matrix(y[7], y[8], y[9], y[10], body.inertia), independent_mass_matrix(y, body), atol=1e-12
        )


def test_printed_eq30_factor_is_a_misprint():
    """Erratum E1: with the printed (J1−J2) sin 2θ the energy disagrees with ½Tr(JΦ̇ᵀΦ̇)."""
    body = BODIES["V3-anisotropic"]
    J1, J2, J3 = body.inertia.J1, body.inertia.J2, body.inertia.J3
    lam, mu, rho, th = 1.3, 0.7, 0.9, 0.6
    w1, w2, w3, thd, ld, md, rd = 0.3, -0.4, 0.5, 0.2, 0.1, -0.3, 0.2
    c, s = math.cos(th), math.sin(th)
    A, B = J1 * c * c + J2 * s * s, J1 * s * s + J2 * c * c

    def eq30(factor):
        return (
            A / 2 * ld**2
            + B / 2 * md**2
            + J3 / 2 * rd**2
            + (B * mu**2 + J3 * rho**2) / 2 * w1**2
            + (A * lam**2 + J3 * rho**2) / 2 * w2**2
            + (J1 + J2) * lam * mu * w3 * thd
            + (J1 - J2) * factor * ((mu * md - lam * ld) * thd + (lam * md - mu * ld) * w3 + lam * mu * w1 * w2)
            + (A * lam**2 + B * mu**2) / 2 * w3**2
            + (B * lam**2 + A * mu**2) / 2 * thd**2
        )

    vel = dict(zip(VELOCITY_NAMES, (w1, w2, w3, thd, ld, md, rd)))
    Phid = configuration_rate(lam, mu, rho, th, vel)
    exact = 0.5 * np.trace(body.inertia.matrix @ Phid.T @ Phid)
    assert math.isclose(eq30(s * c), exact, rel_tol=1e-12)  # corrected
    assert abs(eq30(math.sin(2 * th)) - exact) > 1e-3  # as printed
