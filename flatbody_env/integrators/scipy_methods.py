"""The reference family: scipy ``solve_ivp`` (RK23, RK45, DOP853, Radau, BDF, LSODA) in both charts.

``NAME`` integrates the two-polar equations (eqs. (44)–(49) of [1], :mod:`flatbody_env.physics.equations`);
``NAME-regular`` integrates the regular matrix formulation (docs/physics.md §7, :mod:`flatbody_env.physics.regular`)
and converts back to the paper's state at the output times, following the chart's discrete
branch by continuity.

Failure detection
-----------------
* ``solve_ivp`` failure (step-size collapse: "Required step size is less than spacing between
  numbers") → :class:`IntegrationError` of kind ``"step-collapse"``;
* non-finite values → ``"non-finite"``;
* two-polar chart: λ − μ changing sign while σ₋ = s3 − p_θ ≠ 0 (the centrifugal barrier of
  docs/physics.md §7 forbids it, so it is numerical) → ``"chart-singularity"``; λ, μ or ϱ reaching 0 →
  ``"domain"``;
* regular chart: the Kirchhoff–Love constraints violated beyond tolerance → ``"constraint"``;
* |H(t) − H(0)| beyond ``tol.energy_tol`` (no controls) → ``"energy"``;
* more than ``tol.max_nfev`` right-hand-side evaluations or ``tol.max_wall_time`` seconds →
  ``"budget"`` (checked inside the right-hand side, so no run outlives its budget).
"""

from __future__ import annotations

import time

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.equations import rhs, rhs_with_rotation
from flatbody_env.physics.hamiltonian import hamiltonian
from flatbody_env.physics.kinematics import Decomposition
from flatbody_env.physics.regular import (
    FrameTracker,
    constraint_residual,
    follow_chart,
    paper_from_regular,
    regular_energy,
    regular_from_paper,
    regular_rhs,
)
from flatbody_env.integrators.base import (
    IntegrationError,
    MethodInfo,
    Solution,
    Tolerances,
    budget_error,
    check_regular_body,
    check_step,
    register_method,
)

_ORDERS = {"RK23": 3, "RK45": 5, "DOP853": 8, "Radau": 5, "BDF": 5, "LSODA": 12}
_DESCRIPTIONS = {
    "RK23": "Bogacki–Shampine 3(2), scipy solve_ivp",
    "RK45": "Dormand–Prince 5(4), scipy solve_ivp",
    "DOP853": "Dormand–Prince 8(5,3), scipy solve_ivp",
    "Radau": "implicit Radau IIA order 5, scipy solve_ivp",
    "BDF": "implicit BDF orders 1–5, scipy solve_ivp",
    "LSODA": "Adams/BDF switching (ODEPACK), scipy solve_ivp",
}


def _check_finite(Y: np.ndarray, t: np.ndarray, name: str) -> None:
    bad = ~np.all(np.isfinite(Y), axis=0)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise IntegrationError("non-finite state", t=t[k], method=name, kind="non-finite")


def _check_energy(body: Body, Y: np.ndarray, t: np.ndarray, H0: float, tol: Tolerances, name: str, u) -> np.ndarray:
    H = np.array([hamiltonian(Y[:, k], body) for k in range(Y.shape[1])])
    if u is None or not np.any(u):
        err = np.abs(H - H0)
        if np.any(err > tol.energy_tol):
            k = int(np.argmax(err > tol.energy_tol))
            raise IntegrationError(
                f"energy error {err[k]:.3g} exceeds the tolerance {tol.energy_tol:.3g}",
                t=t[k],
                method=name,
                kind="energy",
            )
    return H


class _OutOfBudget(Exception):
    """Raised inside the right-hand side when the work budget is used up (caught around solve_ivp)."""

    def __init__(self, t: float, used: str) -> None:
        super().__init__(used)
        self.t = t
        self.used = used


