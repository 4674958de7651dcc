"""Hairer's DOP853 coefficients, read from scipy's own file without importing ``scipy.integrate``.

The compiled DOP853 kernels use scipy's coefficient module ``scipy/integrate/_ivp/dop853_coefficients.py``
(a numpy-only file). Importing it the usual way runs ``scipy.integrate``'s package ``__init__``,
which pulls in ``scipy.special`` and the quadrature modules: a sizeable share of every process start
that only steps the compiled methods (an env episode, ``flatbody demo``; the import's cost: docs/integrators.md,
measured by ``python -X importtime -c "import scipy.integrate"``). :data:`dop` is that same
file executed on its own; when ``scipy.integrate`` is already imported (or the file cannot be
found) the ordinary import is used. Either way it is scipy's text, not a copy.

:data:`STAGE_J`, :data:`STAGE_C`, :data:`STAGE_L` and :data:`ERROR_J`, :data:`ERROR_E5`,
:data:`ERROR_E3` list the nonzero coefficients only: the compiled kernels sum over those.
"""

from __future__ import annotations

import importlib.util
import sys
from importlib import import_module
from pathlib import Path
from types import ModuleType

import numpy as np

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


def nonzero_terms(rows):
    """The nonzero coefficients of each row of ``rows`` (a sequence of 1-D arrays) as three arrays:
    column indices ``J`` (R, M) int64, coefficients ``C`` (R, M) and counts ``L`` (R,), M the largest
    count (unused slots 0). A Runge–Kutta sum Σ_j c_j k_j over these terms, in increasing j, is bit
    for bit the sum over all j for finite k_j (a zero term adds ±0.0, which leaves a sum that starts
    at +0.0 unchanged) and skips a quarter of DOP853's products."""
    rows = [np.asarray(r, dtype=np.float64) for r in rows]
    m = max(int(np.count_nonzero(r)) for r in rows)
    J = np.zeros((len(rows), m), dtype=np.int64)
    C = np.zeros((len(rows), m))
    L = np.zeros(len(rows), dtype=np.int64)
    for s, r in enumerate(rows):
        nz = np.flatnonzero(r)
        L[s] = nz.size
        J[s, : nz.size] = nz
        C[s, : nz.size] = r[nz]
    return J, C, L


STAGE_J, STAGE_C, STAGE_L = nonzero_terms([dop.A[s, : dop.N_STAGES] for s in range(dop.N_STAGES)] + [dop.B])
"""DOP853's stage sums without their zero terms: row s < 12 holds the nonzero a_sj (stage s's
argument y + h Σ_j a_sj k_j), row 12 the nonzero b_j (the 8th-order solution); see :func:`nonzero_terms`."""
ERROR_J = np.flatnonzero((dop.E5 != 0) | (dop.E3 != 0)).astype(np.int64)
"""The stages that enter the embedded error estimates (the union of the nonzero E5 and E3 entries)."""
ERROR_E5 = dop.E5[ERROR_J].copy()
ERROR_E3 = dop.E3[ERROR_J].copy()
"""E5 and E3 at :data:`ERROR_J`."""

__all__ = ["ERROR_E3", "ERROR_E5", "ERROR_J", "STAGE_C", "STAGE_J", "STAGE_L", "dop", "nonzero_terms"]
