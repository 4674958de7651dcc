"""Where methods fail: near λ = μ the regular chart keeps its accuracy, and the
fixed-step two-polar methods fail *visibly* (IntegrationError / status flag)."""

from __future__ import annotations

import numpy as np
import pytest

from flatbody_env.integrators import IntegrationError, Tolerances, get_method
from flatbody_env.scene import load_scene
from flatbody_env.physics.state import pack

T_END = 6.0  # the first close pass of the close-approach family is at t ≈ 0.3


def gap_scene(delta):
    """The built-in close-approach scene with σ₋ = s3 − p_θ = delta (smaller delta: closer pass)."""
    return load_scene("close-approach").with_state(s3=1.0 + 0.5 * delta, p_theta=1.0 - 0.5 * delta)


def _min_relative_gap(Z):
    n11 = (Z[0:3] ** 2).sum(0)
    n22 = (Z[3:6] ** 2).sum(0)
    n12 = (Z[0:3] * Z[3:6]).sum(0)
    disc = np.sqrt(0.25 * (n11 - n22) ** 2 + n12**2)
    lam = np.sqrt(0.5 * (n11 + n22) + disc)
    mu = np.sqrt(np.maximum(0.5 * (n11 + n22) - disc, 0.0))
    return float(np.min((lam - mu) / lam))


@pytest.fixture(scope="module")
def regular_chart_errors():
    errors = {}
    for delta in (1e-2, 1e-4, 1e-6):
        sc = gap_scene(delta)
        y0 = pack(sc.state)
        times = np.linspace(0.0, T_END, 3)
        ref = get_method("DOP853-regular").integrate(sc.body, y0, times, tol=Tolerances(rtol=1e-12, atol=1e-12))
        sol = get_method("RATTLE-suzuki4").integrate(
            sc.body, y0, np.linspace(0.0, T_END, 1201), tol=Tolerances(step=0.01)
        )
        errors[delta] = (np.max(np.abs(sol.Y[:, ::600] - ref.Y)), _min_relative_gap(sol.stats["regular"]))
    return errors


def test_the_family_really_approaches_lambda_equals_mu(regular_chart_errors):
    gaps = [regular_chart_errors[d][1] for d in (1e-2, 1e-4, 1e-6)]
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] < 1e-3  # sampled every 0.005: an upper bound of the true closest approach


def test_regular_chart_error_does_not_grow_as_the_gap_shrinks(regular_chart_errors):
    e = {d: regular_chart_errors[d][0] for d in regular_chart_errors}
    assert all(v < 1e-7 for v in e.values()), e
    assert e[1e-6] < 10.0 * e[1e-2] and e[1e-4] < 10.0 * e[1e-2], e


@pytest.mark.parametrize("name", ["RK4", "splitting-strang", "splitting-suzuki4", "splitting-yoshida4"])
def test_fixed_step_two_polar_methods_fail_near_lambda_equals_mu_and_say_so(name):
    sc = gap_scene(1e-6)
    y0 = pack(sc.state)
    with pytest.raises(IntegrationError) as info:
        get_method(name).integrate(sc.body, y0, np.linspace(0.0, T_END, 7), tol=Tolerances(step=0.01, energy_tol=1e-3))
    assert info.value.kind in {"chart-singularity", "under-resolved", "non-finite", "energy", "domain"}
    assert 0.0 < info.value.t <= T_END


@pytest.mark.parametrize("name", ["RK4", "splitting-suzuki4"])
def test_the_same_step_is_fine_away_from_lambda_equals_mu(name):
    """The failure above is the chart's, not the step size's: on the 1e-2 orbit the run succeeds."""
    sc = gap_scene(1e-1)
    y0 = pack(sc.state)
    sol = get_method(name).integrate(
        sc.body, y0, np.linspace(0.0, T_END, 7), tol=Tolerances(step=0.01, energy_tol=1e-3)
    )
    assert np.all(np.isfinite(sol.Y))


def test_adaptive_two_polar_pays_with_cost_near_lambda_equals_mu():
    costs = []
    for delta in (1e-1, 1e-5):
        sc = gap_scene(delta)
        sol = get_method("DOP853-numba").integrate(
            sc.body, pack(sc.state), np.array([0.0, T_END]), tol=Tolerances(rtol=1e-10, atol=1e-12)
        )
        costs.append(sol.nfev)
    assert costs[1] > 2 * costs[0]


def test_env_flag_for_a_step_across_the_close_pass():
    from flatbody_env.integrators.compiled_methods import env_stepper, kernel_params

    sc = gap_scene(1e-6)
    y = pack(sc.state)
    P = kernel_params(sc.body)
    st = env_stepper("splitting-suzuki4")
    out = np.empty(11)
    statuses = []
    for _ in range(int(T_END / 0.05)):
        s = st.step(y, np.zeros(4), P, 0.05, 0.01, 0.0, 0.0, 1e-3, out)
        statuses.append(s)
        if s != 0:
            break
        y = out.copy()
    assert statuses[-1] != 0
