"""The compiled methods (numba, on-disk cache) behind the integrator seam, and the environment API.

The methods are the rows of the method table, :data:`.specs.SPECS` (``flatbody methods`` lists them with their
order, chart and what they preserve; docs/integrators.md compares them): a :class:`CompiledTwoPolar` for the two-polar
kinds (DOP853, RK4, the splittings), a :class:`CompiledRattle` for RATTLE and its compositions. Their speed against
scipy's methods is measured by ``flatbody bench integrators`` (docs/integrators.md).

Fixed-step methods need ``Tolerances(step=h)`` (``simulate(..., step=h)``, ``--step H``); each
output interval is cut into ⌈Δt/h⌉ equal steps. Adaptive ``DOP853-numba`` reads rtol/atol and
steps exactly onto every output time. Compiled methods need a built-in potential (V1, V2, V3):
a :class:`~flatbody_env.physics.potentials.CustomPotential` runs Python code and is refused with a
ValueError (use the scipy methods). Each method's refusals of a body and settings are its ``check`` (the seam's
:meth:`~.base.Method.check`). With ``with_rotation=True`` the two-polar methods carry R on
their own steps (:mod:`.rotation_kernels`; the paper state is bit for bit the one without R); the
regular-chart methods return R from the decomposition. The compiled DOP853 runs within ``max_nfev`` and
``max_wall_time`` in pieces, each continuing the last (:class:`~.budget.WallClockBudget`).

Failures raise :class:`~flatbody_env.integrators.base.IntegrationError` with ``kind`` from
:mod:`.failure` (non-finite, step-collapse, chart-singularity, domain, energy, constraint,
under-resolved, budget, unsupported).

Environment API
---------------
The environment steps through :func:`flatbody_env.integrators.steppers.make_env_step`. Underneath, for the
methods it steps compiled (``spec.env``, :data:`ENV_METHODS`), :func:`env_stepper` (the method's spec, or its
name) → :class:`EnvStepper`, the one compiled env step of :mod:`.twopolar_kernels` bound to the method's
``(kind, coefficients)`` from the method table, no Python work per sub-step::

    stepper = env_stepper("RK4")
    status = stepper.step(y, u, P, dt, h, rtol, atol, energy_tol, out)         # -> int
    stepper.batch(Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS)         # in place

* ``y``, ``out``: float64 (11,), the paper state (:mod:`flatbody_env.physics.state`).
* ``u`` (4,): controls (τ1, τ2, τ3, f_ϱ), constant over the step; ``P`` (9,): a *writable* float64
  copy of ``Body.kernel_params()`` (:func:`kernel_params`).
* ``dt``: the env step; ``h``: the largest sub-step (fixed-step methods) or the first step guess
  (DOP853, 0 = automatic); ``rtol``, ``atol``: DOP853 only; ``energy_tol``: allowed |ΔH| over the
  step without controls (``inf`` = off).
* batched: ``Y``, ``OUT`` (11, N) structure-of-arrays (row k = entry k of every body), ``U`` (4, N),
  ``STATUS`` (N,) int64; one shared ``P``.
* status 0 = success; otherwise :data:`flatbody_env.integrators.failure.KINDS` [status] names the
  failure (e.g. 3 ``"chart-singularity"``, 7 ``"under-resolved"``) — flags, never exceptions.
  ``out`` then holds the state reached when the failure was detected: do not use it as physics.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.kinematics import Decomposition
from flatbody_env.physics.potentials import V2
from flatbody_env.physics.regular import paper_from_regular, regular_from_paper
from flatbody_env.integrators.base import (
    IntegrationError,
    Solution,
    Tolerances,
    budget_error,
    check_regular_body,
    check_step,
    register_method,
)
from flatbody_env.integrators.budget import WallClockBudget
from flatbody_env.integrators.failure import BUDGET, KINDS, raise_for
from flatbody_env.integrators.specs import BY_NAME, ENV_METHODS, SPECS, MethodSpec


def kernel_params(body: Body) -> np.ndarray:
    """``body.kernel_params()`` as the writable float64 array the compiled kernels take (9,)."""
    return np.array(body.kernel_params(), dtype=np.float64)


def _controls(u) -> np.ndarray:
    if u is None:
        return np.zeros(4)
    u = np.array(u, dtype=np.float64).ravel()
    if u.shape != (4,) or not np.all(np.isfinite(u)):
        raise ValueError("u: expected 4 finite controls (tau1, tau2, tau3, f_rho)")
    return u


def _check_compiled_body(body: Body, name: str) -> None:
    if not body.compiled:
        raise ValueError(
            f"potential: {name} is compiled and needs a built-in potential (V1, V2, V3); "
            "a CustomPotential runs Python code — use a scipy method (e.g. DOP853)"
        )


def _check_fixed_budget(name: str, times: np.ndarray, h: float, stages: int, tol: Tolerances) -> float:
    """Fixed-step work is known before the run: ⌈Δt/h⌉ steps per output interval × ``stages`` RHS
    evaluations; beyond ``tol.max_nfev`` it is refused up front (``kind="budget"``). Returns that work."""
    spans = np.diff(times)
    steps = float(np.sum(np.maximum(np.ceil(spans / h - 1e-9), 1.0))) if spans.size else 0.0
    if steps * stages > tol.max_nfev:
        raise budget_error(
            t=float(times[0]),
            method=name,
            tol=tol,
            used=f"{steps:.6g} steps of h = {h:g} x {stages} RHS evaluations needed over [{times[0]:g}, {times[-1]:g}]",
        )
    return steps * stages


_WATCHERS: list[tuple[Callable[[float, float, float], None], float]] = []
"""The watchers of this process's compiled integrations (:func:`watching_kernels`), innermost last."""


