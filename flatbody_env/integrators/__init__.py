"""Integrators behind one seam (:mod:`.base`): methods chosen by name.

``get_method(name)`` returns a method; ``available_methods()`` lists them. The scipy
``solve_ivp`` family (:mod:`.scipy_methods`) is the reference; the compiled methods are one table
(:mod:`.specs`), registered without importing numba (their kernels compile on first use). An
environment steps through :func:`flatbody_env.integrators.steppers.make_env_step`.
"""

from __future__ import annotations

from flatbody_env.integrators.base import (
    DEFAULT_MAX_NFEV,
    DEFAULT_MAX_WALL_TIME,
    CHARTS,
    IntegrationError,
    Method,
    MethodInfo,
    Solution,
    Tolerances,
    available_methods,
    get_method,
    register_method,
)

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
    "CHARTS",
    "IntegrationError",
    "Method",
    "MethodInfo",
    "Solution",
    "Tolerances",
    "available_methods",
    "get_method",
    "register_method",
]
