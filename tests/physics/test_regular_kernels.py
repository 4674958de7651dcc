"""The physics layer's plain-float kernels of the regular formulation, run as plain Python, against
independent forms: the (λ, μ) gradient of eqs. (37)–(40), the SVD, :func:`~flatbody_env.physics.kinematics.decompose`
and the numpy :func:`~flatbody_env.physics.regular.regular_energy`."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import random_state
from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.kinematics import decompose, decompose_kernel, stretches_kernel
from flatbody_env.physics.potentials import (
    KIND_CUSTOM,
    V1,
    V2,
    V3,
    ThicknessPotential,
    invariant_gradient_kernel,
    potential_kernel,
)
from flatbody_env.physics.regular import (
    regular_energy,
    regular_energy_kernel,
    regular_forces_kernel,
    regular_from_paper,
)

POTENTIALS = [V1(k=1.7), V2(c=0.9, d=0.9), V3(kappa=1.3)]
BODIES = [
    Body(inertia=Inertia(J1=1.2, J2=0.8, J3=0.9), potential=p, thickness=ThicknessPotential(a=0.7, b=1.4))
    for p in POTENTIALS
]


@pytest.mark.parametrize("pot", POTENTIALS, ids=["V1", "V2", "V3"])
def test_invariant_gradient_is_the_chain_rule_of_the_stretch_gradient(pot):
    """∂V/∂λ = 2λ V_tr + 2λμ² V_det and ∂V/∂μ = 2μ V_tr + 2λ²μ V_det with V_λ, V_μ of eqs. (37)–(39) (tr = λ² + μ², det = λ²μ²)."""
    rng = np.random.default_rng(5)
    c1, c2 = pot.constants
    for _ in range(20):
        lam, mu = rng.uniform(0.3, 2.5, size=2)
        vt, vd = invariant_gradient_kernel(pot.kind, c1, lam * lam + mu * mu, lam * lam * mu * mu)
        _, gl, gm, _ = potential_kernel(pot.kind, c1, c2, 0.0, 0.0, lam, mu, 1.0)
        assert 2.0 * lam * vt + 2.0 * lam * mu * mu * vd == pytest.approx(gl, rel=1e-13, abs=1e-13)
        assert 2.0 * mu * vt + 2.0 * lam * lam * mu * vd == pytest.approx(gm, rel=1e-13, abs=1e-13)
    assert invariant_gradient_kernel(KIND_CUSTOM, c1, 2.0, 1.0) == (0.0, 0.0)


@pytest.mark.parametrize("body", BODIES, ids=["V1", "V2", "V3"])
def test_energy_and_forces_kernels_equal_the_numpy_forms(body):
    """regular_energy_kernel equals regular_energy; regular_forces_kernel is −∂V/∂q (central differences) plus f_ϱ ψ/ϱ."""
    rng = np.random.default_rng(6)
    P = np.array(body.kernel_params())
    for _ in range(5):
        y = random_state(rng)
        z = regular_from_paper(y, body)
        assert regular_energy_kernel(z, P) == pytest.approx(regular_energy(z, body, y[7] > y[8]), rel=1e-13)
        lam, mu, rho = stretches_kernel(z)
        assert (lam, mu, rho) == pytest.approx((max(y[7], y[8]), min(y[7], y[8]), y[9]), rel=1e-13)
        q, F = z[:9].copy(), np.empty(9)
        det = regular_forces_kernel(q, P, 0.0, F)
        assert det == pytest.approx((y[7] * y[8]) ** 2, rel=1e-12)
        rest = np.concatenate([q, np.zeros(9)])
        for i in range(9):
            e = np.zeros(18)
            e[i] = 1e-6
            g = (regular_energy(rest + e, body, y[7] > y[8]) - regular_energy(rest - e, body, y[7] > y[8])) / 2e-6
            assert F[i] == pytest.approx(-g, rel=1e-6, abs=1e-7)
        F_push = np.empty(9)
        regular_forces_kernel(q, P, 0.75, F_push)
        np.testing.assert_allclose(F_push - F, np.concatenate([np.zeros(6), 0.75 * q[6:] / rho]), atol=1e-15)


def test_decompose_kernel_equals_decompose_to_round_off():
    """The closed-form kernel picks the candidate that decompose picks, near a shifted reference, keep_order or not."""
    rng = np.random.default_rng(7)
    body = BODIES[2]
    for k in range(20):
        y = random_state(rng)
        Phi = regular_from_paper(y, body)[:9].reshape(3, 3).T
        ref = decompose(Phi)
        ref = type(ref)(R=ref.R, lam=ref.lam, mu=ref.mu, rho=ref.rho, theta=ref.theta + 2.0 * np.pi * (k % 3 - 1) + 0.1)
        keep = bool(k % 2)
        want = decompose(Phi, ref, kl_tol=np.inf, keep_order=keep)
        out = np.empty(13)
        jump = decompose_kernel(
            Phi.T.ravel(), np.concatenate([ref.R.ravel(), [ref.lam, ref.mu, ref.rho, ref.theta]]), keep, out
        )
        np.testing.assert_allclose(
            out, np.concatenate([want.R.ravel(), [want.lam, want.mu, want.rho, want.theta]]), atol=1e-12
        )
        assert jump == pytest.approx(abs(want.theta - ref.theta) + np.linalg.norm(want.R - ref.R), abs=1e-12)