@contextmanager
def watching_kernels(watch: Callable[[float, float, float], None], *, every: float = 0.05) -> Iterator[None]:
    """While inside, ``watch(t, t_first, t_last)`` is called every ``every`` seconds from a thread while a compiled
    integration of this process runs: ``t`` is the time its kernel has reached (written by the kernel as it goes;
    the kernels release the GIL), ``t_first, t_last`` its first and last output times. A long integration is one
    call into compiled code; this is how a caller (a service job's progress) sees it move."""
    entry = (watch, float(every))
    _WATCHERS.append(entry)
    try:
        yield
    finally:
        _WATCHERS.remove(entry)


def _watched(run: Callable[[], Any], times: np.ndarray, fail: np.ndarray) -> Any:
    """``run()`` (a compiled kernel writing the time it has reached to ``fail[0]``), watched by the innermost
    :func:`watching_kernels` watcher when there is one."""
    if not _WATCHERS:
        return run()
    watch, every = _WATCHERS[-1]
    t0, t1 = float(times[0]), float(times[-1])
    done = threading.Event()

    def look() -> None:
        while not done.wait(every):
            t = float(fail[0])
            if t0 <= t <= t1:
                watch(t, t0, t1)

    watcher = threading.Thread(target=look, name="flatbody-kernel-watch", daemon=True)
    watcher.start()
    try:
        return run()
    finally:
        done.set()
        watcher.join()


def _times(times) -> np.ndarray:
    times = np.array(times, dtype=np.float64).ravel()
    if times.size < 1 or not np.isfinite(times).all() or not (times[1:] > times[:-1]).all():
        raise validation.refusal("times", "be finite and strictly increasing")
    return times


def _detail(st: int, fail: np.ndarray, tol: Tolerances) -> str:
    if KINDS[st] == "energy":
        return f"|H - H0| = {fail[1]:.3g} > {tol.energy_tol:.3g}"
    return ""


