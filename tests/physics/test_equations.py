"""The equations of motion against Hamilton's equations of an independently built H.

H is assembled from matrices (T = ½ Tr(J Φ̇ᵀ Φ̇) with Φ̇ from eq. (27) of the paper, then
inverted numerically), differentiated by central differences, and combined with the corrected
bracket {s_i, s_j} = +ε_ijk s_k (NOTES E3): ṡ = ω × s, q̇ = ∂H/∂p, ṗ = −∂H/∂q.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from conftest import BODIES, random_state
from oracles import hamilton_rhs, printed_eqs_44_46, printed_eqs_47_49
from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.potentials import ThicknessPotential, V3

N_STATES = 100


@pytest.mark.parametrize("name", sorted(BODIES))
def test_rhs_equals_hamilton_equations(name):
    body = BODIES[name]
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    worst = 0.0
    for _ in range(N_STATES):
        y = random_state(rng)
        ref = hamilton_rhs(y, body)
        got = rhs(0.0, y, None, body)
        err = np.max(np.abs(got - ref) / (1.0 + np.abs(ref)))
        worst = max(worst, err)
    assert worst < 1e-7, f"{name}: worst relative residual {worst:.2e}"


def test_controls_enter_as_torque_and_dilatation_force(body):
    rng = np.random.default_rng(7)
    y = random_state(rng)
    u = np.array([0.3, -0.2, 0.5, 0.7])
    diff = rhs(0.0, y, u, body) - rhs(0.0, y, None, body)
    expected = np.zeros(11)
    expected[[0, 1, 2, 6]] = u
    np.testing.assert_allclose(diff, expected, atol=1e-12)


def test_theta_cyclic_only_when_isotropic():
    rng = np.random.default_rng(3)
    y = random_state(rng)
    iso = BODIES["V3"]
    aniso = Body(
        inertia=Inertia(J1=1.3, J2=0.7, J3=1.0), potential=V3(kappa=1.0), thickness=ThicknessPotential(a=1, b=1)
    )
    assert rhs(0.0, y, None, iso)[3] == 0.0
    assert abs(rhs(0.0, y, None, aniso)[3]) > 1e-3


@pytest.mark.parametrize("name", ["V1", "V2", "V3"])
def test_paper_convention_reproduces_printed_equations(name):
    base = BODIES[name]
    paper = Body(inertia=base.inertia, potential=base.potential, thickness=base.thickness, spin_convention="paper")
    J, J3 = base.inertia.J1, base.inertia.J3
    rng = np.random.default_rng(11)
    for _ in range(50):
        y = random_state(rng)
        got_paper = rhs(0.0, y, None, paper)
        got_default = rhs(0.0, y, None, base)
        np.testing.assert_allclose(got_paper[:3], printed_eqs_44_46(y, J, J3), rtol=1e-9, atol=1e-11)
        # the default (corrected bracket) is the printed spin equations with the opposite sign (E4)
        np.testing.assert_allclose(got_default[:3], -printed_eqs_44_46(y, J, J3), rtol=1e-9, atol=1e-11)
        # eqs. (47)–(49) are correct as printed, in both conventions
        np.testing.assert_allclose(got_default[4:7], printed_eqs_47_49(y, J, J3, base), rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(got_paper[4:7], got_default[4:7], rtol=0, atol=0)
