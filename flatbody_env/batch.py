"""``simulate_batch``: N bodies of one shape from N initial states, on the CPU or on a CUDA GPU.

Each body runs the compiled two-polar method named by ``method`` (the kernels behind
``simulate(..., method=NAME, model="two-polar")``) through the same output times; the result is a
:class:`BatchTrajectory` with a per-body status instead of an exception, so one failed body does not
stop the others. ``device="cpu"`` runs the compiled CPU kernels in parallel over bodies
(:mod:`flatbody_env.integrators.batch_solve`); ``device="cuda"`` runs the same kernel source on the
GPU, one thread per body (:mod:`flatbody_env.integrators.cuda`).

The defaults match :func:`~flatbody_env.simulation.simulate`: integration from t = 0 (``times``
need not hold 0: the state at t = 0 is ``y0``), the energy tolerance of
:func:`~flatbody_env.simulation.default_energy_tol`:
``FIXED_STEP_ENERGY_TOL · max(1, |H₀|)`` for fixed-step methods and
``max(1e-8, 1e4 · max(rtol, atol)) · max(1, |H₀|)`` for DOP853, the work budget ``max_nfev``
per body and ``max_wall_time`` for the batch (pieces of bounded work with the clock read between them, each
continuing the last: :class:`~flatbody_env.integrators.budget.WallClockBudget`). The model ladder is not consulted: every body runs the full
two-polar equations.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatbody_env.integrators import DEFAULT_MAX_NFEV, DEFAULT_MAX_WALL_TIME, Tolerances, get_method
from flatbody_env.integrators.base import check_step
from flatbody_env.integrators.budget import GPU_GROWTH, WallClockBudget
from flatbody_env.integrators.failure import BUDGET
from flatbody_env.integrators.specs import BATCH_METHODS, BY_NAME
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.state import STATE_NAMES, STATE_SIZE
from flatbody_env.simulation import energy_tol_scale

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
    extra : dict
        ``"launches"``: kernel launches of a ``device="cuda"`` run (the wall-clock budget's probes included).
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
            raise validation.refusal(f"y0[{i}].{STATE_NAMES[j]}", f"lie in {rng}", float(col[i]))
    same = np.flatnonzero(arr[:, 7] == arr[:, 8])
    if same.size:
        raise ValueError(
            f"y0[{int(same[0])}].lambda: must differ from mu (lambda = mu is the singular set of the two-polar chart)"
        )
    return np.ascontiguousarray(arr)


def _output_times(times: Any) -> np.ndarray:
    if isinstance(times, (int, float, np.integer, np.floating)) and not isinstance(times, bool):
        times = [times]
    arr = validation.float_array("times", times, shape=(None,))
    if not 1 <= arr.size <= validation.MAX_SAMPLES:
        raise ValueError(f"times: must hold 1 to {validation.MAX_SAMPLES} times, got {arr.size}")
    outside = arr[(arr < 0) | (arr > validation.T_END_MAX)]
    if outside.size:
        raise validation.refusal("times", f"each lie in [0, {validation.T_END_MAX:g}]", float(outside[0]))
    if np.any(np.diff(arr) <= 0):
        raise validation.refusal("times", "be strictly increasing")
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
    max_wall_time: float = DEFAULT_MAX_WALL_TIME,
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
    max_wall_time : float
        Seconds for the whole batch ((0, 86 400]). DOP853-numba: a kernel cannot read the clock, so the
        integration runs in pieces, each with a per-body budget of evaluations, the clock read between them
        (:class:`~flatbody_env.integrators.budget.WallClockBudget`): a timed probe (on the CPU the first bodies,
        on the GPU all of them, ``extra["launches"]`` counting the launches) measures the evaluations per
        second, and each later piece continues the bodies still out of budget (and, on the CPU, starts the
        others) with what the time left allows (at most ``max_nfev``). A body past it ends with the ``budget``
        status, the others bit for bit as without this budget. Fixed-step methods: a run
        whose predicted time (a timed probe of a few hundred steps) exceeds it is refused before it starts
        (``IntegrationError``, ``kind="budget"``), on either device.
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
        ``kind="budget"``: a fixed-step run that would exceed ``max_nfev`` (known before the run) or, by a timed
        probe, ``max_wall_time``.
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
        raise ValueError(
            f"y0, times: N * T * 11 = {n} * {grid.size} * 11 floats exceeds the limit of {MAX_OUTPUT_FLOATS} "
            "(split the batch or ask for fewer times)"
        )
    meth = get_method(method)
    tol = Tolerances(
        rtol=rtol,
        atol=atol,
        step=step,
        max_nfev=max_nfev,
        max_wall_time=max_wall_time,
        energy_tol=math.inf if energy_tol is None else energy_tol,
    )
    h = check_step(meth.info, tol)
    if device == "cuda":
        from flatbody_env.integrators import cuda

        cuda.require()  # CudaUnavailableError naming the fix, before any work

    from flatbody_env.integrators import batch_solve as bs
    from flatbody_env.integrators.compiled_methods import _check_compiled_body, _check_fixed_budget, kernel_params
    from flatbody_env.integrators.twopolar_kernels import carry_size

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
        scale = energy_tol_scale(tol.rtol, tol.atol, adaptive=spec.info.adaptive)
        etol = scale * np.maximum(1.0, np.abs(H0))
    else:
        etol = np.full(n, tol.energy_tol)
    u = np.zeros(4)
    extra: dict[str, Any] = {}
    budget = WallClockBudget.of(tol, growth=GPU_GROWTH if device == "cuda" else math.inf)
    fixed_total = (
        n * spec.stages * float(np.sum(np.maximum(np.ceil(np.diff(grid) / h - 1e-9), 1.0))) if h else 0.0
    )  # fixed steps: the batch's evaluations, known up front
    probe_span = np.array([grid[0], grid[0] + min(256 * h, grid[-1] - grid[0])])  # fixed steps: a few hundred
    start = time.perf_counter()
    if grid.size == 1:  # only t = 0 asked for: the initial states
        OUT, STATUS = Y0[:, None, :].copy(), np.zeros(n, np.int64)
        NFEV, TFAIL = np.zeros(n, np.int64), np.full(n, np.nan)
    elif device == "cpu":
        OUT = np.empty((n, grid.size, STATE_SIZE))
        STATUS = np.zeros(n, np.int64)
        NFEV = np.zeros(n, np.int64)
        TFAIL = np.empty(n)

        def run(m: int, limit: int, span=grid, CARRY=None) -> None:  # the first m bodies through ``span``
            bs.batch_solve(
                kind,
                coeffs,
                Y0[:m],
                span,
                u,
                P,
                h,
                tol.rtol,
                tol.atol,
                etol[:m],
                limit,
                OUT[:m, : span.size],
                STATUS[:m],
                NFEV[:m],
                TFAIL[:m],
                None if CARRY is None else CARRY[:m],
            )

        if spec.info.adaptive:
            CARRY = np.zeros((n, carry_size()))
            todo = {"first": _probe_bodies(n), "pending": n}

            def advance(limit: int) -> tuple[int, int]:  # the probe: the first bodies; then every unfinished one
                m = todo["first"]
                ran = m if m < n else todo["pending"]
                todo["first"] = n
                run(m, limit, grid, CARRY)
                todo["pending"] = int(np.count_nonzero(STATUS[:m] == BUDGET)) + (n - m)
                return ran, todo["pending"]

            budget.run(advance)
        else:
            m = _probe_bodies(n)

            def probe() -> int:
                run(m, tol.max_nfev, probe_span)
                return int(NFEV[:m].sum())

            budget.refuse_fixed(probe, fixed_total, t=float(grid[0]), method=method, what=f" of {n} bodies")
            run(n, tol.max_nfev)
    else:
        launches = [0]
        if spec.info.adaptive:
            series = cuda.Trajectories(method, Y0, grid, u, P, h=h, rtol=tol.rtol, atol=tol.atol, energy_tol=etol)
            todo = {"pending": n}

            def advance(limit: int) -> tuple[int, int]:  # a launch of every body, the unfinished ones go on
                ran = todo["pending"]
                todo["pending"] = int(np.count_nonzero(series.launch(limit) == BUDGET))
                launches[0] += 1
                return ran, todo["pending"]

            budget.run(advance)
        else:

            def probe() -> int:  # every body (they run at once)
                _, _, nf, _ = cuda.solve(
                    method, Y0, probe_span, u, P, h=h, rtol=tol.rtol, atol=tol.atol, energy_tol=etol,
                    max_nfev=tol.max_nfev,
                )  # fmt: skip
                launches[0] += 1
                return int(nf.sum())

            budget.refuse_fixed(probe, fixed_total, t=float(grid[0]), method=method, what=f" of {n} bodies")
            series = cuda.Trajectories(method, Y0, grid, u, P, h=h, rtol=tol.rtol, atol=tol.atol, energy_tol=etol)
            series.launch(tol.max_nfev)
            launches[0] += 1
        OUT, STATUS, NFEV, TFAIL = series.result()
        extra["launches"] = launches[0]
    wall = time.perf_counter() - start
    keep = slice(1, None) if prepended else slice(None)
    return BatchTrajectory(
        t=times_arr.copy(),
        state=OUT[:, keep],
        status=STATUS,
        nfev=NFEV,
        t_fail=TFAIL,
        y0=Y0,
        method=method,
        device=device,
        wall_time=wall,
        extra=extra,
    )


def _probe_bodies(n: int) -> int:
    """Bodies of the CPU's timing probe: enough chunks to keep every thread of the parallel kernel busy."""
    import numba

    from flatbody_env.integrators.batch_solve import CHUNK

    return min(n, CHUNK * max(1, numba.get_num_threads()))


__all__ = ["BATCH_METHODS", "BatchTrajectory", "DEVICES", "MAX_BODIES", "MAX_OUTPUT_FLOATS", "simulate_batch"]
