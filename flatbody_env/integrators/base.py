"""The integrator seam: a method is looked up by name and integrates a body from a paper state.

Every method, whatever its chart or algorithm, takes the paper's packed state (layout in
:mod:`flatbody_env.state`) and returns the paper's state at the requested times: charts other
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

from ..body import Body

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
    from . import _load_all

    _load_all()
    if name not in _REGISTRY:
        raise ValueError(f"method: unknown method {name!r} (allowed: {', '.join(sorted(_REGISTRY))})")
    return _REGISTRY[name]


def available_methods() -> list[MethodInfo]:
    from . import _load_all

    _load_all()
    return [m.info for m in _REGISTRY.values()]
