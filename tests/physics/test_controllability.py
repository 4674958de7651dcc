"""The reachability measure behind the task's target filter (flatbody_env.physics.controllability)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from flatbody_env.physics.body import default_body
from flatbody_env.physics.controllability import (
    REDUCED_STATE,
    linearize,
    settling_rate,
    settling_rate_map,
    target_state,
)
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.equilibria import stationary_from_shape
from flatbody_env.env.task import DEFAULT_LIMITS, ReachStationaryEllipse
from oracles import lqr_rate

LIMITS = np.array(DEFAULT_LIMITS)


def _y(body, lam, aspect, sign=1.0):
    t = stationary_from_shape(body, lam, lam / aspect, sign=sign)
    return target_state(t.lam, t.mu, t.rho, t.s3, t.p_theta)


def test_linearization_is_the_small_signal_model():
    body = default_body()
    y = _y(body, 1.5, 2.2)
    assert np.max(np.abs(rhs(0.0, y, None, body)[list(REDUCED_STATE)])) < 1e-12  # an equilibrium
    A, B = linearize(body, y, LIMITS)
    rng = np.random.default_rng(1)
    dx, a = rng.normal(size=9) * 1e-5, rng.uniform(-1, 1, 4) * 1e-5
    yp = y.copy()
    yp[list(REDUCED_STATE)] += dx
    np.testing.assert_allclose(rhs(0.0, yp, a * LIMITS, body)[list(REDUCED_STATE)], A @ dx + B @ a, atol=1e-9)


@pytest.mark.parametrize("lam, aspect", [(1.25, 1.3), (1.4, 1.9), (1.7, 2.0), (1.6, 2.5)])
def test_settling_rate_is_the_cheap_control_limit(lam, aspect):
    """The slow pole stops moving as control gets cheaper (R 1e-4 → 1e-8): more gain does not settle faster."""
    body = default_body()
    y = _y(body, lam, aspect)
    A, B = linearize(body, y, LIMITS)
    r = settling_rate(body, y, LIMITS)
    moderate, _ = lqr_rate(A, B, np.diag([1.0] * 3 + [10.0] * 6), 0.1 * np.eye(4))  # the agents' LQR weights
    cheap, K = lqr_rate(A, B, np.eye(9), 1e-8 * np.eye(4))
    assert r > 0 and cheap == pytest.approx(r, rel=2e-3)
    # the agents' LQR (other state weights, 1000× dearer control) settles at least about as fast
    assert moderate >= 0.99 * r
    # same for the time-reversed ellipse (the sign of (s3, p_theta))
    assert settling_rate(body, _y(body, lam, aspect, sign=-1.0), LIMITS) == pytest.approx(r, rel=1e-6)
    # the closed loop's slowest error decays as e^(-r t): a generic initial error after 40 s
    x0 = np.random.default_rng(0).normal(size=9)
    x1, x2 = expm((A - B @ K) * 40.0) @ x0, expm((A - B @ K) * 60.0) @ x0
    assert -math.log(np.linalg.norm(x2) / np.linalg.norm(x1)) / 20.0 == pytest.approx(cheap, rel=0.05)


def test_settling_rate_grows_toward_the_edge_of_existence_and_needs_tau3_and_force():
    body = default_body()
    grid = settling_rate_map(body, [1.4, 1.6], [1.1, 1.5, 1.9, 2.5], LIMITS)
    by = {(e.lam, e.aspect): e for e in grid}
    assert len(grid) == 8 and not by[(1.4, 2.5)].exists and math.isnan(by[(1.4, 2.5)].rate)
    rates_16 = [by[(1.6, a)].rate for a in (1.1, 1.5, 1.9, 2.5)]
    assert np.all(np.diff(rates_16) > 0) and rates_16[0] < 0.01 and rates_16[-1] > 0.25
    y = _y(body, 1.6, 2.5)
    for mask in ([0, 0, 0, 1], [1, 1, 1, 0], [1, 1, 0, 1]):  # no τ3: shape; no force: ϱ — not stabilisable
        assert settling_rate(body, y, LIMITS, np.array(mask, dtype=bool)) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.slow  # long: integrates hundreds of episodes
def test_task_samples_only_targets_reachable_in_the_episode():
    body = default_body()
    task = ReachStationaryEllipse()
    rng = np.random.default_rng(3)
    rates = []
    for _ in range(30):
        t = task.sample_target(rng, body)
        assert t.stable
        rates.append(settling_rate(body, target_state(t.lam, t.mu, t.rho, t.s3, t.p_theta), LIMITS))
    assert min(rates) >= task.min_settling_rate == 0.15
    # a typical target of the old ranges is filtered out; without the filter it is accepted
    slow = stationary_from_shape(body, 1.25, 1.25 / 1.3)
    assert not task.reachable(slow, body)
    assert ReachStationaryEllipse(min_settling_rate=0.0).reachable(slow, body)
    assert task.reachable(slow, body, control="torque")  # filter not applicable without force
    with pytest.raises(ValueError, match="min_settling_rate"):
        ReachStationaryEllipse(min_settling_rate=-1.0)
    with pytest.raises(ValueError, match="min_settling_rate"):
        ReachStationaryEllipse(
            target_lambda=(1.25, 1.3), target_aspect=(1.3, 1.4), min_settling_rate=5.0
        ).sample_target(rng, body)


def test_smallest_eigenvalue_closed_form_matches_numpy():
    """The shape block's stability test uses a closed-form smallest eigenvalue (it runs at every reset)."""
    from flatbody_env.physics.equilibria import smallest_eigenvalue_sym3

    rng = np.random.default_rng(0)
    for k in range(300):
        M = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-3, 3)
        H = 0.5 * (M + M.T)
        if k % 3 == 0:
            H[0, 2] = H[2, 0] = H[1, 2] = H[2, 1] = 0.0  # the shape block's usual (λ, μ) | ϱ split
        expected = np.linalg.eigvalsh(H)[0]
        assert abs(
            smallest_eigenvalue_sym3(H[0, 0], H[0, 1], H[0, 2], H[1, 1], H[1, 2], H[2, 2]) - expected
        ) <= 1e-12 * max(1.0, np.abs(H).max())
    assert smallest_eigenvalue_sym3(2.0, 0.0, 0.0, 2.0, 0.0, 2.0) == 2.0
