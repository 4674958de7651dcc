"""One wall-clock budget (:class:`flatbody_env.integrators.budget.WallClockBudget`) for the compiled DOP853: a run its
budget of evaluations stops keeps where it stands, and the next piece continues from there — bit for bit one call, and
nothing integrated twice. No timing is asserted: the clock only decides how the run is cut into pieces."""

from __future__ import annotations

import time

import numpy as np
import pytest

from flatbody_env.integrators import twopolar_kernels as tk
from flatbody_env.integrators.budget import PROBE_NFEV, STEP_NFEV, WallClockBudget
from flatbody_env.integrators.compiled_methods import kernel_params
from flatbody_env.integrators.failure import BUDGET, OK
from flatbody_env.physics.state import pack
from flatbody_env.scene import load_scene
from flatbody_env.simulation import simulate

GRID = np.linspace(0.0, 100.0, 101)
PIECES = {
    "one probe": [PROBE_NFEV],
    "a step at a time": [STEP_NFEV * k for k in range(1, 40)],
    "ragged": list(range(100, 20_000, 77)),
}


def _scene():
    sc = load_scene("planar-v3")
    return pack(sc.state), kernel_params(sc.body)


def _one_call(solve, y0, P, n):
    Z, counters, fail = np.empty((n, GRID.size)), np.array([0, 0, 0, 10**9], np.int64), np.zeros(2)
    st = solve(y0, GRID, np.zeros(4), P, 1e-10, 1e-10, 1.0, Z, counters, fail)
    return st, Z, counters, fail


def _in_pieces(solve, y0, P, n, limits):
    """The same run cut at ``limits`` evaluations, each call continuing the last; also how many stops came right after
    a rejected attempt and the evaluations each call made."""
    Z, counters, fail = np.empty((n, GRID.size)), np.zeros(4, np.int64), np.zeros(2)
    carry = np.zeros(tk.carry_size(n))
    after_rejection, made = 0, []
    for limit in [*limits, 10**9]:
        before = int(counters[0])
        counters[3] = limit
        st = solve(y0, GRID, np.zeros(4), P, 1e-10, 1e-10, 1.0, Z, counters, fail, carry)
        made.append(int(counters[0]) - before)
        if st != BUDGET:
            break
        after_rejection += carry[tk.CARRY_REJECTED] == 1.0
    return st, Z, counters, fail, after_rejection, made


@pytest.mark.parametrize("pieces", list(PIECES.values()), ids=list(PIECES))
@pytest.mark.parametrize("with_rotation", [False, True], ids=["paper", "with R"])
def test_a_run_continued_in_pieces_is_bit_for_bit_one_call(pieces, with_rotation):
    y0, P = _scene()
    if with_rotation:
        from flatbody_env.integrators.rotation_kernels import dop853_solve_R as solve

        y0 = np.concatenate([y0, np.eye(3).ravel()])
    else:
        solve = tk.dop853_solve
    st, Z, counters, fail = _one_call(solve, y0, P, y0.size)
    assert st == OK and counters[0] > 2 * PROBE_NFEV and counters[2] > 0  # long enough, with rejected steps
    st2, Z2, counters2, fail2, after_rejection, made = _in_pieces(solve, y0, P, y0.size, pieces)
    assert st2 == OK
    np.testing.assert_array_equal(Z2, Z)
    np.testing.assert_array_equal(counters2[:3], counters[:3])
    np.testing.assert_array_equal(fail2, fail)
    assert sum(made) == counters[0]  # nothing integrated twice
    if len(pieces) > 30:
        assert after_rejection > 0  # some stops fell between a rejected attempt and its retry


def test_the_ladder_kernels_continue_bit_for_bit():
    from flatbody_env.integrators import ladder, ladder_kernels as lk

    sc = load_scene("planar-v3")
    y0, P = _scene()
    x0 = np.array([y0[7], y0[8], y0[4], y0[5], y0[10], 0.0])
    args = (ladder._template(y0), np.zeros(4), P, 1e-10, 1e-10, bool(y0[2] != y0[3]))
    X, c = np.empty((6, GRID.size)), np.zeros(3, np.int64)
    assert lk.dop853_inplane(x0, GRID, *args, X, c, np.zeros(1)) == OK and sc.body.inertia.is_isotropic
    X2, c2, fail, carry = np.empty((6, GRID.size)), np.zeros(4, np.int64), np.zeros(1), np.zeros(tk.carry_size(6))
    for limit in [*range(50, int(c[0]), 131), 10**9]:
        c2[3] = limit
        st = lk.dop853_inplane(x0, GRID, *args, X2, c2, fail, carry)
        if st != BUDGET:
            break
    assert st == OK
    np.testing.assert_array_equal(X2, X)
    np.testing.assert_array_equal(c2[:3], c)


