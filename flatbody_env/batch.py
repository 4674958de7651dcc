"""``simulate_batch``: N bodies of one shape from N initial states, on the CPU or on a CUDA GPU.

Each body runs the compiled two-polar method named by ``method`` (the kernels behind
``simulate(..., method=NAME, model="two-polar")``) through the same output times; the result is a
:class:`BatchTrajectory` with a per-body status instead of an exception, so one failed body does not
stop the others. ``device="cpu"`` runs the compiled CPU kernels in parallel over bodies
(:mod:`flatbody_env.integrators.batch_solve`); ``device="cuda"`` runs the same kernel source on the
GPU, one thread per body (:mod:`flatbody_env.integrators.cuda`).

The defaults match :func:`~flatbody_env.simulation.simulate`: integration from t = 0 (``times``
need not hold 0: the state at t = 0 is ``y0``), the energy tolerance
``FIXED_STEP_ENERGY_TOL · max(1, |H₀|)`` for fixed-step methods and
``max(1e-8, 1e4 · max(rtol, atol)) · max(1, |H₀|)`` for DOP853, and the work budget ``max_nfev``
per body. The model ladder is not consulted: every body runs the full two-polar equations.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatbody_env.integrators import DEFAULT_MAX_NFEV, Tolerances, get_method
from flatbody_env.integrators.base import check_step
from flatbody_env.integrators.specs import BATCH_METHODS, BY_NAME
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.state import STATE_NAMES, STATE_SIZE
from flatbody_env.simulation import FIXED_STEP_ENERGY_TOL

DEVICES = ("cpu", "cuda")
"""Methods with batch kernels (the compiled two-polar methods)."""
MAX_BODIES = 1 << 24
"""Most bodies in one call."""
MAX_OUTPUT_FLOATS = 1 << 28
"""Most floats in one result (N · T · 11, 2 GiB): larger batches are refused before anything is allocated."""

_POSITIVE = (7, 8, 9)


@dataclass
class BatchTrajectory:
    """N trajectories through the same output times.

    Attributes
    ----------
    t : ndarray (T,)
        Output times.
    state : ndarray (N, T, 11)
        States in the order of :data:`~flatbody_env.physics.state.STATE_NAMES`; NaN from the output
        time at which a body's failure was detected on.
    status : ndarray (N,) int64
        0 = success, otherwise ``flatbody_env.integrators.failure.KINDS[status]`` names the failure.
    nfev : ndarray (N,) int64
        Right-hand-side evaluations per body.
    t_fail : ndarray (N,)
        When the failure was detected (NaN for bodies that succeeded).
    y0 : ndarray (N, 11)
        The states at t = 0.
    method, device : str
        What integrated it and where.
    wall_time : float
        Seconds spent integrating (compilation included on first use).
    """

    t: np.ndarray
    state: np.ndarray
    status: np.ndarray
    nfev: np.ndarray
    t_fail: np.ndarray
    y0: np.ndarray
    method: str
    device: str
    wall_time: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of bodies."""
        return int(self.state.shape[0])

    @property
    def ok(self) -> np.ndarray:
        """(N,) bool: the bodies that succeeded."""
        return self.status == 0

    @property
    def kinds(self) -> list[str]:
        """Each body's outcome as a failure kind (``"ok"`` on success)."""
        from flatbody_env.integrators.failure import KINDS

        return [KINDS[int(s)] for s in self.status]

    def series(self, name: str) -> np.ndarray:
        """One state entry of every body, shape (N, T) (``name`` from STATE_NAMES)."""
        if name not in STATE_NAMES:
            raise ValueError(f"name: unknown state entry {name!r} (allowed: {', '.join(STATE_NAMES)})")
        return self.state[:, :, STATE_NAMES.index(name)]


def _initial_states(y0: Any) -> np.ndarray:
    arr = validation.float_array("y0", y0, shape=(None, STATE_SIZE))
    n = arr.shape[0]
    if not 1 <= n <= MAX_BODIES:
        raise ValueError(f"y0: must hold 1 to {MAX_BODIES} states (rows), got {n}")
    low, high = validation.STRETCH_RANGE
    for j in range(STATE_SIZE):
        col = arr[:, j]
        if j in _POSITIVE:
            bad = np.flatnonzero((col < low) | (col > high))
            rng = f"[{low:g}, {high:g}]"
        else:
            bad = np.flatnonzero(np.abs(col) > validation.MOMENTUM_MAX)
            rng = f"[{-validation.MOMENTUM_MAX:g}, {validation.MOMENTUM_MAX:g}]"
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"y0[{i}].{STATE_NAMES[j]}: must lie in {rng}, got {col[i]!r}")
    same = np.flatnonzero(arr[:, 7] == arr[:, 8])
    if same.size:
        raise ValueError(f"y0[{int(same[0])}].lambda: must differ from mu (lambda = mu is the singular set of the two-polar chart)")
    return np.ascontiguousarray(arr)


def _output_times(times: Any) -> np.ndarray:
    if isinstance(times, (int, float, np.integer, np.floating)) and not isinstance(times, bool):
        times = [times]
    arr = validation.float_array("times", times, shape=(None,))
    if not 1 <= arr.size <= validation.MAX_SAMPLES:
        raise ValueError(f"times: must hold 1 to {validation.MAX_SAMPLES} times, got {arr.size}")
    if np.any(arr < 0) or np.any(arr > validation.T_END_MAX):
        raise ValueError(f"times: every time must lie in [0, {validation.T_END_MAX:g}]")
    if np.any(np.diff(arr) <= 0):
        raise ValueError("times: must be strictly increasing")
    return arr


