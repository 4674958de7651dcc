"""The integrator seam: a method is looked up by name and integrates a body from a paper state.

Every method, whatever its chart or algorithm, takes the paper's packed state (layout in
:mod:`flatbody_env.physics.state`) and returns the paper's state at the requested times: charts other
than the two-polar one convert on the way in and out. Controls are constant over a call
(``u``, shape (4,)): an environment calls a method once per step.

A method reports failure by raising :class:`IntegrationError` with the time and the reason
(non-finite values, step-size collapse, a chart singularity, energy or constraint error beyond
tolerance); the environment turns it into ``info`` flags, the analysis layer lets it propagate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from flatbody_env.physics.body import Body

CHARTS = ("two-polar", "regular")


class IntegrationError(RuntimeError):
    """An integration failed; ``t`` is where and ``reason`` why (one line)."""

    def __init__(self, reason: str, *, t: float, method: str = "", kind: str = "failure") -> None:
        self.reason = reason
        self.t = float(t)
        self.method = method
        self.kind = kind
        where = f"{method} " if method else ""
        super().__init__(f"{where}integration failed at t = {self.t:.6g}: {reason}")


@dataclass(frozen=True, kw_only=True)
class MethodInfo:
    """What ``flatbody methods`` lists for a method."""

    name: str
    adaptive: bool
    order: int
    chart: str
    compiled: bool
    preserves: tuple[str, ...] = ()
    description: str = ""

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "adaptive": self.adaptive,
            "order": self.order,
            "chart": self.chart,
            "compiled": self.compiled,
            "preserves": list(self.preserves),
            "description": self.description,
        }


@dataclass
class Solution:
    """Raw result of a method: paper states ``Y`` (11, n) at times ``t`` (n,)."""

    t: np.ndarray
    Y: np.ndarray
    rotation: np.ndarray | None = None
    nfev: int = 0
    stats: dict = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Tolerances:
    """Accuracy settings passed to every method (adaptive ones read rtol/atol, fixed-step ones step)."""

    rtol: float = 1e-10
    atol: float = 1e-10
    step: float | None = None
    energy_tol: float = np.inf
    """Allowed |H(t) − H(0)| (absolute) before the run is declared failed."""


class Method(Protocol):
    info: MethodInfo

    def integrate(
        self,
        body: Body,
        y0: np.ndarray,
        times: np.ndarray,
        *,
        tol: Tolerances,
        u: np.ndarray | None = None,
        R0: np.ndarray | None = None,
        with_rotation: bool = False,
    ) -> Solution:
        """Integrate from ``y0`` at ``times[0]`` and return the state at every entry of ``times``."""
        ...


_REGISTRY: dict[str, Method] = {}


def register_method(method: Method) -> Method:
    _REGISTRY[method.info.name] = method
    return method


def get_method(name: str) -> Method:
    from flatbody_env.integrators import _load_all

    _load_all()
    if name not in _REGISTRY:
        raise ValueError(f"method: unknown method {name!r} (allowed: {', '.join(sorted(_REGISTRY))})")
    return _REGISTRY[name]


def available_methods() -> list[MethodInfo]:
    from flatbody_env.integrators import _load_all

    _load_all()
    return [m.info for m in _REGISTRY.values()]


@dataclass
class StepResult:
    """One environment step: the new paper state (and R), or a failure flag with the reason.

    On failure ``y`` and ``R`` are the state at the start of the step (never NaN).
    """

    y: np.ndarray
    R: np.ndarray | None
    ok: bool
    reason: str = ""
    kind: str = ""
    nfev: int = 0


class Stepper(Protocol):
    def __call__(self, y: np.ndarray, R: np.ndarray | None, u: np.ndarray, dt: float) -> StepResult: ...


def make_stepper(name: str, body: Body, tol: Tolerances, *, with_rotation: bool = False) -> Stepper:
    """A per-step integrator for environments: ``stepper(y, R, u, dt) -> StepResult``.

    Methods may offer a fast path (a ``make_stepper(body, tol, with_rotation)`` method, e.g. a
    compiled single-step kernel); otherwise each step is one :meth:`Method.integrate` call over
    [0, dt] with the action held constant (a fresh solver per step: NOTES §8 warns against
    carrying an adaptive solver across action changes). Failures come back as flags.
    """
    method = get_method(name)
    fast = getattr(method, "make_stepper", None)
    if fast is not None:
        return fast(body, tol, with_rotation=with_rotation)
    return _IntegrateStepper(name, body, tol, with_rotation)


class _IntegrateStepper:
    """The generic stepper: one :meth:`Method.integrate` call per step (picklable)."""

    def __init__(self, name: str, body: Body, tol: Tolerances, with_rotation: bool) -> None:
        self.name = name
        self.body = body
        self.tol = tol
        self.with_rotation = with_rotation

    def __call__(self, y: np.ndarray, R: np.ndarray | None, u: np.ndarray, dt: float) -> StepResult:
        method = get_method(self.name)
        try:
            sol = method.integrate(self.body, y, np.array([0.0, dt]), tol=self.tol, u=u, R0=R, with_rotation=self.with_rotation)
        except IntegrationError as exc:
            return StepResult(y=y, R=R, ok=False, reason=exc.reason, kind=exc.kind)
        Rn = sol.rotation[-1] if self.with_rotation and sol.rotation is not None else None
        return StepResult(y=sol.Y[:, -1].copy(), R=Rn, ok=True, nfev=sol.nfev)


@dataclass
class BatchStepResult:
    """One step of N bodies: new states (N, 11) (the old state where a body failed) and flags."""

    Y: np.ndarray
    ok: np.ndarray
    reasons: list[str]


def make_batch_stepper(name: str, body: Body, tol: Tolerances):
    """``batch(Y (N, 11), U (N, 4), dt) -> BatchStepResult`` for vector environments.

    Methods may offer a compiled batch (``make_batch_stepper(body, tol)``: N bodies in one
    compiled call); otherwise this loops the single-body stepper of :func:`make_stepper`.
    """
    method = get_method(name)
    fast = getattr(method, "make_batch_stepper", None)
    if fast is not None:
        return fast(body, tol)
    return _LoopBatchStepper(make_stepper(name, body, tol))


class _LoopBatchStepper:
    """The generic batch: the single-body stepper in a Python loop (picklable)."""

    def __init__(self, single: Stepper) -> None:
        self.single = single

    def __call__(self, Y: np.ndarray, U: np.ndarray, dt: float) -> BatchStepResult:
        out = Y.copy()
        ok = np.ones(Y.shape[0], dtype=bool)
        reasons = [""] * Y.shape[0]
        for i in range(Y.shape[0]):
            r = self.single(Y[i], None, U[i], dt)
            if r.ok:
                out[i] = r.y
            else:
                ok[i] = False
                reasons[i] = f"{r.kind}: {r.reason}"
        return BatchStepResult(Y=out, ok=ok, reasons=reasons)
