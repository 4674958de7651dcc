"""Compiled copies of the physics layer's scalar kernels (numba, on-disk cache where one can be written).

The physics layer stays free of numba: :func:`flatbody_env.physics.hamiltonian.kinetic_kernel`,
:func:`flatbody_env.physics.potentials.potential_kernel`, :func:`flatbody_env.physics.equations.rhs_core` and
:func:`flatbody_env.physics.equations.rhs_kernel` are plain-float Python functions. numba compiles a
function's calls to globals only when those globals are numba dispatchers themselves, so each
kernel is compiled here by :func:`retarget`: the same code object (the physics module's source)
with every function it calls re-bound to its compiled copy, recursively
(``types.FunctionType(f.__code__, {**f.__globals__, **compiled_callees})``). No formula is restated
here. The same :func:`retarget` clones the stepping code for the 20-entry state that carries R
(:mod:`.rotation_kernels`), the fused batch's block sizes (:mod:`.batch_kernels`) and the ladder's
sub-systems (:mod:`.ladder_kernels`), compiles the env's kernels (:mod:`flatbody_env.env.compiled`)
and, on its CUDA :class:`Target`, the device functions (:mod:`.cuda`).

Inlining (:func:`inlined`): the scalar right-hand side (:func:`~flatbody_env.physics.equations.rhs_kernel`,
:func:`~flatbody_env.physics.equations.rhs_core`, the J1 ≠ J2 kinetic term they call,
:func:`~flatbody_env.physics.hamiltonian.kinetic_general`, and the store of its outputs,
:func:`~flatbody_env.physics.hamiltonian.store_kinetic`) is compiled into its callers, so that the arrays it is handed
cost no reference counting per call (a call left in it keeps the counts): 150 → 12.5 ns a call, a DOP853 step of the
single env 2.7 → 0.95 µs, ≈ 5 s more compiling on the first run.

The on-disk cache (:func:`njit`): numba keys a function by its file, line and bytecode and checks
its own file's time stamp; :func:`code_digest` adds the constants, the numeric globals and,
recursively, the code of every compiled callee, so a caller recompiles when a callee in another
file changes, and copies of one code object with other callees get their own entries.

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

import hashlib
import os
import tempfile
import types
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
from numba.core.caching import FunctionCache

from flatbody_env.physics import equations as _equations
from flatbody_env.physics import hamiltonian as _hamiltonian
from flatbody_env.physics import potentials as _potentials

_PACKAGE = Path(__file__).resolve().parents[1]
_KERNEL_SOURCE_DIRS = ("physics", "integrators", "env", "bench")
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


def _names(code: types.CodeType) -> set[str]:
    """The global names ``code`` (and the code nested in it) reads."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _names(const)
    return names


def _consts(code: types.CodeType) -> list:
    return [_consts(c) if isinstance(c, types.CodeType) else c for c in code.co_consts]


def _value_digest(value) -> bytes | None:
    if isinstance(value, np.ndarray):
        return repr((value.dtype.str, value.shape)).encode() + value.tobytes()
    if isinstance(value, (bool, int, float, complex, str, np.number)):
        return repr(value).encode()
    return None


def code_digest(func, _active=None) -> str:
    """A hash of what ``func`` compiles to besides its own bytecode: its constants, the values of the
    numeric globals it reads (e.g. a re-bound ``N``) and, recursively, the code of every compiled
    function it calls. It is part of the on-disk cache key of every compiled function
    (:func:`njit`), so a caller recompiles when a callee in another file changes (numba alone
    compares only the caller's own file) and two copies of one code object with other callees or
    constants get their own cache entries."""
    func = getattr(func, "py_func", func)
    cached = getattr(func, "_flatbody_digest", None)
    if cached is not None:
        return cached
    active = set() if _active is None else _active
    if id(func) in active:  # recursion: the cycle is hashed once
        return func.__qualname__
    active.add(id(func))
    h = hashlib.sha256(func.__code__.co_code + repr(_consts(func.__code__)).encode())
    if func.__code__ in INLINED:  # compiled into its callers: their machine code changes with it
        h.update(b"inline=always")
    for name in sorted(_names(func.__code__)):
        value = func.__globals__.get(name)
        if isinstance(value, numba.core.dispatcher.Dispatcher):
            h.update(f"{name}:{code_digest(value, active)}".encode())
        elif (digest := _value_digest(value)) is not None:
            h.update(name.encode() + digest)
    active.discard(id(func))
    func._flatbody_digest = digest = h.hexdigest()
    return digest