class CompiledTwoPolar:
    """A compiled method in the two-polar chart (:mod:`.twopolar_kernels`), from its :class:`~.specs.MethodSpec`.
    The kernels are imported on first use: registering compiles nothing and imports no numba."""

    def __init__(self, spec: MethodSpec) -> None:
        self.spec = spec
        self.info = spec.info
        self.kind = spec.kind  # "dop853", "rk4", "split"
        self.coeffs = spec.coeffs

    def integrate(self, body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        name = self.info.name
        h = self.check(body, tol)
        y0 = np.array(y0, dtype=np.float64)
        times = _times(times)
        uu = _controls(u)
        P = kernel_params(body)
        counters = np.array([0, 0, 0, tol.max_nfev], np.int64)
        fail = np.zeros(2)
        energy_tol = float(tol.energy_tol)
        if self.kind != "dop853":
            total = _check_fixed_budget(name, times, h, self.spec.stages, tol)
        from flatbody_env.integrators import twopolar_kernels as _tk

        if with_rotation:
            # the same stepping code on z = (y, vec(R)) (rotation_kernels): y bit for bit as without R
            from flatbody_env.integrators import rotation_kernels as kernels

            R0 = np.eye(3) if R0 is None else np.asarray(R0, dtype=np.float64)
            y0 = np.concatenate([y0, R0.ravel()])
            dop853, fixed = kernels.dop853_solve_R, kernels.fixed_solve_R
        else:
            dop853, fixed = _tk.dop853_solve, _tk.fixed_solve
        Z = np.empty((y0.size, times.size))
        start = time.perf_counter()
        budget = WallClockBudget.of(tol)
        wall = False
        if self.kind == "dop853":
            carry = np.zeros(_tk.carry_size(y0.size))
            rtol, atol = float(tol.rtol), float(tol.atol)
            status = [0]

            def advance(
                limit: int,
            ) -> tuple[int, int]:  # on from where the last piece stopped, to ``limit`` evaluations
                counters[3] = limit
                status[0] = dop853(y0, times, uu, P, rtol, atol, energy_tol, Z, counters, fail, carry)
                return 1, int(status[0] == BUDGET)

            wall = _watched(lambda: budget.run(advance), times, fail)  # max_nfev and max_wall_time
            st = status[0]
        else:

            def probe() -> int:  # a few hundred steps from the first time: the cost of one RHS evaluation
                c = np.zeros(4, np.int64)
                span = min(256 * h, times[-1] - times[0])
                fixed(
                    self.spec.code,
                    self.coeffs,
                    y0,
                    np.array([times[0], times[0] + span]),
                    uu,
                    P,
                    h,
                    np.inf,
                    np.empty((y0.size, 2)),
                    c,
                    np.zeros(2),
                )
                return int(c[0])

            budget.refuse_fixed(probe, total, t=float(times[0]), method=name)
            st = _watched(
                lambda: fixed(self.spec.code, self.coeffs, y0, times, uu, P, h, energy_tol, Z, counters, fail),
                times,
                fail,
            )
        if KINDS[st] == "budget":
            used = f"{int(counters[0])} RHS evaluations in {int(counters[1] + counters[2])} steps, {time.perf_counter() - start:.3g} s"
            raise budget_error(
                t=float(fail[0]), method=name, tol=tol, used=used + (" (the wall-clock budget)" if wall else "")
            )
        raise_for(st, t=fail[0], method=name, detail=_detail(st, fail, tol))
        Y = np.ascontiguousarray(Z[:11])
        energy = np.empty(times.size)
        _tk.energy_series(Y, P, energy)  # H of every row, compiled (the values of physics.hamiltonian)
        stats = {"steps": int(counters[1]), "energy": energy}
        if self.kind == "dop853":
            stats["rejected"] = int(counters[2])
        rotation = np.ascontiguousarray(Z[11:].T).reshape(times.size, 3, 3) if with_rotation else None
        return Solution(t=times.copy(), Y=Y, rotation=rotation, nfev=int(counters[0]), stats=stats)

    def check(self, body: Body, tol: Tolerances) -> float:
        """The method's refusals (custom potential, step setting, J1 ≠ J2 for a splitting); returns the fixed step
        (0 if adaptive)."""
        name = self.info.name
        _check_compiled_body(body, name)
        h = check_step(self.info, tol)
        if self.kind == "split" and not body.inertia.is_isotropic:
            raise ValueError(
                f"params: {name} (Poisson splitting, docs/physics.md §10) needs J1 = J2; use RK4 or DOP853-numba"
            )
        return h


class CompiledRattle:
    """Compiled RATTLE (composition ``spec.coeffs``) in the regular chart (:mod:`.rattle_kernels`)."""

    def __init__(self, spec: MethodSpec) -> None:
        self.spec = spec
        self.info = spec.info
        self.coeffs = spec.coeffs

    def check(self, body: Body, tol: Tolerances) -> float:
        """The method's refusals (custom potential, step setting, the paper spin convention, V2 with c ≠ d); returns
        the fixed step. (Torques, which it cannot apply, are refused by :meth:`integrate`, with the controls.)"""
        name = self.info.name
        _check_compiled_body(body, name)
        h = check_step(self.info, tol)
        check_regular_body(body)
        if isinstance(body.potential, V2) and body.potential.c != body.potential.d:
            raise ValueError(
                f"potential: V2 with c != d is no function of the invariants (erratum E9); {name} needs c = d — "
                "use DOP853-regular"
            )
        return h

    def integrate(self, body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        name = self.info.name
        h = self.check(body, tol)
        uu = _controls(u)
        if np.any(uu[:3] != 0.0):
            raise ValueError(
                f"u: {name} applies the dilatation force f_rho only; torques depend on the chart's frame "
                "(singular at lambda = mu) — use DOP853-regular or a two-polar method"
            )
        y0 = np.array(y0, dtype=np.float64)
        times = _times(times)
        _check_fixed_budget(name, times, h, self.coeffs.size, tol)
        R0 = np.eye(3) if R0 is None else np.asarray(R0, dtype=np.float64)
        z0 = regular_from_paper(y0, body, R0)
        dec0 = np.concatenate([R0.ravel(), [y0[7], y0[8], y0[9], y0[10]]])
        keep_order = not (body.inertia.is_isotropic and y0[2] == y0[3] and uu[2] == 0.0)
        P = kernel_params(body)
        n = times.size
        Z = np.empty((18, n))
        DEC = np.empty((13, n))
        counters = np.zeros(3, np.int64)
        fail = np.zeros(2)
        from flatbody_env.integrators.rattle_kernels import rattle_solve

        st = _watched(
            lambda: rattle_solve(
                self.coeffs, z0, dec0, times, uu, P, h, keep_order, float(tol.energy_tol), Z, DEC, counters, fail
            ),
            times,
            fail,
        )
        if KINDS[st] == "chart-singularity":
            raise IntegrationError(
                "the paper chart's frame could not be followed through lambda ~ mu (the regular state itself is fine; "
                "ask for output times away from the pass or a smaller step)",
                t=fail[0],
                method=name,
                kind="chart-singularity",
            )
        raise_for(st, t=fail[0], method=name, detail=_detail(st, fail, tol))
        Y, rotation = paper_states(Z, DEC, body, times, name)
        return Solution(
            t=times.copy(),
            Y=Y,
            rotation=rotation if with_rotation else None,
            nfev=int(counters[0]),
            stats={"steps": int(counters[1]), "regular": Z},
        )


def paper_states(
    Z: np.ndarray, DEC: np.ndarray, body: Body, times: np.ndarray, name: str = ""
) -> tuple[np.ndarray, np.ndarray]:
    """Paper states (11, n) and R (n, 3, 3) from regular states Z (18, n) and followed decompositions DEC (13, n)."""
    n = Z.shape[1]
    Y = np.empty((11, n))
    rotation = np.empty((n, 3, 3))
    for k in range(n):
        d = DEC[:, k]
        dec = Decomposition(
            R=d[:9].reshape(3, 3).copy(), lam=float(d[9]), mu=float(d[10]), rho=float(d[11]), theta=float(d[12])
        )
        try:
            Y[:, k], _ = paper_from_regular(Z[:, k], body, decomposition=dec)
        except ValueError as exc:
            raise IntegrationError(
                f"cannot express the state in the paper's chart: {exc}",
                t=times[k],
                method=name,
                kind="chart-singularity",
            ) from exc
        rotation[k] = dec.R
    return Y, rotation


# --------------------------------------------------------------------------------------------- registry
for _spec in SPECS:
    register_method(CompiledRattle(_spec) if _spec.kind == "rattle" else CompiledTwoPolar(_spec))


# --------------------------------------------------------------------------------------------- env API
def _uncounted(kernel, *args):
    """``kernel`` with a trailing counters (3,) (one body) or NFEV (N,) (a batch, ``args[0]`` (n, N)) it discards."""
    work = np.zeros(args[0].shape[1] if args[0].ndim == 2 else 3, np.int64)
    return kernel(*args, work)


@dataclass(frozen=True)
class EnvStepper:
    """Compiled one-step functions of a method for the environment (module docstring)."""

    name: str
    step: object
    batch: object
    fixed_step: bool
    step_counted: object = None
    """``step`` with a trailing ``counters`` (3,) int64 argument (accumulates [nfev, steps, rejected])."""
    batch_counted: object = None
    """``batch`` with a trailing ``NFEV`` (N,) int64 output (each body's function evaluations)."""


def env_stepper(spec: MethodSpec | str) -> EnvStepper:
    """The compiled per-step functions of a method the environment steps compiled (``spec.env``,
    :data:`ENV_METHODS`): its row of the method table, or its name."""
    if isinstance(spec, str):
        spec = BY_NAME.get(spec, spec)
    if not isinstance(spec, MethodSpec) or not spec.env:
        name = spec.name if isinstance(spec, MethodSpec) else spec
        raise ValueError(f"method: no environment stepper for {name!r:.60} (allowed: {', '.join(ENV_METHODS)})")
    from flatbody_env.integrators.batch_solve import batch_env_step_serial
    from flatbody_env.integrators.twopolar_kernels import env_step

    step = functools.partial(env_step, spec.code, spec.coeffs)
    batch = functools.partial(batch_env_step_serial, spec.code, spec.coeffs)
    return EnvStepper(
        name=spec.name,
        step=functools.partial(_uncounted, step),
        batch=functools.partial(_uncounted, batch),
        fixed_step=not spec.info.adaptive,
        step_counted=step,
        batch_counted=batch,
    )


def warm_up(names=None) -> None:
    """Compile (or load from the on-disk cache) the kernels of the given compiled methods (default: all): the
    environment's steppers of those it steps compiled, and every method's ``integrate``."""
    from flatbody_env.integrators.base import get_method
    from flatbody_env.physics.body import default_body

    names = list(names or BY_NAME)
    body = default_body()
    P = kernel_params(body)
    y = np.array([0.05, 0.0, 1.45, 1.77, 0.02, 0.0, 0.05, 1.4, 0.9, 1.0, 0.0])
    u = np.zeros(4)
    for name in names:
        if name in ENV_METHODS:
            st = env_stepper(name)
            st.step(y, u, P, 0.05, 0.05, 1e-8, 1e-8, np.inf, np.empty(11))
            X = np.repeat(y[:, None], 2, axis=1)
            st.batch(X, np.zeros((4, 2)), P, 0.05, 0.05, 1e-8, 1e-8, np.inf, np.empty_like(X), np.zeros(2, np.int64))
        meth = get_method(name)
        tol = Tolerances(rtol=1e-8, atol=1e-8, step=None if meth.info.adaptive else 0.05)
        meth.integrate(body, y, np.array([0.0, 0.1]), tol=tol)


__all__ = [
    "CompiledRattle",
    "CompiledTwoPolar",
    "ENV_METHODS",
    "EnvStepper",
    "env_stepper",
    "kernel_params",
    "paper_states",
    "warm_up",
    "watching_kernels",
]