def test_the_cpu_batch_continues_each_body_bit_for_bit():
    from flatbody_env.integrators import batch_solve as bs

    y0, P = _scene()
    rng = np.random.default_rng(5)
    Y0 = np.repeat(y0[None], 70, axis=0)
    Y0[:, 4:7] += rng.uniform(-0.05, 0.05, (70, 3))
    kind, coeffs = bs.KIND["DOP853-numba"]
    etol = np.full(70, 1.0)

    def arrays():
        return np.empty((70, GRID.size, 11)), np.zeros(70, np.int64), np.zeros(70, np.int64), np.empty(70)

    OUT, ST, NF, TF = arrays()
    bs.batch_solve(kind, coeffs, Y0, GRID, np.zeros(4), P, 0.0, 1e-10, 1e-10, etol, 10**9, OUT, ST, NF, TF)
    OUT2, ST2, NF2, TF2 = arrays()
    CARRY = np.zeros((70, tk.carry_size()))
    for m, limit in [(20, 3000), (20, 6000), (70, 9000), (70, 10**9)]:  # a probe on the first bodies, then all
        bs.batch_solve(
            kind, coeffs, Y0[:m], GRID, np.zeros(4), P, 0.0, 1e-10, 1e-10, etol[:m], limit, OUT2[:m], ST2[:m],
            NF2[:m], TF2[:m], CARRY[:m],
        )  # fmt: skip
    assert (ST == OK).all() and NF.min() > 9000
    for a, b in ((OUT, OUT2), (ST, ST2), (NF, NF2), (TF, TF2)):
        np.testing.assert_array_equal(a, b)


def test_compiled_simulate_runs_the_kernel_once_over(monkeypatch):
    """A compiled simulate longer than the probe: the answer of one kernel call, and the pieces' evaluations add up to
    the run's (the probe's work is continued, not repeated)."""
    sc = load_scene("planar-v3")
    y0, P = _scene()
    made = []
    solve = tk.dop853_solve

    def counting(*args):
        counters = args[8]
        before = int(counters[0])
        st = solve(*args)
        made.append(int(counters[0]) - before)
        return st

    monkeypatch.setattr(tk, "dop853_solve", counting)
    run = simulate(sc, t_end=100.0, method="DOP853-numba", model="two-polar", energy_tol=1.0)
    monkeypatch.undo()
    st, Z, counters, _ = _one_call(solve, y0, P, 11)
    assert st == OK and len(made) >= 2 and sum(made) == run.nfev == counters[0]
    np.testing.assert_array_equal(run.y, Z)


class _Run:
    """A stand-in run of ``need`` evaluations that costs ``seconds_per_eval`` of wall time (sleeps)."""

    def __init__(self, need, seconds_per_eval=0.0):
        self.need, self.spe, self.done, self.limits = need, seconds_per_eval, 0, []

    def __call__(self, limit):
        self.limits.append(limit)
        work = min(limit, self.need) - self.done
        if self.spe:
            time.sleep(work * self.spe)
        self.done += work
        return 1, int(self.done < self.need)


def test_budget_pieces_rise_to_max_nfev_and_stop_there():
    run = _Run(need=10**6)
    assert WallClockBudget(max_nfev=50_000, max_wall_time=3600.0).run(run) is False  # max_nfev, not the clock
    assert run.limits[0] == PROBE_NFEV and run.limits[-1] == 50_000 and run.done == 50_000
    assert all(b - a >= STEP_NFEV for a, b in zip(run.limits, run.limits[1:], strict=False))
    small = _Run(need=10**6)
    WallClockBudget(max_nfev=2 * PROBE_NFEV, max_wall_time=3600.0).run(small)
    assert small.limits == [2 * PROBE_NFEV]  # a budget within two probes: one call


def test_budget_a_run_that_fits_ends_in_its_pieces():
    run = _Run(need=12_345)
    assert WallClockBudget(max_nfev=10**7, max_wall_time=3600.0).run(run) is False
    assert run.done == 12_345 and len(run.limits) <= 3


def test_budget_the_clock_ends_a_run_that_does_not_fit():
    """1e-5 s per evaluation, 10^9 needed (~3 h) in 0.3 s: stopped by the clock after a fraction of the work."""
    run = _Run(need=10**9, seconds_per_eval=1e-5)
    start = time.perf_counter()
    assert WallClockBudget(max_nfev=10**9, max_wall_time=0.3).run(run) is True
    assert run.done < 10**7 and time.perf_counter() - start < 60.0  # a hang guard, not a timing


def test_budget_growth_caps_each_piece():
    run = _Run(need=10**8)
    WallClockBudget(max_nfev=10**8, max_wall_time=3600.0, growth=8).run(run)
    pieces = np.diff([0, *run.limits])
    assert run.done == 10**8 and all(b <= 8 * a for a, b in zip(pieces, pieces[1:], strict=False))
