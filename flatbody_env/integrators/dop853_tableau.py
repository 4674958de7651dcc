"""Hairer's DOP853 coefficients, read from scipy's own file without importing ``scipy.integrate``.

The compiled DOP853 kernels use scipy's coefficient module ``scipy/integrate/_ivp/dop853_coefficients.py``
(a numpy-only file). Importing it the usual way runs ``scipy.integrate``'s package ``__init__``,
which pulls in ``scipy.special`` and the quadrature modules: ≈0.5 s of every process start that
only steps the compiled methods (an env episode, ``flatbody demo``). :data:`dop` is that same
file executed on its own; when ``scipy.integrate`` is already imported (or the file cannot be
found) the ordinary import is used. Either way it is scipy's text, not a copy.
"""

from __future__ import annotations

import importlib.util
import sys
from importlib import import_module
from pathlib import Path
from types import ModuleType

_NAME = "scipy.integrate._ivp.dop853_coefficients"


def _load() -> ModuleType:
    if _NAME in sys.modules:
        return sys.modules[_NAME]
    spec = importlib.util.find_spec("scipy")
    path = Path(spec.origin).parent / "integrate" / "_ivp" / "dop853_coefficients.py" if spec and spec.origin else None
    if path is None or not path.is_file():  # pragma: no cover - an unusual scipy layout
        return import_module(_NAME)
    file_spec = importlib.util.spec_from_file_location("flatbody_env.integrators._scipy_dop853_coefficients", path)
    module = importlib.util.module_from_spec(file_spec)
    file_spec.loader.exec_module(module)
    return module


dop = _load()
"""scipy's ``dop853_coefficients`` module (``N_STAGES``, ``A``, ``B``, ``C``, ``E3``, ``E5``, …)."""

__all__ = ["dop"]
