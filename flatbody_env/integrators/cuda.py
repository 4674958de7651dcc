"""The CUDA target of the integrators: the same plain-Python kernels, compiled by numba's CUDA target.

The CUDA target of :func:`.jit.retarget`, the one way a kernel is compiled: every integrator function
is plain Python (or a numba CPU dispatcher around it, ``.py_func``); :func:`device_twin` compiles it
with ``cuda.jit(device=True)`` with every function it calls re-bound to *its* device twin,
recursively, as the CPU target does with ``njit``. No formula is restated: the physics kernels, the
RK4/splitting/DOP853 steps (one step control, :func:`~.twopolar_kernels.dop853_advance`) and the
per-body drivers of :mod:`.batch_solve` run on the GPU from the source the CPU runs.

Only the target glue is written here: the two kernels (one thread per body) that take their work
arrays from ``cuda.local.array`` and their body from ``cuda.grid(1)``, and the device side of
:func:`~.twopolar_kernels.dop853_initial_step` (its CPU wrapper allocates one array with
``np.empty``; on the device that array is a local one). Module-level coefficient arrays
(``_A``, ``STRANG``, ``_KEEP_*``) become constant memory unchanged. Device code reads ``np`` as
:data:`DEVICE_NUMPY`: numpy with its scalar ufuncs (``np.sqrt``, ``np.abs``, …) replaced by their
``math`` twins, which numba-cuda lowers (numba-cuda 0.30.4 has no CUDA lowering of ``np.sqrt`` on a
scalar: ``KeyError: <ufunc 'sqrt'>`` on a real GPU, while its simulator runs numpy itself). The task's
kernels keep calling numpy ufuncs, so that the same source also scores N bodies on arrays.

* :func:`env_step` — one environment step of N bodies, **one launch per step**: ``Y``, ``OUT``
  (11, N), ``U`` (4, N) structure-of-arrays (coalesced: thread b reads column b), ``STATUS`` (N,)
  with :mod:`.failure`'s codes. Device arrays stay on the device (no copy); host arrays are copied.
* :func:`solve` — N trajectories through the output times, ``OUT`` (11, T, N) on the device,
  returned as (N, T, 11); :class:`Trajectories` keeps them on the device so that a series of launches continues the
  bodies each launch's budget stopped: the kernel behind ``simulate_batch(..., device="cuda")``.

numba's CUDA target comes from the ``numba-cuda`` package (``pip install "flatbody[gpu]"``). It is
imported only when a CUDA function is first used, never by importing this module, so a machine
without it (or without a GPU) imports everything and gets one :class:`CudaUnavailableError` that
names the fix. numba-cuda 0.30.4 fails to import on numpy ≥ 2.5 (it uses the removed
``np.row_stack``): the ``gpu`` extra pins numpy below 2.5, and that import failure is reported by
the same error.

Testing without a GPU: numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, set before numba.cuda is
imported) runs these kernels as Python on the CPU; ``tests/integrators/test_cuda_simulator.py``
compares them with the CPU kernels in a subprocess.
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import types
import warnings

import numpy as np
from numba import float64, int64

from flatbody_env.integrators import batch_solve as _bs
from flatbody_env.integrators.batch_solve import env_step_body, solve_body
from flatbody_env.integrators.jit import _KERNEL_SOURCE_DIRS, _PACKAGE, CACHE, Target, rebound, retarget
from flatbody_env.integrators.twopolar_kernels import dop853_initial_step_into

INSTALL_HINT = 'pip install "flatbody[gpu]" on a machine with an NVIDIA driver'
THREADS_PER_BLOCK = 128
"""Threads per block of both kernels (the simulator runs each as a Python thread: keep N small there)."""

cuda = None
"""numba.cuda once :func:`require` has imported it (the kernels' ``cuda`` global)."""


class CudaUnavailableError(RuntimeError):
    """No usable CUDA target: numba-cuda missing or broken, or no GPU / driver."""


def simulated() -> bool:
    """True when numba's CUDA simulator is on (``NUMBA_ENABLE_CUDASIM=1``)."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


def _import_cuda():
    try:
        from numba import cuda as module
    except Exception as exc:  # ImportError, or numba-cuda on numpy >= 2.5 (AttributeError: row_stack)
        raise CudaUnavailableError(
            f"device: numba's CUDA target does not import ({type(exc).__name__}: {exc}); {INSTALL_HINT} "
            "(numpy below 2.5 for numba-cuda 0.30)"
        ) from exc
    return module


@functools.lru_cache(maxsize=1)
def _probe() -> tuple[bool, str]:
    try:
        module = _import_cuda()
    except CudaUnavailableError as exc:
        return False, str(exc)
    try:
        ok = bool(module.is_available())
    except Exception as exc:  # a driver that fails to initialise
        return False, f"device: CUDA driver error ({exc}); {INSTALL_HINT}"
    return (True, "") if ok else (False, f"device: no CUDA GPU found ({INSTALL_HINT})")


def is_available() -> bool:
    """Whether ``device="cuda"`` can run here (a GPU, or the simulator). Never raises."""
    return _probe()[0]


def require():
    """numba.cuda, or :class:`CudaUnavailableError` saying what is missing and how to fix it."""
    ok, why = _probe()
    if not ok:
        raise CudaUnavailableError(why)
    global cuda
    cuda = _import_cuda()
    return cuda


def device_name() -> str:
    """The GPU's name (``"simulator"`` under the simulator); :class:`CudaUnavailableError` without one."""
    module = require()
    if simulated():
        return "simulator"
    name = module.get_current_device().name
    return name.decode() if isinstance(name, bytes) else str(name)


# --------------------------------------------------------------------------------------------- device twins
_SCALAR_UFUNCS = {
    "sqrt": math.sqrt,
    "abs": math.fabs,
    "absolute": math.fabs,
    "fabs": math.fabs,
    "exp": math.exp,
    "log": math.log,
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "arctan": math.atan,
    "arctan2": math.atan2,
    "hypot": math.hypot,
    "tanh": math.tanh,
    "floor": math.floor,
    "ceil": math.ceil,
    "isfinite": math.isfinite,
    "isnan": math.isnan,
    "isinf": math.isinf,
    "copysign": math.copysign,
}


def _device_numpy() -> types.ModuleType:
    """numpy as device code reads it (module docstring): every attribute of numpy, except the scalar ufuncs of
    :data:`_SCALAR_UFUNCS`, which are their ``math`` twins (the same IEEE results on float64)."""
    module = types.ModuleType("numpy_on_the_device", "numpy with its scalar ufuncs as math functions (device code)")
    module.__dict__.update({k: getattr(np, k) for k in dir(np) if not k.startswith("_")})
    module.__dict__.update(_SCALAR_UFUNCS)
    return module


DEVICE_NUMPY = _device_numpy()
"""The ``np`` of device code (:func:`device_twin`, :func:`kernel`)."""


@functools.lru_cache(maxsize=1)
def _target() -> tuple[Target, dict]:
    """The CUDA target of :func:`~.jit.retarget` and the globals re-bound on it: the kernels' ``cuda``, ``np`` as
    :data:`DEVICE_NUMPY`, and the device side of the initial step (its CPU wrapper allocates) wherever a device
    function calls it."""
    module = require()
    return Target("cuda", module.jit(device=True), share_compiled=False), dict(
        cuda=module, np=DEVICE_NUMPY, dop853_initial_step=_dop853_initial_step_device
    )


def device_twin(func):
    """The CUDA device function compiled from ``func`` (a numba CPU dispatcher or plain Python) with everything
    it calls re-bound to device twins, recursively (:func:`~.jit.retarget` on the CUDA target).
    :class:`CudaUnavailableError` without a CUDA target."""
    target, constants = _target()
    return retarget(func, target, **constants)


def _dop853_initial_step_device(y, f, t0, t_bound, u, P, rtol, atol, vel, force, work, counters):
    """Device side of :func:`~.twopolar_kernels.dop853_initial_step` (same arguments): its second work array
    is a local one."""
    y1 = cuda.local.array(11, float64)
    return dop853_initial_step_into(y, f, t0, t_bound, u, P, rtol, atol, vel, force, work, y1, counters)


def _env_step_kernel(kind, coeffs, Y, U, P, dt, h, rtol, atol, energy_tol, max_nfev, OUT, STATUS, NFEV):
    """One thread per body: :func:`~.batch_solve.env_step_body` with local work arrays; ``max_nfev`` is each body's budget of
    RHS evaluations in the step (DOP853 checks it before every step, as :func:`~.batch_solve.batch_env_step_serial`)."""
    b = cuda.grid(1)
    if b < Y.shape[1]:
        y = cuda.local.array(11, float64)
        u = cuda.local.array(4, float64)
        out = cuda.local.array(11, float64)
        K = cuda.local.array((13, 11), float64)
        ynew = cuda.local.array(11, float64)
        ytmp = cuda.local.array(11, float64)
        vel = cuda.local.array(7, float64)
        force = cuda.local.array(4, float64)
        f = cuda.local.array(11, float64)
        counters = cuda.local.array(4, int64)
        counters[3] = max_nfev
        env_step_body(
            b,
            kind,
            coeffs,
            Y,
            U,
            P,
            dt,
            h,
            rtol,
            atol,
            energy_tol,
            OUT,
            STATUS,
            NFEV,
            y,
            u,
            out,
            K,
            ynew,
            ytmp,
            vel,
            force,
            f,
            counters,
        )


def _solve_kernel(kind, coeffs, Y0, times, u, P, h, rtol, atol, ENERGY_TOL, max_nfev, OUT, STATUS, NFEV, TFAIL, CARRY):
    """One thread per body: :func:`~.batch_solve.solve_body`; Y0 (11, N), OUT (11, T, N), CARRY (carry size, N)."""
    b = cuda.grid(1)
    if b < Y0.shape[1]:
        y = cuda.local.array(11, float64)
        f = cuda.local.array(11, float64)
        K = cuda.local.array((13, 11), float64)
        ynew = cuda.local.array(11, float64)
        ytmp = cuda.local.array(11, float64)
        vel = cuda.local.array(7, float64)
        force = cuda.local.array(4, float64)
        counters = cuda.local.array(4, int64)
        fail = cuda.local.array(3, float64)
        solve_body(
            b,
            kind,
            coeffs,
            Y0[:, b],
            times,
            u,
            P,
            h,
            rtol,
            atol,
            ENERGY_TOL[b],
            max_nfev,
            OUT[:, :, b],
            STATUS,
            NFEV,
            TFAIL,
            y,
            f,
            K,
            ynew,
            ytmp,
            vel,
            force,
            counters,
            fail,
            CARRY[:, b],
        )


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """A hash of the source every device kernel is compiled from (the modules of the physics, integrator and env
    layers): part of the key of the kernels' on-disk cache, so that an edit anywhere beneath a kernel compiles it anew
    (numba alone compares only the kernel's own file)."""
    h = hashlib.sha256()
    for path in sorted(_PACKAGE.glob("*/*.py")):
        if path.parent.name in _KERNEL_SOURCE_DIRS:
            h.update(path.relative_to(_PACKAGE).as_posix().encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def _cache_class():
    """numba-cuda's kernel cache with :func:`source_digest` in its key; an entry that cannot be read or written costs
    a compile and a warning, never the launch."""
    from numba.cuda.dispatcher import CUDACache

    class SourceDigestCache(CUDACache):
        def _index_key(self, sig, codegen):
            return (*super()._index_key(sig, codegen), source_digest())

        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except Exception as exc:  # a damaged or foreign entry: compiled anew
                warnings.warn(f"CUDA kernel cache: not read ({type(exc).__name__}: {exc}); compiling", stacklevel=2)
                return None

        def save_overload(self, sig, data):
            try:
                super().save_overload(sig, data)
            except Exception as exc:  # the kernel runs all the same; the next process compiles it again
                warnings.warn(f"CUDA kernel cache: not written ({type(exc).__name__}: {exc})", stacklevel=2)

    return SourceDigestCache


def _jit(func, target, constants):
    """A CUDA kernel from the module-level plain-Python ``func`` re-bound on the CUDA target, with an on-disk cache
    (where :data:`~.jit.CACHE` allows one; not under the simulator, which compiles nothing): the env's kernels take
    ≈ 40 s to compile on first use (PTX, then the driver's machine code), loaded from the cache afterwards, in any
    process, until a kernel's source changes (:func:`source_digest`) or another GPU model or driver asks for other
    machine code (numba-cuda keys entries by compute capability and CUDA version)."""
    dispatcher = constants["cuda"].jit(rebound(func, target, **constants))
    if CACHE and not simulated():
        dispatcher._cache = _cache_class()(dispatcher.py_func)
    return dispatcher


@functools.lru_cache(maxsize=1)
def _kernels():
    target, constants = _target()
    return _jit(_env_step_kernel, target, constants), _jit(_solve_kernel, target, constants)


@functools.cache
def kernel(func):
    """The CUDA kernel compiled from ``func``, a module-level plain-Python kernel from outside this module (the env's,
    :mod:`flatbody_env.env.transition`) whose ``cuda`` global is bound here, with the same device twins as
    :func:`env_step`'s; cached on disk (:func:`_jit`)."""
    target, constants = _target()
    return _jit(func, target, constants)


# --------------------------------------------------------------------------------------------- host API
def _blocks(n: int, threads: int) -> tuple[int, int]:
    threads = max(1, min(int(threads), n))
    return (n + threads - 1) // threads, threads


def _method(method: str) -> tuple[int, np.ndarray]:
    if method not in _bs.KIND:
        raise ValueError(f"method: no batch kernel for {method!r} (allowed: {', '.join(_bs.BATCH_METHODS)})")
    return _bs.KIND[method]


def env_step(
    method,
    Y,
    U,
    P,
    dt,
    *,
    h=0.0,
    rtol=1e-11,
    atol=1e-11,
    energy_tol=np.inf,
    OUT=None,
    STATUS=None,
    NFEV=None,
    threads_per_block=THREADS_PER_BLOCK,
    max_nfev=_bs.NO_BUDGET,
):
    """One environment step of N bodies on the GPU, one kernel launch.

    ``Y`` (11, N), ``U`` (4, N), ``P`` (9,) host or device arrays; outputs ``OUT`` (11, N), ``STATUS``,
    ``NFEV`` (N,) int64 are allocated on the device when not given. Returns (OUT, STATUS, NFEV) as
    given/allocated (device arrays unless host arrays were passed in, which are then filled). ``max_nfev``: each
    body's budget of RHS evaluations in this step (DOP853; a body past it gets the ``budget`` status and keeps its
    state, as in :func:`~.batch_solve.batch_env_step_serial`); the launch's work is bounded by it, since a kernel cannot
    read the clock. The env's whole step (:mod:`flatbody_env.env.transition`) has the env's budget,
    :data:`~flatbody_env.physics.validation.ENV_STEP_MAX_NFEV`."""
    kind, coeffs = _method(method)
    kernel, _ = _kernels()
    n = Y.shape[1]
    if OUT is None:
        OUT = cuda.device_array((11, n), np.float64)
    if STATUS is None:
        STATUS = cuda.device_array(n, np.int64)
    if NFEV is None:
        NFEV = cuda.device_array(n, np.int64)
    blocks, threads = _blocks(n, threads_per_block)
    kernel[blocks, threads](
        kind,
        coeffs,
        Y,
        U,
        P,
        float(dt),
        float(h),
        float(rtol),
        float(atol),
        float(energy_tol),
        int(max_nfev),
        OUT,
        STATUS,
        NFEV,
    )
    return OUT, STATUS, NFEV


class Trajectories:
    """N trajectories on the GPU whose arrays stay on the device between launches: each :meth:`launch` continues the
    bodies the last one's budget of evaluations stopped (DOP853: :func:`~.twopolar_kernels.dop853_solve_into`'s
    ``carry``, one column per body) and leaves the others as they are, so a body that finishes is bit for bit that of
    one launch. Y0 (N, 11) host; ``energy_tol`` (N,); the other arguments as :func:`solve`'s."""

    def __init__(self, method, Y0, times, u, P, *, h, rtol, atol, energy_tol, threads_per_block=THREADS_PER_BLOCK):
        from flatbody_env.integrators.twopolar_kernels import carry_size

        kind, coeffs = _method(method)
        _, self._kernel = _kernels()
        n, T = Y0.shape[0], times.size
        self._grid = _blocks(n, threads_per_block)
        self._inputs = (
            kind,
            cuda.to_device(coeffs),
            cuda.to_device(np.ascontiguousarray(Y0.T)),
            cuda.to_device(times),
            cuda.to_device(u),
            cuda.to_device(P),
            float(h),
            float(rtol),
            float(atol),
            cuda.to_device(energy_tol),
        )
        self._OUT = cuda.device_array((11, T, n), np.float64)
        self._STATUS = cuda.device_array(n, np.int64)
        self._NFEV = cuda.device_array(n, np.int64)
        self._TFAIL = cuda.device_array(n, np.float64)
        self._CARRY = cuda.to_device(np.zeros((carry_size(), n)))

    def launch(self, max_nfev: int) -> np.ndarray:
        """One launch, every body within ``max_nfev`` evaluations in all; returns the bodies' statuses (host)."""
        blocks, threads = self._grid
        self._kernel[blocks, threads](
            *self._inputs, int(max_nfev), self._OUT, self._STATUS, self._NFEV, self._TFAIL, self._CARRY
        )
        return self._STATUS.copy_to_host()

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(OUT (N, T, 11), STATUS, NFEV, TFAIL) host arrays."""
        OUT = np.ascontiguousarray(self._OUT.copy_to_host().transpose(2, 1, 0))
        return OUT, self._STATUS.copy_to_host(), self._NFEV.copy_to_host(), self._TFAIL.copy_to_host()


def solve(method, Y0, times, u, P, *, h, rtol, atol, energy_tol, max_nfev, threads_per_block=THREADS_PER_BLOCK):
    """N trajectories on the GPU: Y0 (N, 11) host → (OUT (N, T, 11), STATUS, NFEV, TFAIL) host arrays
    (the batch analogue of :func:`~.batch_solve.batch_solve`; ``energy_tol`` (N,)); one launch of :class:`Trajectories`."""
    run = Trajectories(
        method, Y0, times, u, P, h=h, rtol=rtol, atol=atol, energy_tol=energy_tol, threads_per_block=threads_per_block
    )
    run.launch(max_nfev)
    return run.result()


__all__ = [
    "INSTALL_HINT",
    "THREADS_PER_BLOCK",
    "CudaUnavailableError",
    "Trajectories",
    "device_name",
    "device_twin",
    "env_step",
    "is_available",
    "kernel",
    "require",
    "simulated",
    "solve",
]
