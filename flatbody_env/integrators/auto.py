"""``method="auto"``: the fastest registered method that meets the requested tolerance in a chart.

The rule follows the work-precision chart (``flatbody chart``, docs/integrators.md), measured on
the built-in scenes at final-state errors of 1e-6 and 1e-9:

* **two-polar chart** (the scene provably keeps clear of λ = μ): ``DOP853-numba``, the compiled
  port of scipy's DOP853 — the same steps and errors as scipy's DOP853 in far less time (the
  speed-ups: ``flatbody bench integrators``, docs/integrators.md, the ``method="auto"`` table), and
  the fastest method at both targets on ``regular``, ``small-rho-bounce`` and ``long-horizon``.
  It reads rtol/atol exactly as scipy does. With a ``CustomPotential`` (Python code, which the
  compiled methods refuse) scipy's ``DOP853``.
* **regular chart** (the scene may pass close to λ = μ, or J1 ≠ J2 where no bound is known):
  ``RATTLE-kahanli6`` (compiled, sixth order, regular at λ = μ), the fastest at both targets on
  ``close-approach`` and the only method whose error does not grow as the gap closes. It is a
  fixed-step method, so the step is chosen to meet the tolerance (:func:`rattle_to_tolerance`):
  h = :data:`FIRST_STEP`, h/2, h/4, … until the Richardson estimate of the error of the finer run,
  |Y_{h/2} − Y_h| / (2⁶ − 1), is within atol + rtol·|Y| in every entry at every output time. Where
  RATTLE does not apply (a custom potential, V2 with c ≠ d, the paper's spin convention, torques)
  or no step down to :data:`MIN_STEP` meets the tolerance: scipy's ``DOP853-regular``, whose own
  error control meets it.

:func:`auto_method` names the choice and why; :func:`integrate_auto` runs it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from flatbody_env.integrators.base import IntegrationError, Solution, Tolerances, get_method
from flatbody_env.physics.body import Body

AUTO = "auto"
FIRST_STEP = 0.1
"""RATTLE-kahanli6's first step (the chart: an error of ≈1e-6 on ``close-approach`` at h = 0.1)."""
MIN_STEP = 0.1 / 2**9
"""The smallest step tried before falling back to DOP853-regular."""
RATTLE_AUTO = "RATTLE-kahanli6"
RATTLE_ORDER = 6


@dataclass(frozen=True)
class MethodChoice:
    """What ``method="auto"`` runs in a chart and why (the trajectory's ``meta`` carries both)."""

    method: str
    reason: str

    def as_meta(self) -> dict:
        return {"method_requested": AUTO, "method_reason": self.reason}


def auto_method(chart: str, body: Body) -> MethodChoice:
    """The method ``auto`` tries first in ``chart`` (``"two-polar"`` or ``"regular"``) for ``body``."""
    if chart == "two-polar":
        if body.compiled:
            return MethodChoice(
                "DOP853-numba",
                "auto: the compiled DOP853, fastest in the two-polar chart at every error (work-precision chart)",
            )
        return MethodChoice(
            "DOP853", "auto: scipy DOP853 (a custom potential runs Python code, which the compiled methods refuse)"
        )
    if chart == "regular":
        return MethodChoice(
            RATTLE_AUTO,
            "auto: compiled RATTLE-kahanli6 in the regular chart (fastest near lambda = mu, work-precision chart), "
            "step halved until the Richardson error estimate meets rtol/atol",
        )
    raise ValueError(f"model: method='auto' chooses within the full models two-polar and regular, got {chart!r}")


def _error_ratio(fine: np.ndarray, coarse: np.ndarray, tol: Tolerances) -> float:
    """max over entries and times of |fine − coarse| / (2^p − 1) / (atol + rtol |fine|)."""
    est = np.abs(fine - coarse) / (2.0**RATTLE_ORDER - 1.0)
    return float(np.max(est / (tol.atol + tol.rtol * np.abs(fine))))


def rattle_to_tolerance(
    body: Body, y0: np.ndarray, times: np.ndarray, tol: Tolerances, *, with_rotation: bool = False
) -> tuple[Solution, float, float]:
    """RATTLE-kahanli6 at the largest step h = FIRST_STEP / 2^k whose error estimate meets ``tol``.

    Returns (solution at h, h, the estimated error ratio ≤ 1). Raises ValueError where RATTLE does
    not apply and :class:`IntegrationError` (kind ``"budget"`` or the last failure) when no step
    down to :data:`MIN_STEP` meets the tolerance.
    """
    meth = get_method(RATTLE_AUTO)
    h = FIRST_STEP
    span = float(times[-1] - times[0])
    while h > span and h / 2 >= MIN_STEP:  # at least one step per run
        h /= 2
    coarse = None
    last_error: IntegrationError | None = None
    while h >= MIN_STEP:
        try:
            sol = meth.integrate(body, y0, times, tol=dataclasses.replace(tol, step=h), with_rotation=with_rotation)
        except IntegrationError as exc:
            if exc.kind == "budget":
                raise
            last_error, coarse = exc, None
            h /= 2
            continue
        if coarse is not None:
            ratio = _error_ratio(sol.Y, coarse.Y, tol)
            if ratio <= 1.0:
                return sol, h, ratio
        coarse = sol
        h /= 2
    raise last_error or IntegrationError(
        f"no step down to {MIN_STEP:g} met rtol = {tol.rtol:g}, atol = {tol.atol:g}",
        t=float(times[0]),
        method=RATTLE_AUTO,
        kind="budget",
    )


def integrate_auto(
    chart: str, body: Body, y0: np.ndarray, times: np.ndarray, tol: Tolerances, *, with_rotation: bool = False
) -> tuple[Solution, str, dict]:
    """Integrate with the method ``auto`` picks in ``chart``; returns (solution, method name, meta entries).

    ``meta``: ``method_requested`` ("auto"), ``method_reason`` and, for RATTLE, ``auto_step`` and
    ``auto_error_estimate`` (the Richardson ratio, ≤ 1 when the tolerance is met).
    """
    choice = auto_method(chart, body)
    if choice.method != RATTLE_AUTO:
        return (
            get_method(choice.method).integrate(body, y0, times, tol=tol, with_rotation=with_rotation),
            choice.method,
            choice.as_meta(),
        )
    try:
        sol, h, ratio = rattle_to_tolerance(body, y0, times, tol, with_rotation=with_rotation)
        return sol, RATTLE_AUTO, {**choice.as_meta(), "auto_step": h, "auto_error_estimate": ratio}
    except ValueError as exc:  # RATTLE does not apply to this body
        why = f"auto: DOP853-regular (RATTLE-kahanli6 does not apply: {str(exc).split(';')[0]})"
    except IntegrationError as exc:
        if exc.kind == "budget":
            raise
        why = f"auto: DOP853-regular (RATTLE-kahanli6 met the tolerance at no step down to {MIN_STEP:g}: {exc.kind})"
    sol = get_method("DOP853-regular").integrate(body, y0, times, tol=tol, with_rotation=with_rotation)
    return sol, "DOP853-regular", {"method_requested": AUTO, "method_reason": why}


__all__ = ["AUTO", "FIRST_STEP", "MIN_STEP", "MethodChoice", "auto_method", "integrate_auto", "rattle_to_tolerance"]
