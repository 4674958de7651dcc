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

import math
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


DEFAULT_MAX_NFEV = 20_000_000
"""Default budget of right-hand-side evaluations of one integration (compiled: a few seconds)."""
DEFAULT_MAX_WALL_TIME = 120.0
"""Default wall-clock budget (s) of one integration, checked by the Python (scipy) methods."""


@dataclass(frozen=True, kw_only=True)
class Tolerances:
    """Accuracy settings and the work budget passed to every method (adaptive ones read rtol/atol,
    fixed-step ones step). Validated on construction (``ValueError`` naming the field and range).

    Budget: an integration that would need more than ``max_nfev`` right-hand-side evaluations
    (fixed-step methods: known before the run, ⌈Δt/h⌉ steps × stages; adaptive methods: counted as
    they go) or more than ``max_wall_time`` seconds (checked by the scipy methods in the right-hand side; the
    compiled DOP853 turns it into an evaluation budget from a timed probe, compiled fixed-step methods
    refuse a run whose predicted time exceeds it) stops with :class:`IntegrationError` of ``kind="budget"``.
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    step: float | None = None
    energy_tol: float = np.inf
    """Allowed |H(t) − H(0)| (absolute) before the run is declared failed (``inf``: no check)."""
    max_nfev: int = DEFAULT_MAX_NFEV
    """Budget of right-hand-side evaluations."""
    max_wall_time: float = DEFAULT_MAX_WALL_TIME
    """Budget of wall-clock seconds (every method; see the class docstring)."""

    def __post_init__(self) -> None:
        from flatbody_env.physics import validation as v

        object.__setattr__(self, "rtol", v.number("rtol", self.rtol, low=v.TOL_RANGE[0], high=v.TOL_RANGE[1]))
        object.__setattr__(self, "atol", v.number("atol", self.atol, low=v.TOL_RANGE[0], high=v.TOL_RANGE[1]))
        if self.step is not None:
            object.__setattr__(self, "step", v.number("step", self.step, positive=True, high=v.T_END_MAX))
        v.requirement(
            "energy_tol",
            self.energy_tol,
            isinstance(self.energy_tol, (int, float, np.integer, np.floating))
            and not isinstance(self.energy_tol, bool)
            and (self.energy_tol == np.inf or (math.isfinite(float(self.energy_tol)) and self.energy_tol > 0)),
            "be a number > 0 or inf (allowed range (0, inf])",
        )
        object.__setattr__(self, "energy_tol", float(self.energy_tol))
        object.__setattr__(self, "max_nfev", v.integer("max_nfev", self.max_nfev, low=1, high=10**12))
        object.__setattr__(
            self, "max_wall_time", v.number("max_wall_time", self.max_wall_time, positive=True, high=v.MAX_SECONDS)
        )


def check_step(info: MethodInfo, tol: Tolerances) -> float:
    """The fixed step ``h`` of a fixed-step method (0.0 for adaptive ones): the one home of the rule
    "fixed-step methods need ``step=``, adaptive methods refuse it" (``ValueError`` naming ``step``)."""
    if info.adaptive:
        if tol.step is not None:
            raise ValueError(f"step: {info.name} is adaptive; step= (CLI: --step) applies to fixed-step methods only")
        return 0.0
    if tol.step is None:
        raise ValueError(f"step: {info.name} is a fixed-step method; give step= (CLI: --step H), e.g. step=0.01")
    return float(tol.step)


def check_regular_body(body: Body) -> None:
    """The regular-chart methods' refusal of a body (scipy's ``NAME-regular`` and RATTLE's): the regular formulation
    is the corrected one (``ValueError`` naming ``spin_convention``)."""
    if body.spin_convention != "corrected":
        raise ValueError(
            "spin_convention: the regular formulation is the corrected one; 'paper' needs a two-polar method"
        )


def budget_error(*, t: float, method: str, used: str, tol: Tolerances) -> IntegrationError:
    """The :class:`IntegrationError` (``kind="budget"``) for a run that ran out of its budget; ``tol``: the budget
    quoted (its ``max_nfev`` and ``max_wall_time``: a :class:`Tolerances` or a :class:`~.budget.WallClockBudget`)."""
    return IntegrationError(
        f"work budget exhausted ({used}; budget max_nfev = {tol.max_nfev}, max_wall_time = {tol.max_wall_time:g} s — "
        "raise them (max_nfev=, max_wall_time=; CLI --max-nfev, --max-seconds) or shorten t_end)",
        t=t,
        method=method,
        kind="budget",
    )


class Method(Protocol):
    """What every registered method declares: :attr:`info`, :attr:`spec`, :meth:`check` and :meth:`integrate`."""

    info: MethodInfo
    spec: object | None
    """A compiled method's row of the method table (a :class:`~.specs.MethodSpec`); None for the others."""

    def check(self, body: Body, tol: Tolerances) -> float:
        """The method's refusals of ``body`` and ``tol`` (``ValueError`` naming the field), before any run; returns
        the fixed step (0.0 for an adaptive method). :meth:`integrate` calls it first; the environment at
        construction (:func:`~.steppers.make_env_step`)."""
        ...

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


def get_method(name: str, *, where: str = "method") -> Method:
    """The registered method ``name``; a ``ValueError`` naming ``where`` (the caller's argument) and the allowed names."""
    from flatbody_env.integrators import _load_all

    _load_all()
    if not isinstance(name, str) or name not in _REGISTRY:
        raise ValueError(f"{where}: unknown method {name!r:.60} (allowed: {', '.join(sorted(_REGISTRY))})")
    return _REGISTRY[name]


def available_methods() -> list[MethodInfo]:
    """The registered methods: the scipy reference family first, then the compiled ones, each group in
    registration order — the same list whatever module a process happened to import first."""
    from flatbody_env.integrators import _load_all

    _load_all()
    infos = [m.info for m in _REGISTRY.values()]
    return sorted(infos, key=lambda info: info.compiled)  # stable: keeps the registration order within each group