def simulate_batch(
    body: Body,
    y0: Sequence[Sequence[float]] | np.ndarray,
    *,
    times: Sequence[float] | np.ndarray,
    method: str,
    step: float | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    energy_tol: float | None = None,
    max_nfev: int = DEFAULT_MAX_NFEV,
    device: str = "cpu",
) -> BatchTrajectory:
    """Integrate N bodies of one shape from the states ``y0`` (N, 11) through ``times``.

    Parameters
    ----------
    body : Body
        The shared shape (inertia and a built-in potential: the kernels are compiled).
    y0 : array (N, 11)
        Initial states at t = 0, rows in the order of STATE_NAMES; λ, μ, ϱ in
        [1e-6, 1e6], λ ≠ μ, other entries within ±1e6.
    times : sequence of float (T,)
        Output times, strictly increasing, in [0, 1e6]; at most 100 000. N · T · 11 must stay
        below :data:`MAX_OUTPUT_FLOATS`.
    method : str
        One of :data:`BATCH_METHODS`.
    step : float, optional
        Step of the fixed-step methods (required for them, refused by DOP853-numba).
    rtol, atol : float
        Tolerances of DOP853-numba.
    energy_tol : float, optional
        Allowed |H(t) − H(0)| per body (absolute; ``math.inf`` switches the check off); default as
        :func:`~flatbody_env.simulation.simulate` (per body, from its own H₀).
    max_nfev : int
        Work budget per body: right-hand-side evaluations.
    device : {"cpu", "cuda"}
        Where to run: the compiled CPU kernels (parallel over bodies) or a CUDA GPU.

    Returns
    -------
    BatchTrajectory
        Per-body status instead of exceptions; body i equals ``simulate(Scene(body, y0[i]),
        times=..., method=method, step=step, model="two-polar")`` to round-off (tested to 1e-12).

    Raises
    ------
    ValueError
        Bad arguments (naming the field and its range).
    IntegrationError
        ``kind="budget"``: a fixed-step run that would exceed ``max_nfev`` (known before the run).
    flatbody_env.integrators.cuda.CudaUnavailableError
        ``device="cuda"`` without a usable CUDA GPU (the message names the fix).
    """
    if not isinstance(body, Body):
        raise ValueError(f"body: expected a flatbody_env.Body, got {type(body).__name__}")
    device = validation.string("device", device, choices=DEVICES)
    method = validation.string("method", method, choices=BATCH_METHODS)
    Y0 = _initial_states(y0)
    times_arr = _output_times(times)
    prepended = times_arr[0] != 0.0
    grid = np.concatenate([[0.0], times_arr]) if prepended else times_arr
    n = Y0.shape[0]
    if n * grid.size * STATE_SIZE > MAX_OUTPUT_FLOATS:
        raise ValueError(f"y0, times: N * T * 11 = {n} * {grid.size} * 11 floats exceeds the limit of {MAX_OUTPUT_FLOATS} "
                         "(split the batch or ask for fewer times)")
    meth = get_method(method)
    tol = Tolerances(rtol=rtol, atol=atol, step=step, max_nfev=max_nfev, energy_tol=math.inf if energy_tol is None else energy_tol)
    h = check_step(meth.info, tol)
    if device == "cuda":
        from flatbody_env.integrators import cuda

        cuda.require()  # CudaUnavailableError naming the fix, before any work

    from flatbody_env.integrators import batch_solve as bs
    from flatbody_env.integrators.compiled_methods import _check_compiled_body, _check_fixed_budget, kernel_params

    _check_compiled_body(body, method)
    spec = BY_NAME[method]
    kind, coeffs = spec.code, spec.coeffs
    if spec.kind == "split" and not body.inertia.is_isotropic:
        raise ValueError(f"body: {method} (Poisson splitting) needs J1 = J2; use RK4 or DOP853-numba")
    if not spec.info.adaptive:
        _check_fixed_budget(method, grid, h, spec.stages, tol)
    P = kernel_params(body)
    if energy_tol is None:
        H0 = np.empty(n)
        bs.batch_energy(Y0, P, H0)
        scale = FIXED_STEP_ENERGY_TOL if not spec.info.adaptive else max(1e-8, 1e4 * max(tol.rtol, tol.atol))
        etol = scale * np.maximum(1.0, np.abs(H0))
    else:
        etol = np.full(n, tol.energy_tol)
    u = np.zeros(4)
    start = time.perf_counter()
    if grid.size == 1:  # only t = 0 asked for: the initial states
        OUT, STATUS = Y0[:, None, :].copy(), np.zeros(n, np.int64)
        NFEV, TFAIL = np.zeros(n, np.int64), np.full(n, np.nan)
    elif device == "cpu":
        OUT = np.empty((n, grid.size, STATE_SIZE))
        STATUS = np.zeros(n, np.int64)
        NFEV = np.zeros(n, np.int64)
        TFAIL = np.empty(n)
        bs.batch_solve(kind, coeffs, Y0, grid, u, P, h, tol.rtol, tol.atol, etol, tol.max_nfev, OUT, STATUS, NFEV, TFAIL)
    else:
        OUT, STATUS, NFEV, TFAIL = cuda.solve(method, Y0, grid, u, P, h=h, rtol=tol.rtol, atol=tol.atol, energy_tol=etol,
                                              max_nfev=tol.max_nfev)
    wall = time.perf_counter() - start
    keep = slice(1, None) if prepended else slice(None)
    return BatchTrajectory(t=times_arr.copy(), state=OUT[:, keep], status=STATUS, nfev=NFEV, t_fail=TFAIL, y0=Y0, method=method,
                           device=device, wall_time=wall)


__all__ = ["BATCH_METHODS", "BatchTrajectory", "DEVICES", "MAX_BODIES", "MAX_OUTPUT_FLOATS", "simulate_batch"]
