"""Convergence and accuracy of the compiled integrators.

Orders are measured on a smooth short problem (the default scene, t = 2) against a DOP853
reference at rtol = atol = 1e-14 that is cross-checked by scipy's DOP853 (independent code).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flatbody_env.physics.equations import rhs

from flatbody_env.physics.invariants import casimir
from flatbody_env.integrators import Tolerances, available_methods, get_method
from flatbody_env.scene import load_scene
from flatbody_env.physics.state import pack

FIXED = {
    "RK4": 4,
    "splitting-strang": 2,
    "splitting-suzuki4": 4,
    "splitting-yoshida4": 4,
    "RATTLE": 2,
    "RATTLE-suzuki4": 4,
    "RATTLE-kahanli6": 6,
}


@pytest.fixture(scope="module")
def smooth_problem():
    sc = load_scene("default")
    y0 = pack(sc.state)
    times = np.array([0.0, 2.0])
    ref = get_method("DOP853-numba").integrate(sc.body, y0, times, tol=Tolerances(rtol=1e-14, atol=1e-14)).Y[:, -1]
    ref_scipy = get_method("DOP853").integrate(sc.body, y0, times, tol=Tolerances(rtol=1e-13, atol=1e-13)).Y[:, -1]
    assert np.max(np.abs(ref - ref_scipy)) < 1e-11  # the reference's own floor
    return sc, y0, times, ref


def test_every_fixed_step_method_is_covered():
    fixed = {m.name for m in available_methods() if not m.adaptive}
    assert fixed == set(FIXED)
    for m in available_methods():
        if m.name in FIXED:
            assert m.order == FIXED[m.name]


@pytest.mark.parametrize("name", sorted(FIXED))
def test_measured_order_within_0_3_of_nominal(smooth_problem, name):
    sc, y0, times, ref = smooth_problem
    hs = {2: np.array([0.05, 0.025, 0.0125]), 4: np.array([0.1, 0.05, 0.025]), 6: np.array([0.2, 0.1, 0.05])}[
        FIXED[name]
    ]
    err = []
    for h in hs:
        Y = get_method(name).integrate(sc.body, y0, times, tol=Tolerances(step=float(h))).Y
        err.append(np.max(np.abs(Y[:, -1] - ref)))
    err = np.array(err)
    assert np.all(err > 1e-12), f"{name}: errors {err} hit the reference floor; the order would be meaningless"
    order = np.polyfit(np.log(hs), np.log(err), 1)[0]
    assert abs(order - FIXED[name]) <= 0.3, f"{name}: measured order {order:.2f}, nominal {FIXED[name]}"


def test_dop853_port_takes_scipys_steps():
    """Same coefficients and step control as scipy: identical RHS counts and agreement to round-off."""
    sc = load_scene("regular")
    y0 = pack(sc.state)
    times = np.array([0.0, 20.0])
    for rtol in (1e-6, 1e-10):
        tol = Tolerances(rtol=rtol, atol=rtol * 1e-3)
        a = get_method("DOP853-numba").integrate(sc.body, y0, times, tol=tol)
        b = solve_ivp(
            lambda t, y: rhs(t, y, None, sc.body), (0.0, 20.0), y0, method="DOP853", rtol=tol.rtol, atol=tol.atol
        )
        assert a.nfev == b.nfev
        assert a.stats["steps"] == b.t.size - 1
        assert np.max(np.abs(a.Y[:, -1] - b.y[:, -1])) < 1e-11


# every registered method, at a setting that should reach ~1e-7 on the regular scene (t = 10)
SETTINGS = {
    "RK23": dict(rtol=1e-10, atol=1e-12),
    "RK45": dict(rtol=1e-10, atol=1e-12),
    "DOP853": dict(rtol=1e-10, atol=1e-12),
    "Radau": dict(rtol=1e-10, atol=1e-12),
    "BDF": dict(rtol=1e-10, atol=1e-12),
    "LSODA": dict(rtol=1e-10, atol=1e-12),
    "DOP853-numba": dict(rtol=1e-10, atol=1e-12),
    "RK4": dict(step=0.01),
    "splitting-strang": dict(step=0.001),
    "splitting-suzuki4": dict(step=0.01),
    "splitting-yoshida4": dict(step=0.01),
    "RATTLE": dict(step=0.001),
    "RATTLE-suzuki4": dict(step=0.01),
    "RATTLE-kahanli6": dict(step=0.02),
}


@pytest.fixture(scope="module")
def regular_reference():
    sc = load_scene("regular")
    y0 = pack(sc.state)
    times = np.linspace(0.0, 10.0, 6)
    ref = get_method("DOP853-numba").integrate(sc.body, y0, times, tol=Tolerances(rtol=1e-13, atol=1e-14)).Y
    cross = get_method("RATTLE-suzuki4").integrate(sc.body, y0, times, tol=Tolerances(step=0.0025)).Y
    assert np.max(np.abs(ref - cross)) < 1e-9  # two charts, two algorithms
    return sc, y0, times, ref


@pytest.mark.parametrize("name", sorted({m.name for m in available_methods()}))
def test_every_method_agrees_with_the_reference_on_the_regular_scene(regular_reference, name):
    sc, y0, times, ref = regular_reference
    base = name[: -len("-regular")] if name.endswith("-regular") else name
    if name.endswith("-regular") and base in ("Radau", "BDF", "LSODA", "RK23"):
        kw = dict(rtol=1e-8, atol=1e-10)  # slow implicit/low-order scipy runs on 18 variables
        bound = 1e-5
    else:
        kw = SETTINGS[base]
        bound = 1e-6
    sol = get_method(name).integrate(sc.body, y0, times, tol=Tolerances(**kw))
    assert sol.Y.shape == (11, times.size)
    err = np.max(np.abs(sol.Y - ref))
    assert err < bound, f"{name}: max error {err:.3g}"


@pytest.mark.parametrize("name", ["splitting-strang", "splitting-suzuki4", "splitting-yoshida4"])
def test_splitting_keeps_casimir_and_p_theta_to_1e_13(name):
    sc = load_scene("default")  # s1, s2 ≠ 0: all three spin rotations are active
    y0 = pack(sc.state)
    times = np.linspace(0.0, 100.0, 201)
    Y = get_method(name).integrate(sc.body, y0, times, tol=Tolerances(step=0.05)).Y
    c = casimir(Y[0], Y[1], Y[2])
    assert np.max(np.abs(c - c[0])) <= 1e-13 * max(1.0, c[0])
    assert np.max(np.abs(Y[3] - y0[3])) <= 1e-13
    # and the dynamics is not frozen: the spin really rotated
    assert np.ptp(Y[0]) > 1e-2 and np.ptp(Y[2]) > 1e-3


def test_splitting_energy_error_is_bounded_over_a_long_horizon():
    """Symplectic: no drift. The energy error at t = 2000 is no larger than at t = 200 (×3 margin)."""
    from flatbody_env.physics.hamiltonian import hamiltonian_series

    sc = load_scene("long-horizon")
    y0 = pack(sc.state)
    times = np.linspace(0.0, 2000.0, 401)
    Y = get_method("splitting-suzuki4").integrate(sc.body, y0, times, tol=Tolerances(step=0.1)).Y
    dH = np.abs(hamiltonian_series(Y, sc.body) - hamiltonian_series(Y[:, :1], sc.body)[0])
    early = dH[times <= 200].max()
    late = dH[times > 1800].max()
    assert early > 0 and late < 3.0 * early + 1e-14
