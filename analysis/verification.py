"""Verification of stationary ellipses and their stability by direct simulation.

* :func:`verify_stationary` — from a stationary ellipse, λ, μ, ϱ, the spins and momenta, ω3, θ̇
  and the invariants (H, |s|², p_θ, laboratory spin R s) stay constant; the largest drift over
  t = 100 must be ≤ 1e-8 (integrated with DOP853 at rtol = 1e-13, atol = 1e-15 by
  :func:`flatbody_env.simulation.simulate`; near an equilibrium the error estimate is tiny and the
  steps grow long, so with atol = 1e-12 fast circulating ellipses drifted by up to 5e-7).
* :func:`verify_growth` — from an ellipse classified hyperbolic, a perturbation of size ε along
  the most unstable eigenvector grows like ε·exp(γt); the measured rate (least-squares slope of
  log |x(t) − x*| while the deviation is between 30ε and 1e-3) is compared with the predicted
  γ = max Re of the eigenvalues (:mod:`analysis.stability`).
* :func:`verify_bounded` — from an ellipse classified elliptic, a random perturbation of size ε
  stays bounded: max |x(t) − x*| over the run ≤ ``factor``·ε and no growth between the first
  and last thirds of the run.

Deviations are measured in the reduced coordinates (θ excluded, it is cyclic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.invariants import laboratory_spin
from flatbody_env.physics.hamiltonian import velocities_from_momenta
from flatbody_env.scene import Scene
from flatbody_env.simulation import Trajectory, simulate
from flatbody_env.physics.state import STATE_NAMES

from analysis.stability import StabilityResult
from analysis.stationary import StationaryEllipse, check_isotropic

STATIONARY_DRIFT_TOL = 1e-8
GROWTH_REL_TOL = 0.10


@dataclass(frozen=True, kw_only=True)
class StationarityCheck:
    """Result of :func:`verify_stationary`."""

    t_end: float
    drift: dict[str, float]
    """max |q(t) − q(0)| for each state entry (θ excluded), ω3, θ̇ (as measured θ(t) − θ̇ t), H, |s|², p_θ, R s."""
    max_drift: float
    passed: bool
    """max_drift ≤ tolerance."""
    tolerance: float
    nfev: int


@dataclass(frozen=True, kw_only=True)
class GrowthCheck:
    """Result of :func:`verify_growth`."""

    predicted_rate: float
    measured_rate: float
    relative_error: float
    passed: bool
    """relative_error ≤ tolerance."""
    tolerance: float
    eps: float
    t_end: float
    fit_window: tuple[float, float]
    t: np.ndarray
    deviation: np.ndarray


@dataclass(frozen=True, kw_only=True)
class BoundednessCheck:
    """Result of :func:`verify_bounded`."""

    eps: float
    t_end: float
    max_ratio: float
    """max |x(t) − x*| / |x(0) − x*|."""
    growth_ratio: float
    """max deviation in the last third / max deviation in the first third."""
    passed: bool
    factor: float


def _scene(body: Body, y: np.ndarray, name: str) -> Scene:
    return Scene(name=name, body=body, state={n: float(v) for n, v in zip(STATE_NAMES, y)})


def _run(
    body: Body, y0: np.ndarray, t_end: float, samples: int, rtol: float, atol: float, with_rotation: bool
) -> Trajectory:
    return simulate(
        _scene(body, y0, "analysis-verification"),
        t_end=t_end,
        times=np.linspace(0.0, t_end, samples),
        method="DOP853",
        rtol=rtol,
        atol=atol,
        with_rotation=with_rotation,
        model="two-polar",
        energy_tol=math.inf,
    )


def verify_stationary(
    body: Body,
    ellipse: StationaryEllipse,
    *,
    t_end: float = 100.0,
    samples: int = 201,
    rtol: float = 1e-13,
    atol: float = 1e-15,
    tolerance: float = STATIONARY_DRIFT_TOL,
) -> StationarityCheck:
    """Simulate from the ellipse and measure how far everything that should be constant drifts."""
    check_isotropic(body)
    y0 = ellipse.y
    traj = _run(body, y0, t_end, samples, rtol, atol, True)
    Y = traj.y
    drift = {name: float(np.max(np.abs(Y[i] - y0[i]))) for i, name in enumerate(STATE_NAMES[:10])}
    w3 = np.array([velocities_from_momenta(Y[:, k], body)["omega3"] for k in range(Y.shape[1])])
    drift["omega3"] = float(np.max(np.abs(w3 - ellipse.omega3)))
    drift["theta - theta_dot t"] = float(np.max(np.abs(Y[10] - y0[10] - ellipse.theta_dot * traj.t)))
    drift["energy"] = float(np.max(np.abs(traj.energy - ellipse.energy)))
    drift["casimir"] = float(np.max(np.abs(traj.casimir - traj.casimir[0])))
    ls = laboratory_spin(traj.rotation, Y[:3].T)
    drift["lab_spin"] = float(np.max(np.linalg.norm(ls - ls[0], axis=-1)))
    # θ accumulates θ̇ t: its error grows with t like any phase; judge it relative to t_end
    phase = drift.pop("theta - theta_dot t")
    drift["theta_rate"] = phase / t_end
    worst = max(drift.values())
    return StationarityCheck(
        t_end=t_end, drift=drift, max_drift=worst, passed=bool(worst <= tolerance), tolerance=tolerance, nfev=traj.nfev
    )


def _deviation(Y: np.ndarray, y_star: np.ndarray) -> np.ndarray:
    return np.linalg.norm(Y[:10] - y_star[:10, None], axis=0)


def verify_growth(
    body: Body,
    result: StabilityResult,
    *,
    eps: float = 1e-9,
    final: float = 1e-3,
    samples: int = 400,
    rtol: float = 1e-13,
    atol: float = 1e-15,
    tolerance: float = GROWTH_REL_TOL,
) -> GrowthCheck:
    """Perturb along the most unstable eigenvector and compare the measured growth rate with max Re."""
    if result.classification != "hyperbolic":
        raise ValueError(
            f"result.classification: verify_growth needs a hyperbolic ellipse, got {result.classification!r}"
        )
    gamma = result.max_real_part
    mode = result.unstable_mode()
    y_star = result.ellipse.y
    y0 = y_star.copy()
    y0[:10] += eps * mode
    t_end = math.log(final / eps) / gamma * 1.05
    traj = _run(body, y0, t_end, samples, rtol, atol, False)
    d = _deviation(traj.y, y_star)
    lo, hi = 30.0 * eps, 0.1 * final
    mask = (d > lo) & (d < hi)
    t = traj.t
    if np.count_nonzero(mask) < 10:
        raise ValueError("eps: the deviation never entered the fit window; choose a smaller eps or a larger final")
    slope, _ = np.polyfit(t[mask], np.log(d[mask]), 1)
    rel = abs(slope - gamma) / gamma
    return GrowthCheck(
        predicted_rate=gamma,
        measured_rate=float(slope),
        relative_error=float(rel),
        passed=bool(rel <= tolerance),
        tolerance=tolerance,
        eps=eps,
        t_end=t_end,
        fit_window=(float(t[mask][0]), float(t[mask][-1])),
        t=t,
        deviation=d,
    )


def verify_bounded(
    body: Body,
    result: StabilityResult,
    *,
    eps: float = 1e-6,
    t_end: float = 100.0,
    samples: int = 501,
    seed: int = 0,
    factor: float = 100.0,
    rtol: float = 1e-11,
    atol: float = 1e-13,
) -> BoundednessCheck:
    """Perturb randomly by ε (reduced coordinates) and check that the deviation stays bounded."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=10)
    direction /= np.linalg.norm(direction)
    y_star = result.ellipse.y
    y0 = y_star.copy()
    y0[:10] += eps * direction
    traj = _run(body, y0, t_end, samples, rtol, atol, False)
    d = _deviation(traj.y, y_star)
    n3 = max(1, d.size // 3)
    max_ratio = float(np.max(d) / d[0])
    growth = float(np.max(d[-n3:]) / np.max(d[:n3]))
    passed = bool(max_ratio <= factor and growth <= 3.0)
    return BoundednessCheck(
        eps=eps, t_end=t_end, max_ratio=max_ratio, growth_ratio=growth, passed=passed, factor=factor
    )


__all__ = [
    "BoundednessCheck",
    "GROWTH_REL_TOL",
    "GrowthCheck",
    "STATIONARY_DRIFT_TOL",
    "StationarityCheck",
    "verify_bounded",
    "verify_growth",
    "verify_stationary",
]