class _DigestCache(FunctionCache):
    """numba's function cache with :func:`code_digest` in the index key."""

    def _index_key(self, sig, codegen):
        return super()._index_key(sig, codegen) + (code_digest(self._py_func),)


INLINED: set = set()
"""Code objects of the kernels compiled into their callers (numba's ``inline="always"``, :func:`inlined`)."""


def inlined(func):
    """Mark the plain-Python kernel ``func`` to be compiled into its callers (numba's ``inline="always"``: inlined in
    numba's own IR, before LLVM; returns ``func`` unchanged). A compiled call that LLVM does not inline pays an atomic
    increment and decrement of the reference count of every array it is handed; for the scalar right-hand side (six
    arrays, 13 calls per DOP853 step) that cost ten times its arithmetic. For small kernels called in hot loops with
    array arguments (each mark adds compile time to every caller); the results are bit for bit those of the call (no
    fast-math). Mark before the first caller compiles."""
    INLINED.add(getattr(func, "py_func", func).__code__)
    return func


def njit(func=None, **options):
    """``numba.njit`` with :data:`JIT_OPTIONS` (and ``options``) whose on-disk cache entry is keyed by
    :func:`code_digest` too; as ``@njit`` or ``njit(parallel=True)(func)``. A kernel marked by :func:`inlined` is
    compiled with ``inline="always"``."""

    def compile_(f):
        inline = {"inline": "always"} if f.__code__ in INLINED else {}
        dispatcher = numba.njit(**{**JIT_OPTIONS, **inline, **options})(f)
        if CACHE:
            dispatcher._cache = _DigestCache(dispatcher.py_func)
        return dispatcher

    return compile_ if func is None else compile_(func)


def _clone(func, callees):
    """The plain-Python ``func`` (or a dispatcher's Python function) with the globals ``callees`` replaced."""
    func = getattr(func, "py_func", func)
    clone = types.FunctionType(
        func.__code__, {**func.__globals__, **callees}, func.__name__, func.__defaults__, func.__closure__
    )
    clone.__module__, clone.__qualname__, clone.__doc__ = func.__module__, func.__qualname__, func.__doc__
    return clone


def _compile_cpu(clone):
    # a name of its own: numba's cached machine code names its symbols after the qualified name, so two
    # copies of one code object under one name would link to each other's code
    clone.__qualname__ = f"{clone.__qualname__}__{code_digest(clone)[:12]}"
    return njit(clone)


@dataclass(frozen=True)
class Target:
    """Where :func:`retarget` compiles: ``compile`` turns a re-bound plain-Python function into the
    target's compiled function. ``share_compiled``: a compiled (CPU) callee with nothing re-bound
    beneath it is used as it is (the CPU); else every callee is compiled anew (CUDA, :mod:`.cuda`)."""

    name: str
    compile: Callable
    share_compiled: bool = True


CPU = Target("cpu", _compile_cpu)
"""The CPU target (:func:`njit`, the on-disk cache keyed by :func:`code_digest`)."""

_RETARGETED: dict = {}


def _is_function(value) -> bool:
    return isinstance(value, (numba.core.dispatcher.Dispatcher, types.FunctionType))


