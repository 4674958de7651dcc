"""Integrators behind one seam (:mod:`.base`): methods chosen by name.

``get_method(name)`` returns a method; ``available_methods()`` lists them. The scipy
``solve_ivp`` family (:mod:`.scipy_methods`) is the reference.
"""

from __future__ import annotations

from flatbody_env.integrators.base import DEFAULT_MAX_NFEV, DEFAULT_MAX_WALL_TIME, BatchStepResult, CHARTS, IntegrationError, Method, MethodInfo, Solution, Stepper, StepResult, Tolerances, available_methods, get_method, make_batch_stepper, make_stepper, register_method

_LOADED = False


def _load_all() -> None:
    """Import the modules that register methods (once)."""
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    from flatbody_env.integrators import scipy_methods  # noqa: F401
    from flatbody_env.integrators import compiled_methods  # noqa: F401


__all__ = [
    "DEFAULT_MAX_NFEV",
    "DEFAULT_MAX_WALL_TIME",
    "BatchStepResult",
    "CHARTS",
    "IntegrationError",
    "Method",
    "MethodInfo",
    "Solution",
    "StepResult",
    "Stepper",
    "Tolerances",
    "available_methods",
    "get_method",
    "make_batch_stepper",
    "make_stepper",
    "register_method",
]
