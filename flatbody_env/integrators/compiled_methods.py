"""The compiled methods (numba, on-disk cache) behind the integrator seam, and the environment API.

Registered methods (``flatbody methods``)

=====================  ========  =====  =========  =================================================
name                   adaptive  order  chart      algorithm
=====================  ========  =====  =========  =================================================
``DOP853-numba``       yes       8      two-polar  port of scipy's DOP853 (same steps, ~100× faster)
``RK4``                no        4      two-polar  classical Runge–Kutta
``splitting-strang``   no        2      two-polar  Poisson splitting, exact flows (docs/physics.md §10), J1 = J2
``splitting-suzuki4``  no        4      two-polar  Suzuki 5-stage composition of Strang
``splitting-yoshida4`` no        4      two-polar  Yoshida triple-jump composition of Strang
``RATTLE``             no        2      regular    RATTLE on Φ = [φ1, φ2, ψ] (docs/physics.md §7)
``RATTLE-suzuki4``     no        4      regular    Suzuki 5-stage composition of RATTLE
``RATTLE-kahanli6``    no        6      regular    Kahan–Li 9-stage composition of RATTLE
=====================  ========  =====  =========  =================================================

Fixed-step methods need ``Tolerances(step=h)`` (``simulate(..., step=h)``, ``--step H``); each
output interval is cut into ⌈Δt/h⌉ equal steps. Adaptive ``DOP853-numba`` reads rtol/atol and
steps exactly onto every output time. Compiled methods need a built-in potential (V1, V2, V3):
a :class:`~flatbody_env.physics.potentials.CustomPotential` runs Python code and is refused with a
ValueError (use the scipy methods). With ``with_rotation=True`` the two-polar methods carry R on
their own steps (:mod:`.rotation_kernels`; the paper state is bit for bit the one without R); the
regular-chart methods return R from the decomposition.

Failures raise :class:`~flatbody_env.integrators.base.IntegrationError` with ``kind`` from
:mod:`.failure` (non-finite, step-collapse, chart-singularity, domain, energy, constraint,
under-resolved, budget, unsupported).

Environment API
---------------
Through the seam: ``make_stepper(name, body, tol)`` / ``make_batch_stepper(name, body, tol)`` of
:mod:`.base` find :meth:`CompiledTwoPolar.make_stepper` / ``make_batch_stepper`` (one compiled call
per env step; failures as ``StepResult.ok = False`` with ``kind``); the regular-chart methods use
the generic per-step :meth:`integrate` path (it converts and returns R). Underneath,
:func:`env_stepper` (name) → :class:`EnvStepper` with two compiled functions and no Python work per
sub-step::

    stepper = env_stepper("RK4")
    status = stepper.step(y, u, P, dt, h, rtol, atol, energy_tol, out)         # -> int
    stepper.batch(Y, U, P, dt, h, rtol, atol, energy_tol, OUT, STATUS)         # in place

* ``y``, ``out``: float64 (n,) with n = 11 (paper state, :mod:`flatbody_env.physics.state`) for two-polar
  methods and n = 18 (regular state z, :mod:`flatbody_env.physics.regular`) for ``stepper.state ==
  "regular"``; convert once with :func:`flatbody_env.physics.regular.regular_from_paper` /
  :func:`~flatbody_env.physics.regular.paper_from_regular`.
* ``u`` (4,): controls (τ1, τ2, τ3, f_ϱ), constant over the step; ``P`` (9,): a *writable* float64
  copy of ``Body.kernel_params()`` (:func:`kernel_params`).
* ``dt``: the env step; ``h``: the largest sub-step (fixed-step methods) or the first step guess
  (DOP853, 0 = automatic); ``rtol``, ``atol``: DOP853 only; ``energy_tol``: allowed |ΔH| over the
  step without controls (``inf`` = off).
* batched: ``Y``, ``OUT`` (n, N) structure-of-arrays (row k = entry k of every body), ``U`` (4, N),
  ``STATUS`` (N,) int64; one shared ``P``.
* status 0 = success; otherwise :data:`flatbody_env.integrators.failure.KINDS` [status] names the
  failure (e.g. 3 ``"chart-singularity"``, 7 ``"under-resolved"``) — flags, never exceptions.
  ``out`` then holds the state reached when the failure was detected: do not use it as physics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flatbody_env.physics.body import Body
from flatbody_env.physics.kinematics import Decomposition
from flatbody_env.physics.potentials import V2
from flatbody_env.physics.regular import paper_from_regular, regular_from_paper
from flatbody_env.integrators import rattle_kernels as _rk
from flatbody_env.integrators import twopolar_kernels as _tk
from flatbody_env.integrators.base import IntegrationError, MethodInfo, Solution, Tolerances, budget_error, check_step, register_method
from flatbody_env.integrators.failure import KINDS, failure_reason, raise_for


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


def _check_fixed_budget(name: str, times: np.ndarray, h: float, stages: int, tol: Tolerances) -> None:
    """Fixed-step work is known before the run: ⌈Δt/h⌉ steps per output interval × ``stages`` RHS
    evaluations; beyond ``tol.max_nfev`` it is refused up front (``kind="budget"``)."""
    spans = np.diff(times)
    steps = float(np.sum(np.maximum(np.ceil(spans / h - 1e-9), 1.0))) if spans.size else 0.0
    if steps * stages > tol.max_nfev:
        raise budget_error(t=float(times[0]), method=name, tol=tol,
                           used=f"{steps:.6g} steps of h = {h:g} x {stages} RHS evaluations needed over [{times[0]:g}, {times[-1]:g}]")


def _times(times) -> np.ndarray:
    times = np.array(times, dtype=np.float64).ravel()
    if times.size < 1 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise ValueError("times: must be finite and strictly increasing")
    return times


def _detail(st: int, fail: np.ndarray, tol: Tolerances) -> str:
    if KINDS[st] == "energy":
        return f"|H - H0| = {fail[1]:.3g} > {tol.energy_tol:.3g}"
    return ""


class CompiledTwoPolar:
    """A compiled method in the two-polar chart (:mod:`.twopolar_kernels`)."""

    def __init__(self, info: MethodInfo, kind: str, coeffs: np.ndarray | None = None) -> None:
        self.info = info
        self.kind = kind  # "dop853", "rk4", "split"
        self.coeffs = coeffs if coeffs is not None else _tk.STRANG

    def integrate(self, body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        name = self.info.name
        _check_compiled_body(body, name)
        h = check_step(self.info, tol)
        if self.kind == "split" and not body.inertia.is_isotropic:
            raise ValueError(f"params: {name} (Poisson splitting, docs/physics.md §10) needs J1 = J2; use RK4 or DOP853-numba")
        y0 = np.array(y0, dtype=np.float64)
        times = _times(times)
        uu = _controls(u)
        P = kernel_params(body)
        Y = np.empty((11, times.size))
        counters = np.array([0, 0, 0, tol.max_nfev], np.int64)
        fail = np.zeros(2)
        energy_tol = float(tol.energy_tol)
        if self.kind != "dop853":
            _check_fixed_budget(name, times, h, 4 if self.kind == "rk4" else self.coeffs.size, tol)
        if with_rotation:
            # the same stepping code on z = (y, vec(R)) (rotation_kernels): y bit for bit as without R
            from flatbody_env.integrators import rotation_kernels as _rot

            R0 = np.eye(3) if R0 is None else np.asarray(R0, dtype=np.float64)
            z0 = np.concatenate([y0, R0.ravel()])
            Z = np.empty((z0.size, times.size))
            if self.kind == "dop853":
                st = _rot.dop853_solve_R(z0, times, uu, P, float(tol.rtol), float(tol.atol), energy_tol, Z, counters, fail)
            else:
                st = _rot.fixed_solve_R(0 if self.kind == "rk4" else 1, self.coeffs, z0, times, uu, P, h, energy_tol, Z, counters, fail)
            Y = Z[:11]
        elif self.kind == "dop853":
            st = _tk.dop853_solve(y0, times, uu, P, float(tol.rtol), float(tol.atol), energy_tol, Y, counters, fail)
        else:
            st = _tk.fixed_solve(0 if self.kind == "rk4" else 1, self.coeffs, y0, times, uu, P, h, energy_tol, Y, counters, fail)
        if KINDS[st] == "budget":
            raise budget_error(t=float(fail[0]), method=name, tol=tol, used=f"{int(counters[0])} RHS evaluations in {int(counters[1] + counters[2])} steps")
        raise_for(st, t=fail[0], method=name, detail=_detail(st, fail, tol))
        stats = {"steps": int(counters[1])}
        if self.kind == "dop853":
            stats["rejected"] = int(counters[2])
        rotation = np.ascontiguousarray(Z[11:].T).reshape(times.size, 3, 3) if with_rotation else None
        return Solution(t=times.copy(), Y=np.ascontiguousarray(Y), rotation=rotation, nfev=int(counters[0]), stats=stats)

    # -- the environment seam (flatbody_env.integrators.base.make_stepper / make_batch_stepper) --
    def _check_env(self, body: Body, tol: Tolerances) -> None:
        name = self.info.name
        _check_compiled_body(body, name)
        check_step(self.info, tol)
        if self.kind == "split" and not body.inertia.is_isotropic:
            raise ValueError(f"params: {name} (Poisson splitting, docs/physics.md §10) needs J1 = J2; use RK4 or DOP853-numba")

    def make_stepper(self, body: Body, tol: Tolerances, *, with_rotation: bool = False) -> "CompiledStepper":
        """Compiled single-body env stepper ``(y, R, u, dt) -> StepResult`` (one compiled call per step).
        It passes R through unchanged; the environment carries R with
        :func:`flatbody_env.integrators.steppers.make_env_step` (``with_rotation=True``) instead."""
        if with_rotation:
            raise ValueError(
                f"with_rotation: this stepper of {self.info.name} does not integrate R; use "
                "flatbody_env.integrators.steppers.make_env_step(..., with_rotation=True), which carries R compiled"
            )
        self._check_env(body, tol)
        return CompiledStepper(self.info.name, body, tol)

    def make_batch_stepper(self, body: Body, tol: Tolerances) -> "CompiledBatchStepper":
        """Compiled batch stepper ``(Y (N, 11), U (N, 4), dt) -> BatchStepResult`` (one compiled call)."""
        self._check_env(body, tol)
        return CompiledBatchStepper(self.info.name, body, tol)


class CompiledRattle:
    """Compiled RATTLE (composition ``coeffs``) in the regular chart (:mod:`.rattle_kernels`)."""

    def __init__(self, info: MethodInfo, coeffs: np.ndarray) -> None:
        self.info = info
        self.coeffs = coeffs

    def integrate(self, body, y0, times, *, tol: Tolerances, u=None, R0=None, with_rotation=False) -> Solution:
        name = self.info.name
        _check_compiled_body(body, name)
        h = check_step(self.info, tol)
        if body.spin_convention != "corrected":
            raise ValueError("spin_convention: the regular formulation is the corrected one; 'paper' needs a two-polar method")
        if isinstance(body.potential, V2) and body.potential.c != body.potential.d:
            raise ValueError(
                f"potential: V2 with c != d is no function of the invariants (erratum E9); {name} needs c = d — "
                "use DOP853-regular"
            )
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
        st = _rk.rattle_solve(self.coeffs, z0, dec0, times, uu, P, h, keep_order, float(tol.energy_tol), Z, DEC, counters, fail)
        if KINDS[st] == "chart-singularity":
            raise IntegrationError(
                "the paper chart's frame could not be followed through lambda ~ mu (the regular state itself is fine; "
                "ask for output times away from the pass or a smaller step)",
                t=fail[0], method=name, kind="chart-singularity",
            )
        raise_for(st, t=fail[0], method=name, detail=_detail(st, fail, tol))
        Y, rotation = paper_states(Z, DEC, body, times, name)
        return Solution(
            t=times.copy(), Y=Y, rotation=rotation if with_rotation else None, nfev=int(counters[0]),
            stats={"steps": int(counters[1]), "regular": Z},
        )


def paper_states(Z: np.ndarray, DEC: np.ndarray, body: Body, times: np.ndarray, name: str = "") -> tuple[np.ndarray, np.ndarray]:
    """Paper states (11, n) and R (n, 3, 3) from regular states Z (18, n) and followed decompositions DEC (13, n)."""
    n = Z.shape[1]
    Y = np.empty((11, n))
    rotation = np.empty((n, 3, 3))
    for k in range(n):
        d = DEC[:, k]
        dec = Decomposition(R=d[:9].reshape(3, 3).copy(), lam=float(d[9]), mu=float(d[10]), rho=float(d[11]), theta=float(d[12]))
        try:
            Y[:, k], _ = paper_from_regular(Z[:, k], body, decomposition=dec)
        except ValueError as exc:
            raise IntegrationError(
                f"cannot express the state in the paper's chart: {exc}", t=times[k], method=name, kind="chart-singularity"
            ) from exc
        rotation[k] = dec.R
    return Y, rotation


# --------------------------------------------------------------------------------------------- registry
_TWO_POLAR = "two-polar"

DOP853_NUMBA = register_method(
    CompiledTwoPolar(
        MethodInfo(
            name="DOP853-numba", adaptive=True, order=8, chart=_TWO_POLAR, compiled=True, preserves=(),
            description="compiled port of scipy's DOP853 (Hairer's coefficients and step control), two-polar chart",
        ),
        "dop853",
    )
)
RK4 = register_method(
    CompiledTwoPolar(
        MethodInfo(name="RK4", adaptive=False, order=4, chart=_TWO_POLAR, compiled=True, preserves=(),
                   description="classical fixed-step Runge-Kutta 4, compiled, two-polar chart"),
        "rk4",
    )
)
_SPLIT_PRESERVES = ("casimir", "p_theta", "symplectic")
SPLITTING_STRANG = register_method(
    CompiledTwoPolar(
        MethodInfo(name="splitting-strang", adaptive=False, order=2, chart=_TWO_POLAR, compiled=True, preserves=_SPLIT_PRESERVES,
                   description="Poisson splitting with exact flows (docs/physics.md 8), Strang, J1 = J2 only"),
        "split", _tk.STRANG,
    )
)
SPLITTING_SUZUKI4 = register_method(
    CompiledTwoPolar(
        MethodInfo(name="splitting-suzuki4", adaptive=False, order=4, chart=_TWO_POLAR, compiled=True, preserves=_SPLIT_PRESERVES,
                   description="Poisson splitting, Suzuki 5-stage order-4 composition, J1 = J2 only"),
        "split", _tk.SUZUKI4,
    )
)
SPLITTING_YOSHIDA4 = register_method(
    CompiledTwoPolar(
        MethodInfo(name="splitting-yoshida4", adaptive=False, order=4, chart=_TWO_POLAR, compiled=True, preserves=_SPLIT_PRESERVES,
                   description="Poisson splitting, Yoshida triple-jump order-4 composition, J1 = J2 only"),
        "split", _tk.YOSHIDA4,
    )
)
_RATTLE_PRESERVES = ("constraints", "casimir", "lab_spin", "p_theta", "symplectic")
RATTLE = register_method(
    CompiledRattle(
        MethodInfo(name="RATTLE", adaptive=False, order=2, chart="regular", compiled=True, preserves=_RATTLE_PRESERVES,
                   description="RATTLE on the regular phi-psi formulation (docs/physics.md 5), passes through lambda = mu; "
                   "p_theta only for J1 = J2"),
        _tk.STRANG,
    )
)
RATTLE_SUZUKI4 = register_method(
    CompiledRattle(
        MethodInfo(name="RATTLE-suzuki4", adaptive=False, order=4, chart="regular", compiled=True, preserves=_RATTLE_PRESERVES,
                   description="Suzuki 5-stage composition of RATTLE, regular chart, passes through lambda = mu; "
                   "p_theta only for J1 = J2"),
        _tk.SUZUKI4,
    )
)

RATTLE_KAHANLI6 = register_method(
    CompiledRattle(
        MethodInfo(name="RATTLE-kahanli6", adaptive=False, order=6, chart="regular", compiled=True, preserves=_RATTLE_PRESERVES,
                   description="Kahan-Li 9-stage order-6 composition of RATTLE, regular chart, passes through lambda = mu; "
                   "p_theta only for J1 = J2"),
        _tk.KAHAN_LI6,
    )
)

# --------------------------------------------------------------------------------------------- env API
class _EnvBase:
    """Picklable holder of a method name and its settings; the compiled kernel is looked up lazily."""

    def __init__(self, name: str, body: Body, tol: Tolerances) -> None:
        self.name = name
        self.P = kernel_params(body)
        self.h = float(tol.step) if tol.step is not None else 0.0
        self.rtol = float(tol.rtol)
        self.atol = float(tol.atol)
        self.energy_tol = float(tol.energy_tol)
        self._stepper = None

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_stepper"] = None
        return state

    @property
    def stepper(self) -> "EnvStepper":
        if self._stepper is None:
            self._stepper = env_stepper(self.name)
        return self._stepper


class CompiledStepper(_EnvBase):
    """``stepper(y, R, u, dt) -> StepResult``; R is passed through unchanged (two-polar state only).
    ``nfev`` is not counted on this path (reported as 0)."""

    def __call__(self, y, R, u, dt):
        from flatbody_env.integrators.base import StepResult

        y = np.ascontiguousarray(y, dtype=np.float64)
        out = np.empty(11)
        st = self.stepper.step(y, _controls(u), self.P, float(dt), self.h, self.rtol, self.atol, self.energy_tol, out)
        if st != 0:
            return StepResult(y=y.copy(), R=R, ok=False, reason=failure_reason(st), kind=KINDS[st])
        return StepResult(y=out, R=R, ok=True)


class CompiledBatchStepper(_EnvBase):
    """``batch(Y (N, 11), U (N, 4), dt) -> BatchStepResult``: transposes to the kernels'
    structure-of-arrays layout and runs all bodies in one compiled call."""

    def __call__(self, Y, U, dt):
        from flatbody_env.integrators.base import BatchStepResult

        Y = np.asarray(Y, dtype=np.float64)
        Ys = np.ascontiguousarray(Y.T)
        Us = np.ascontiguousarray(np.asarray(U, dtype=np.float64).T)
        OUT = np.empty_like(Ys)
        STATUS = np.zeros(Ys.shape[1], np.int64)
        self.stepper.batch(Ys, Us, self.P, float(dt), self.h, self.rtol, self.atol, self.energy_tol, OUT, STATUS)
        ok = STATUS == 0
        out = OUT.T.copy()
        out[~ok] = Y[~ok]
        reasons = ["" if s == 0 else f"{KINDS[s]}: {failure_reason(s)}" for s in STATUS]
        return BatchStepResult(Y=out, ok=ok, reasons=reasons)


@dataclass(frozen=True)
class EnvStepper:
    """Compiled one-step functions of a method for the environment (module docstring)."""

    name: str
    step: object
    batch: object
    state: str
    """``"paper"`` (11 entries) or ``"regular"`` (18 entries)."""
    fixed_step: bool
    step_counted: object = None
    """``step`` with a trailing ``counters`` (3,) int64 argument (accumulates [nfev, steps, rejected])."""
    batch_counted: object = None
    """``batch`` with a trailing ``NFEV`` (N,) int64 output (each body's function evaluations)."""

    @property
    def size(self) -> int:
        return 11 if self.state == "paper" else 18


_ENV = {
    "DOP853-numba": (_tk.dop853_env_step, _tk.batch_dop853_env_step, "paper", False,
                     _tk.dop853_env_step_counted, _tk.batch_dop853_env_step_counted),
    "RK4": (_tk.rk4_env_step, _tk.batch_rk4_env_step, "paper", True, _tk.rk4_env_step_counted, _tk.batch_rk4_env_step_counted),
    "splitting-strang": (_tk.strang_env_step, _tk.batch_strang_env_step, "paper", True,
                         _tk.strang_env_step_counted, _tk.batch_strang_env_step_counted),
    "splitting-suzuki4": (_tk.suzuki4_env_step, _tk.batch_suzuki4_env_step, "paper", True,
                          _tk.suzuki4_env_step_counted, _tk.batch_suzuki4_env_step_counted),
    "splitting-yoshida4": (_tk.yoshida4_env_step, _tk.batch_yoshida4_env_step, "paper", True,
                           _tk.yoshida4_env_step_counted, _tk.batch_yoshida4_env_step_counted),
    "RATTLE-suzuki4": (_rk.rattle_env_step, _rk.batch_rattle_env_step, "regular", True, None, None),
}
ENV_METHODS = tuple(_ENV)
"""Methods with an environment stepper."""


def env_stepper(name: str) -> EnvStepper:
    """The compiled per-step functions of method ``name`` (one of :data:`ENV_METHODS`)."""
    if name not in _ENV:
        raise ValueError(f"method: no environment stepper for {name!r} (allowed: {', '.join(ENV_METHODS)})")
    step, batch, state, fixed, step_counted, batch_counted = _ENV[name]
    return EnvStepper(name=name, step=step, batch=batch, state=state, fixed_step=fixed, step_counted=step_counted,
                      batch_counted=batch_counted)


def warm_up(names=None) -> None:
    """Compile (or load from the on-disk cache) the kernels of the given methods (default: all)."""
    from flatbody_env.physics.body import default_body

    body = default_body()
    P = kernel_params(body)
    y = np.array([0.05, 0.0, 1.45, 1.77, 0.02, 0.0, 0.05, 1.4, 0.9, 1.0, 0.0])
    u = np.zeros(4)
    z = regular_from_paper(y, body)
    for name in names or ENV_METHODS:
        st = env_stepper(name)
        x = y if st.state == "paper" else z
        out = np.empty_like(x)
        st.step(x, u, P, 0.05, 0.05, 1e-8, 1e-8, np.inf, out)
        X = np.repeat(x[:, None], 2, axis=1)
        st.batch(X, np.zeros((4, 2)), P, 0.05, 0.05, 1e-8, 1e-8, np.inf, np.empty_like(X), np.zeros(2, np.int64))
    from flatbody_env.integrators.base import get_method

    times = np.array([0.0, 0.1])
    for name in names or [m for m in ENV_METHODS] + ["RATTLE", "RATTLE-kahanli6"]:
        meth = get_method(name)
        tol = Tolerances(rtol=1e-8, atol=1e-8, step=None if meth.info.adaptive else 0.05)
        meth.integrate(body, y, times, tol=tol)


__all__ = ["CompiledBatchStepper", "CompiledRattle", "CompiledStepper", "CompiledTwoPolar", "ENV_METHODS", "EnvStepper", "env_stepper", "kernel_params", "paper_states", "warm_up"]
