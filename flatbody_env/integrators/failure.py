"""Failure codes of the compiled integrators and their translation to :class:`IntegrationError`.

Compiled kernels never raise: they return an integer status (0 = success) so that the
environment can turn it into ``info`` flags without exception overhead, and the analysis path
(:meth:`Method.integrate`) raises :class:`~flatbody_env.integrators.base.IntegrationError` with
``kind`` = :data:`KINDS` [status].

=====  =====================  =====================================================================
code   kind                   meaning
=====  =====================  =====================================================================
0      ``"ok"``               success
1      ``"non-finite"``       a NaN or inf appeared in the state
2      ``"step-collapse"``    the adaptive step fell below 10 ulp of t (scipy's criterion)
3      ``"chart-singularity"``  λ − μ changed sign while σ₋ = s3 − p_θ ≠ 0 (two-polar chart, docs/physics.md §7)
4      ``"domain"``           λ, μ or ϱ ≤ 0 (two-polar) or det φᵀφ ≤ 0 (regular)
5      ``"energy"``           |H − H₀| beyond the energy tolerance (only without controls)
6      ``"constraint"``       RATTLE's Newton iteration for the Kirchhoff–Love constraints failed
7      ``"under-resolved"``   a fixed step turns the chart's frame by more than 1 rad (h·max(|ω3|,|θ̇|) > 1):
                              the two-polar chart near λ = μ, where every fixed-step method blows up
8      ``"budget"``           the work budget (RHS evaluations, steps or wall-clock, :class:`Tolerances`) was used up
9      ``"unsupported"``      a control the method cannot apply (torques in the compiled regular chart)
=====  =====================  =====================================================================
"""

from __future__ import annotations

from flatbody_env.integrators.base import IntegrationError

OK = 0
NON_FINITE = 1
STEP_COLLAPSE = 2
CHART_SINGULARITY = 3
DOMAIN = 4
ENERGY = 5
CONSTRAINT = 6
UNDER_RESOLVED = 7
BUDGET = 8
MAX_STEPS = BUDGET  # the kernels' name of the same code
UNSUPPORTED = 9

KINDS = (
    "ok",
    "non-finite",
    "step-collapse",
    "chart-singularity",
    "domain",
    "energy",
    "constraint",
    "under-resolved",
    "budget",
    "unsupported",
)

_REASONS = {
    NON_FINITE: "non-finite state",
    STEP_COLLAPSE: "required step size fell below 10 ulp of t (step-size collapse)",
    CHART_SINGULARITY: "lambda - mu changed sign while s3 - p_theta != 0: the two-polar chart is singular at "
    "lambda = mu (use a regular-chart method)",
    DOMAIN: "lambda, mu or rho left the domain (> 0)",
    ENERGY: "energy error beyond the tolerance",
    CONSTRAINT: "RATTLE could not satisfy the Kirchhoff-Love constraints (Newton did not converge)",
    UNDER_RESOLVED: "a fixed step turns the chart's frame by more than 1 rad (lambda ~ mu: the two-polar chart "
    "is under-resolved; use a smaller step or a regular-chart method)",
    BUDGET: "work budget exhausted (RHS evaluations or steps)",
    UNSUPPORTED: "control not supported by this method",
}

MAX_TURN = 1.0
"""Largest chart rotation h·max(|ω3|, |θ̇|) (rad) a fixed step may take before ``"under-resolved"``."""


def failure_reason(status: int) -> str:
    """One line saying why a kernel returned ``status``."""
    return _REASONS.get(int(status), f"status {int(status)}")


def raise_for(status: int, *, t: float, method: str, detail: str = "") -> None:
    """Raise the :class:`IntegrationError` for a non-zero ``status`` (no-op for 0)."""
    status = int(status)
    if status == OK:
        return
    reason = _REASONS.get(status, f"status {status}")
    if detail:
        reason = f"{reason} ({detail})"
    raise IntegrationError(reason, t=t, method=method, kind=KINDS[status] if 0 <= status < len(KINDS) else "failure")


__all__ = [
    "KINDS",
    "MAX_TURN",
    "failure_reason",
    "raise_for",
    "OK",
    "NON_FINITE",
    "STEP_COLLAPSE",
    "CHART_SINGULARITY",
    "DOMAIN",
    "ENERGY",
    "CONSTRAINT",
    "UNDER_RESOLVED",
    "BUDGET",
    "MAX_STEPS",
    "UNSUPPORTED",
]
