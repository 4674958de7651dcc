"""Compiled copies of the physics layer's scalar kernels (numba, on-disk cache where one can be written).

The physics layer stays free of numba: :func:`flatbody_env.physics.hamiltonian.kinetic_kernel`,
:func:`flatbody_env.physics.potentials.potential_kernel`, :func:`flatbody_env.physics.equations.rhs_core` and
:func:`flatbody_env.physics.equations.rhs_kernel` are plain-float Python functions. numba compiles a
function's calls to globals only when those globals are numba dispatchers themselves, so each
kernel is copied here with

.. code-block:: python

    types.FunctionType(f.__code__, {**f.__globals__, **jitted_callees}, f.__name__)

(the same code object, i.e. the physics module's source, with the called kernels re-bound to
their jitted copies) and wrapped by ``numba.njit(cache=True)``. No formula is restated here.
numba's cache keys on the code object's file and line, so the compiled machine code lands in
``flatbody_env/__pycache__`` (or ``$NUMBA_CACHE_DIR``) and is re-used by later processes;
editing a physics module invalidates it (numba compares the source file's time stamp).

Read-only installs: :data:`CACHE` (``cache=`` of every compiled function) is decided once at
import by :func:`cache_location`: ``$NUMBA_CACHE_DIR`` when set and writable, else the package's
``__pycache__`` folders when writable, else numba's user-wide cache folder (e.g.
``~/.cache/numba``) when writable; when none can be written (a read-only image without a
writable home) the kernels are compiled in memory on first use (``cache=False``) instead of
failing with numba's "no locator available".

Public names: :data:`kinetic_iso`, :data:`kinetic_kernel`, :data:`potential_kernel`, :data:`rhs_iso`, :data:`rhs_core`,
:data:`rhs_kernel`, :data:`rotation_rate_kernel`, :data:`rhs_rotation_kernel`,
:data:`turn_rotation_kernel` (jitted twins of the physics kernels, same signatures) and
:func:`energy_kernel` (H = 𝒯 + V, eq. (41) of [1]).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in
   degenerate dimension", arXiv:0902.3573 (2009).
"""

from __future__ import annotations

import os
import tempfile
import types
from pathlib import Path

import numba

from flatbody_env.physics import equations as _equations
from flatbody_env.physics import hamiltonian as _hamiltonian
from flatbody_env.physics import potentials as _potentials

_PACKAGE = Path(__file__).resolve().parents[1]
_KERNEL_SOURCE_DIRS = ("physics", "integrators", "env")
"""Folders (under the package) whose modules hold compiled functions: their ``__pycache__`` is numba's in-tree cache."""


def _writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (or, when it does not exist yet, in its nearest existing parent)."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            return False
        probe = probe.parent
    try:
        tempfile.TemporaryFile(dir=probe).close()
    except OSError:
        return False
    return True


def cache_location() -> str | None:
    """Where numba can keep compiled kernels: a folder path, or None (compile in memory).

    Probes, in numba's own order: ``$NUMBA_CACHE_DIR``; the package's ``__pycache__`` folders;
    numba's user-wide cache folder.
    """
    env_dir = os.environ.get("NUMBA_CACHE_DIR")
    if env_dir and _writable(Path(env_dir)):
        return env_dir
    in_tree = [_PACKAGE / sub / "__pycache__" for sub in _KERNEL_SOURCE_DIRS]
    if all(_writable(d) for d in in_tree):
        return str(_PACKAGE)
    try:
        from numba.misc.appdirs import AppDirs

        user_dir = Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)
    except Exception:  # pragma: no cover - numba moved its helper; treat as no user cache
        return None
    return str(user_dir) if _writable(user_dir) else None


CACHE_DIR = cache_location()
"""The folder numba caches compiled kernels under, or None when they are compiled in memory."""
CACHE = CACHE_DIR is not None
"""``cache=`` of every compiled function (False on read-only installs without a writable cache folder)."""

JIT_OPTIONS = {"cache": CACHE, "nogil": True, "error_model": "numpy"}
"""Options of every compiled function of the integrators (``error_model="numpy"``: x/0 gives
inf/nan instead of raising, so failures surface as status flags)."""


def jit_copy(func, *, variant: str = "", **callees):
    """A numba-compiled copy of the plain-Python ``func`` (or of a numba dispatcher's Python
    function) whose called globals ``callees`` are replaced by (jitted) substitutes. ``func``
    itself is left untouched.

    ``variant``: a name suffix for a second copy of the same code object with other callees (e.g.
    the stepping loops re-bound to the 20-entry state that carries R). numba's on-disk cache keys a
    function by its file, line, qualified name and argument types — not by its globals — so two
    copies of one code object under one name would load each other's machine code; the suffix
    gives each copy its own cache entry.
    """
    func = getattr(func, "py_func", func)
    glob = dict(func.__globals__)
    glob.update(callees)
    clone = types.FunctionType(func.__code__, glob, func.__name__, func.__defaults__, func.__closure__)
    clone.__module__ = func.__module__
    clone.__qualname__ = func.__qualname__ + (f"__{variant}" if variant else "")
    clone.__doc__ = func.__doc__
    return numba.njit(**JIT_OPTIONS)(clone)


kinetic_iso = jit_copy(_hamiltonian.kinetic_iso)
kinetic_kernel = jit_copy(_hamiltonian.kinetic_kernel, kinetic_iso=kinetic_iso)
potential_kernel = jit_copy(_potentials.potential_kernel)
rhs_iso = jit_copy(_equations.rhs_iso, kinetic_iso=kinetic_iso)
rhs_core = jit_copy(_equations.rhs_core, kinetic_kernel=kinetic_kernel, rhs_iso=rhs_iso)
rhs_kernel = jit_copy(_equations.rhs_kernel, potential_kernel=potential_kernel, rhs_core=rhs_core)
rotation_rate_kernel = jit_copy(_equations.rotation_rate_kernel)
rhs_rotation_kernel = jit_copy(_equations.rhs_rotation_kernel, rhs_kernel=rhs_kernel, rotation_rate_kernel=rotation_rate_kernel)
turn_rotation_kernel = jit_copy(_equations.turn_rotation_kernel)


@numba.njit(**JIT_OPTIONS)
def energy_kernel(y, P, vel, force):
    """H = 𝒯 + V of the packed state ``y`` (11,) with kernel parameters ``P`` (9,) (eq. (41) of [1]);
    ``vel`` (7,), ``force`` (4,) are work space."""
    v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], y[7], y[8], y[9])
    return kinetic_kernel(y, P, vel, force) + v


__all__ = ["CACHE", "CACHE_DIR", "JIT_OPTIONS", "cache_location", "jit_copy", "kinetic_iso", "kinetic_kernel", "potential_kernel", "rhs_iso",
           "rhs_core", "rhs_kernel", "rotation_rate_kernel", "rhs_rotation_kernel", "turn_rotation_kernel", "energy_kernel"]