def retarget(func, target: Target = CPU, **constants):
    """``func`` (plain Python or a compiled dispatcher) compiled for ``target`` with the globals
    ``constants`` re-bound in it and, recursively, in every function it calls: a plain-Python callee
    (e.g. a physics kernel) is compiled the same way; a compiled callee is copied only when a
    re-bound name is read somewhere beneath it (on the CPU; on other targets always), else shared.
    A constant that is a plain-Python function is a substitute, compiled like a callee; any other
    constant (a number, an array, a compiled function, a module) is used as given. Memoised: one
    copy per (target, function, constants).

    The one way the integrators and the env compile a kernel for another state, size or target (the
    physics kernels, the R-carrying state, the fused batch's block sizes, the ladder's sub-systems,
    the env's kernels, CUDA device functions)."""
    return _retarget(func, target, constants, _key(constants))


def rebound(func, target: Target = CPU, **constants):
    """The plain-Python copy of ``func`` that :func:`retarget` compiles (its callees retargeted), not
    compiled itself: for an entry point the caller compiles (a CUDA kernel)."""
    return _clone(func, _callees(getattr(func, "py_func", func), target, constants, _key(constants)))


def _key(constants) -> tuple:
    return tuple(sorted((k, v if isinstance(v, (int, float)) else id(v)) for k, v in constants.items()))


def _callees(py, target, constants, key) -> dict:
    callees = {}
    for name in _names(py.__code__):
        value = constants[name] if name in constants else py.__globals__.get(name)
        if name in constants and not isinstance(value, types.FunctionType):
            callees[name] = value
        elif _is_function(value) and value is not py:
            twin = _retarget(value, target, constants, key)
            if twin is not value:
                callees[name] = twin
    return callees


def _retarget(func, target, constants, key):
    memo_key = (target.name, id(func), key)
    if memo_key in _RETARGETED:
        return _RETARGETED[memo_key][1]
    _RETARGETED[memo_key] = (func, func)  # a recursive call sees the function itself
    py = getattr(func, "py_func", func)
    callees = _callees(py, target, constants, key)
    shared = target.share_compiled and isinstance(func, numba.core.dispatcher.Dispatcher) and not callees
    result = func if shared else target.compile(_clone(py, callees))
    _RETARGETED[memo_key] = (func, result)  # keeps func alive: its id stays unique
    return result


for _kernel in (_hamiltonian.kinetic_general, _hamiltonian.store_kinetic, _equations.rhs_core, _equations.rhs_kernel):
    inlined(_kernel)  # the scalar right-hand side: called 13 times per DOP853 step with six arrays (module docstring)
kinetic_iso = retarget(_hamiltonian.kinetic_iso)
kinetic_kernel = retarget(_hamiltonian.kinetic_kernel)
potential_kernel = retarget(_potentials.potential_kernel)
rhs_iso = retarget(_equations.rhs_iso)
rhs_core = retarget(_equations.rhs_core)
rhs_kernel = retarget(_equations.rhs_kernel)
rotation_rate_kernel = retarget(_equations.rotation_rate_kernel)
rhs_rotation_kernel = retarget(_equations.rhs_rotation_kernel)
turn_rotation_kernel = retarget(_equations.turn_rotation_kernel)


@njit
def energy_kernel(y, P, vel, force):
    """H = 𝒯 + V of the packed state ``y`` (11,) with kernel parameters ``P`` (9,) (eq. (41) of [1]);
    ``vel`` (7,), ``force`` (4,) are work space."""
    v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], y[7], y[8], y[9])
    return kinetic_kernel(y, P, vel, force) + v


__all__ = [
    "CACHE",
    "CACHE_DIR",
    "CPU",
    "JIT_OPTIONS",
    "Target",
    "cache_location",
    "code_digest",
    "inlined",
    "njit",
    "rebound",
    "retarget",
    "kinetic_iso",
    "kinetic_kernel",
    "potential_kernel",
    "rhs_iso",
    "rhs_core",
    "rhs_kernel",
    "rotation_rate_kernel",
    "rhs_rotation_kernel",
    "turn_rotation_kernel",
    "energy_kernel",
]