class _Budget:
    """Wraps a right-hand side ``fun(t, z)``: counts evaluations against ``tol.max_nfev`` and checks
    the wall clock against ``tol.max_wall_time`` every 64 evaluations."""

    def __init__(self, fun, tol: Tolerances) -> None:
        self.fun = fun
        self.max_nfev = tol.max_nfev
        self.max_wall = tol.max_wall_time
        self.start = time.perf_counter()
        self.nfev = 0

    def __call__(self, t, z):
        self.nfev += 1
        if self.nfev > self.max_nfev:
            raise _OutOfBudget(float(t), f"{self.nfev - 1} RHS evaluations")
        if self.nfev % 64 == 0:
            elapsed = time.perf_counter() - self.start
            if elapsed > self.max_wall:
                raise _OutOfBudget(float(t), f"{elapsed:.1f} s wall-clock after {self.nfev} RHS evaluations")
        return self.fun(t, z)


def _solve(fun, span, z0, *, tol: Tolerances, name: str, **kwargs):
    """``solve_ivp`` under the work budget of ``tol`` (``IntegrationError(kind="budget")`` past it)."""
    from scipy.integrate import (
        solve_ivp,
    )  # here, not at import: scipy.integrate is slow to import (docs/integrators.md)

    wrapped = _Budget(fun, tol)
    try:
        return solve_ivp(wrapped, span, z0, rtol=tol.rtol, atol=tol.atol, **kwargs)
    except _OutOfBudget as exc:
        raise budget_error(t=exc.t, method=name, used=exc.used, tol=tol) from None


