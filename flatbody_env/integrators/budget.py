"""The work budget of a compiled run, ``max_nfev`` evaluations and ``max_wall_time`` seconds: :class:`WallClockBudget`.

A compiled kernel cannot read the clock. It counts its right-hand-side evaluations and stops once a body has used its
budget of them (checked before every step), keeping where it stands, so that a call with a larger budget *continues*
from there (:func:`~.twopolar_kernels.dop853_solve_into`'s ``carry``, and the ladder's systems,
:mod:`.ladder_kernels`). The wall clock is read between calls: :meth:`WallClockBudget.run` integrates in pieces of
rising budgets — a short probe of :data:`PROBE_NFEV` evaluations first (a second one when the first was slow enough
to have included loading the kernel), each later piece sized to what the time left allows at the rate the last piece
measured, at most ``max_nfev`` in all and, on the GPU, at most :data:`GPU_GROWTH` times the last piece. Nothing is
integrated twice, and a body that finishes is bit for bit that of one call with the final budget. It serves the
compiled DOP853 (``simulate``), the ladder's rungs, the CPU batch and the GPU launch series (``simulate_batch``).

Fixed-step methods know their work before they start: :meth:`WallClockBudget.refuse_fixed` times a few hundred steps
and refuses (``IntegrationError``, ``kind="budget"``) a run whose predicted time exceeds ``max_wall_time``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from flatbody_env.integrators.base import Tolerances, budget_error

PROBE_NFEV = 5_000
"""Evaluations per body of the first piece, the timing probe (short against any budget when compiled)."""
COMPILED_RATE = 2e5
"""Evaluations per second (of one body) below which the probe is taken to have included loading the kernel (compiled
kernels run far faster: the per-step costs of ``flatbody bench integrators``), so a second probe measures the rate."""
STEP_NFEV = 13
"""The least piece worth running: one DOP853 step (12 evaluations) past where a body stopped."""
GPU_GROWTH = 8
"""On the GPU, how many times the last piece's evaluations one piece may be given (a launch's time is the slowest
body's: a rate measured on one launch is not stretched further than this)."""


@dataclass(frozen=True, kw_only=True)
class WallClockBudget:
    """``max_nfev`` evaluations per body and ``max_wall_time`` seconds for a run of compiled pieces (module docstring).

    Attributes
    ----------
    max_nfev : int
        Right-hand-side evaluations per body, in all.
    max_wall_time : float
        Seconds for the whole run, from the first piece on.
    growth : float
        At most this many times the last piece's evaluations in one piece (``inf`` on the CPU; :data:`GPU_GROWTH`).
    """

    max_nfev: int
    max_wall_time: float
    growth: float = math.inf

    @classmethod
    def of(cls, tol: Tolerances, *, growth: float = math.inf) -> WallClockBudget:
        """The budget of ``tol`` (its ``max_nfev`` and ``max_wall_time``)."""
        return cls(max_nfev=int(tol.max_nfev), max_wall_time=float(tol.max_wall_time), growth=growth)

    def run(self, advance: Callable[[int], tuple[int, int]]) -> bool:
        """Integrate in pieces within both budgets.

        Parameters
        ----------
        advance : callable
            ``advance(limit) -> (ran, pending)`` continues the run until every unfinished body has used ``limit``
            evaluations in all (or has finished); ``ran``: the bodies it worked on, ``pending``: the bodies still
            stopped by their budget or not yet started. Limits only rise; each exceeds the last by at least
            :data:`STEP_NFEV`, except the last one, which is ``max_nfev``.

        Returns
        -------
        bool
            Whether the wall clock, not ``max_nfev``, ended the run with bodies unfinished.
        """
        start = time.perf_counter()
        limit = self.max_nfev if self.max_nfev <= 2 * PROBE_NFEV else PROBE_NFEV
        last = 0  # the previous limit
        probes = 0
        while True:
            t0 = time.perf_counter()
            ran, pending = advance(limit)
            now = time.perf_counter()
            if pending == 0 or limit >= self.max_nfev:
                return False
            piece, took = limit - last, max(now - t0, 1e-9)
            last = limit
            left = self.max_wall_time - (now - start)
            probes += 1
            if probes == 1 and piece / took < COMPILED_RATE:  # the probe may have loaded the kernel: measure again
                if left <= 0.0:
                    return True
                limit += PROBE_NFEV
                continue
            per_eval = took / piece * max(1.0, pending / max(ran, 1))  # seconds per evaluation of the next piece
            by_time = left / per_eval
            if by_time < STEP_NFEV:
                return True
            limit += max(1, int(min(self.max_nfev - limit, self.growth * piece, by_time)))

    def refuse_fixed(
        self, probe: Callable[[], int], total_nfev: float, *, t: float, method: str, what: str = ""
    ) -> None:
        """Refuse a fixed-step run whose predicted time exceeds ``max_wall_time`` (``IntegrationError``,
        ``kind="budget"``, before it starts). ``probe()`` integrates a few hundred steps and returns the evaluations it
        made (run twice, the second timed: the first may load the kernel); ``total_nfev``: the evaluations of the whole
        run; ``t``: its start; ``what``: words after the prediction (e.g. ``" of 64 bodies"``). A run of at most
        4 :data:`PROBE_NFEV` evaluations is never probed."""
        if total_nfev <= 4 * PROBE_NFEV:
            return
        probe()
        t0 = time.perf_counter()
        made = max(1, int(probe()))
        predicted = total_nfev * (time.perf_counter() - t0) / made
        if predicted > self.max_wall_time:
            raise budget_error(
                t=t,
                method=method,
                tol=self,
                used=f"~{predicted:.3g} s predicted for {total_nfev:.6g} RHS evaluations{what}",
            )


__all__ = ["COMPILED_RATE", "GPU_GROWTH", "PROBE_NFEV", "STEP_NFEV", "WallClockBudget"]