class ScipyTwoPolar:
    """``solve_ivp`` on the two-polar equations (eqs. (44)–(49) of [1])."""

    spec = None

    def __init__(self, algorithm: str) -> None:
        self.algorithm = algorithm
        self.info = MethodInfo(
            name=algorithm,
            adaptive=True,
            order=_ORDERS[algorithm],
            chart="two-polar",
            compiled=False,
            preserves=(),
            description=_DESCRIPTIONS[algorithm] + ", two-polar chart",
        )

    def check(self, body: Body, tol: Tolerances) -> float:
        """Adaptive: refuses ``step=`` (:func:`~.base.check_step`); any body."""
        return check_step(self.info, tol)

    def integrate(self, body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        name = self.info.name
        self.check(body, tol)
        y0 = np.asarray(y0, float)
        times = np.asarray(times, float)
        if with_rotation:
            z0 = np.concatenate([y0, (np.eye(3) if R0 is None else np.asarray(R0, float)).ravel()])

            def fun(t, z):
                return rhs_with_rotation(t, z, u, body)
        else:
            z0 = y0

            def fun(t, z):
                return rhs(t, z, u, body)

        sigma_minus = y0[2] - y0[3]
        may_cross = sigma_minus == 0.0 and body.inertia.is_isotropic and (u is None or u[2] == 0.0)

        def gap(t, z):
            return z[7] - z[8]

        gap.terminal = True

        def lam_zero(t, z):
            return z[7]

        def mu_zero(t, z):
            return z[8]

        def rho_zero(t, z):
            return z[9]

        for ev in (lam_zero, mu_zero, rho_zero):
            ev.terminal = True
        events = [lam_zero, mu_zero, rho_zero] + ([] if may_cross else [gap])
        sol = _solve(
            fun, (times[0], times[-1]), z0, tol=tol, name=name, method=self.algorithm, t_eval=times, events=events
        )
        if sol.status == -1:
            raise IntegrationError(
                sol.message, t=sol.t[-1] if sol.t.size else times[0], method=name, kind="step-collapse"
            )
        if sol.status == 1:
            for k, label in enumerate(("lambda", "mu", "rho")):
                if sol.t_events[k].size:
                    raise IntegrationError(
                        f"{label} reached 0 (outside the domain {label} > 0)",
                        t=sol.t_events[k][0],
                        method=name,
                        kind="domain",
                    )
            raise IntegrationError(
                "lambda - mu changed sign while s3 - p_theta != 0: the two-polar chart is singular at lambda = mu "
                "(use a regular-chart method)",
                t=sol.t_events[3][0],
                method=name,
                kind="chart-singularity",
            )
        _check_finite(sol.y, sol.t, name)
        Y = sol.y[:11]
        H0 = hamiltonian(y0, body)
        H = _check_energy(body, Y, sol.t, H0, tol, name, u)
        rotation = None
        if with_rotation:
            rotation = np.transpose(sol.y[11:].reshape(3, 3, -1), (2, 0, 1))
        return Solution(t=sol.t, Y=Y, rotation=rotation, nfev=int(sol.nfev), stats={"energy": H, "njev": int(sol.njev)})


class ScipyRegular:
    """``solve_ivp`` on the regular matrix formulation (docs/physics.md §7), output in the paper's state."""

    spec = None

    def __init__(self, algorithm: str) -> None:
        self.algorithm = algorithm
        self.info = MethodInfo(
            name=f"{algorithm}-regular",
            adaptive=True,
            order=_ORDERS[algorithm],
            chart="regular",
            compiled=False,
            preserves=(),
            description=_DESCRIPTIONS[algorithm] + ", regular matrix formulation (passes through lambda = mu)",
        )

    def check(self, body: Body, tol: Tolerances) -> float:
        """Adaptive: refuses ``step=``; and the ``'paper'`` spin convention (the regular formulation is the corrected one)."""
        h = check_step(self.info, tol)
        check_regular_body(body)
        return h

    def integrate(self, body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        name = self.info.name
        self.check(body, tol)
        y0 = np.asarray(y0, float)
        times = np.asarray(times, float)
        R0 = np.eye(3) if R0 is None else np.asarray(R0, float)
        z0 = regular_from_paper(y0, body, R0)
        ref = Decomposition(R=R0, lam=y0[7], mu=y0[8], rho=y0[9], theta=y0[10])
        lambda_is_larger = bool(y0[7] > y0[8])
        frame = FrameTracker(ref) if u is not None and np.any(u) else None

        def fun(t, z):
            return regular_rhs(t, z, u, body, lambda_is_larger, frame)

        sol = _solve(fun, (times[0], times[-1]), z0, tol=tol, name=name, method=self.algorithm, dense_output=True)
        if sol.status == -1:
            raise IntegrationError(
                sol.message, t=sol.t[-1] if sol.t.size else times[0], method=name, kind="step-collapse"
            )
        _check_finite(sol.y, sol.t, name)
        # Follow the chart's discrete branch through every internal step (steps shrink where the
        # frame turns fast), then read the outputs off the dense output.
        n = times.size
        Y = np.empty((11, n))
        rotation = np.empty((n, 3, 3))
        scale = max(1.0, float(np.max(np.abs(z0))))
        ctol = max(1e-6, 1e3 * max(tol.rtol, tol.atol)) * scale * scale
        grid = np.union1d(sol.t, times)
        is_output = np.isin(grid, times)
        keep_order = not (body.inertia.is_isotropic and y0[2] == y0[3] and (u is None or u[2] == 0.0))
        k = 0
        t_prev = grid[0]
        for j in range(grid.size):
            z = sol.sol(grid[j])
            if not np.all(np.isfinite(z)):
                raise IntegrationError("non-finite state", t=grid[j], method=name, kind="non-finite")
            res = np.max(np.abs(constraint_residual(z)))
            if res > ctol:
                raise IntegrationError(
                    f"Kirchhoff-Love constraint violated by {res:.3g} (> {ctol:.3g})",
                    t=grid[j],
                    method=name,
                    kind="constraint",
                )
            try:
                ref = follow_chart(sol.sol, t_prev, grid[j], ref, keep_order=keep_order)
                t_prev = grid[j]
                if is_output[j]:
                    Y[:, k], _ = paper_from_regular(z, body, decomposition=ref)
            except ValueError as exc:
                raise IntegrationError(
                    f"cannot express the state in the paper's chart: {exc}",
                    t=grid[j],
                    method=name,
                    kind="chart-singularity",
                ) from exc
            if is_output[j]:
                rotation[k] = ref.R
                k += 1
        H0 = regular_energy(z0, body, lambda_is_larger)
        H = _check_energy(body, Y, times, H0, tol, name, u)
        return Solution(
            t=times.copy(),
            Y=Y,
            rotation=rotation if with_rotation else None,
            nfev=int(sol.nfev),
            stats={"energy": H, "njev": int(sol.njev)},
        )


for _alg in _ORDERS:
    register_method(ScipyTwoPolar(_alg))
    register_method(ScipyRegular(_alg))
