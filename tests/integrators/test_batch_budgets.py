"""Budgets of the compiled integrators that had none: the batched DOP853 env steps (a budget of RHS
evaluations per body and step, as the scalar env step) and the ladder's compiled DOP853 (max_nfev and
max_wall_time). A tiny budget stops the run with the ``budget`` failure; an ample one changes nothing,
bit for bit."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import random_lanes

from flatbody_env.integrators import IntegrationError, Tolerances
from flatbody_env.integrators import batch_solve as bs
from flatbody_env.integrators.batch_kernels import FUSED_MAX_NFEV, DOP853Batch
from flatbody_env.integrators.compiled_methods import env_stepper, kernel_params
from flatbody_env.integrators.failure import KINDS
from flatbody_env.integrators.steppers import make_env_step
from flatbody_env.physics import validation
from flatbody_env.physics.body import default_body
from flatbody_env.physics.state import STATE_NAMES
from flatbody_env.simulation import simulate

BUDGET = KINDS.index("budget")
DT = 0.5
TINY = 500
"""A budget per body and step that the fast lanes exceed (they need ~1 000–4 000 evaluations) and the others keep."""


def _lanes(n=40, seed=3):
    Y, U = random_lanes(n, seed)
    Y[4:7, :8] *= 60.0  # fast lanes: many steps in one env step
    return np.ascontiguousarray(Y), np.ascontiguousarray(U)


def _scalar(Y, U, P, h, max_nfev):
    """Each body by the scalar env step with the budget in counters[3] (as the env steps one body)."""
    st = env_stepper("DOP853-numba")
    n = Y.shape[1]
    OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
    for k in range(n):
        counters = np.array([0, 0, 0, max_nfev], np.int64)
        out = np.empty(11)
        S[k] = st.step_counted(Y[:, k].copy(), U[:, k].copy(), P, DT, h, 1e-11, 1e-11, np.inf, out, counters)
        NF[k] = counters[0]
        OUT[:, k] = out
    return OUT, S, NF


def _batch(kernel, Y, U, P, h, *budget):
    n = Y.shape[1]
    OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
    kind, coeffs = bs.KIND["DOP853-numba"]
    kernel(kind, coeffs, Y, U, P, DT, h, 1e-11, 1e-11, np.inf, OUT, S, NF, *budget)
    return OUT, S, NF


def _fused(Y, U, P, *budget):
    n = Y.shape[1]
    OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
    DOP853Batch(n)(Y, U, P, DT, 1e-11, 1e-11, np.inf, OUT, S, NF, *budget)
    return OUT, S, NF


def _same(a, b):
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


def test_batch_env_step_stops_each_body_at_its_budget():
    """The env's batch step (its parallel twin of the GPU benchmark: tests/bench/test_kernels.py)."""
    kernel = bs.batch_env_step_serial
    P = kernel_params(default_body())
    Y, U = _lanes()
    tiny = _batch(kernel, Y, U, P, 0.0, TINY)
    _same(tiny, _scalar(Y, U, P, 0.0, TINY))  # the scalar env step's outcome, body by body
    assert (tiny[1] == BUDGET).sum() >= 5 and (tiny[1] == 0).sum() >= 20
    assert tiny[2].max() <= TINY + 13  # checked before every step
    free = _batch(kernel, Y, U, P, 0.0)
    assert free[2].max() > TINY and not (free[1] == BUDGET).any()
    _same(_batch(kernel, Y, U, P, 0.0, validation.ENV_STEP_MAX_NFEV), free)  # an ample budget: bit for bit


def test_fused_batch_step_honours_the_budget_bit_for_bit():
    P = kernel_params(default_body())
    Y, U = _lanes()
    free = _fused(Y, U, P)
    _same(_fused(Y, U, P, validation.ENV_STEP_MAX_NFEV), free)  # an ample budget: bit for bit
    _same(free, _scalar(Y, U, P, DT, 10**12))
    # the least budget that keeps the fused path: lanes handed to the scalar kernel run with it from their start
    least = _fused(Y, U, P, FUSED_MAX_NFEV)
    _same(least, _scalar(Y, U, P, DT, FUSED_MAX_NFEV))
    assert (least[1] == BUDGET).any() and (least[1] == 0).sum() >= 20
    tiny = _fused(Y, U, P, TINY)
    _same(tiny, _scalar(Y, U, P, DT, TINY))
    assert (tiny[1] == BUDGET).sum() >= 5 and TINY < FUSED_MAX_NFEV


def test_env_stepper_batch_carries_the_tolerances_budget():
    """The vector env's path (make_env_step(...).advance_batch): the budget of its Tolerances per body."""
    body = default_body()
    Y, U = _lanes()
    n = Y.shape[1]
    for first_step in (0.0, DT):  # the scalar batch kernel and the fused one
        step = make_env_step(
            "DOP853-numba", body, Tolerances(rtol=1e-11, atol=1e-11, max_nfev=TINY), first_step=first_step
        )
        OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
        step.advance_batch(Y, U, DT, OUT, S, NF)
        _same((OUT, S, NF), _scalar(Y, U, kernel_params(body), first_step, TINY))
        assert (S == BUDGET).any() and step.describe(BUDGET).startswith("budget")


# --------------------------------------------------------------------------------------------- the ladder
def _planar_kernel_directly(t_end):
    """The planar rung's two kernels called as before the budgets (no budget entry in counters)."""
    from flatbody_env.integrators import ladder
    from flatbody_env.integrators import ladder_kernels as lk
    from flatbody_env.scene import load_scene

    scene = load_scene("planar-v3")
    y0 = np.array([scene.state[k] for k in STATE_NAMES])
    times = np.linspace(0.0, t_end, 201)
    P = kernel_params(scene.body)
    u = np.zeros(4)
    x0 = np.array([y0[7], y0[8], y0[4], y0[5], y0[10], 0.0])
    X = np.empty((6, times.size))
    c = np.zeros(3, np.int64)
    st = lk.dop853_inplane(x0, times, ladder._template(y0), u, P, 1e-10, 1e-10, bool(y0[2] != y0[3]), X, c, np.zeros(1))
    assert st == 0
    return times, X


def test_ladder_planar_ample_budget_is_bit_for_bit_the_kernels_result():
    times, X = _planar_kernel_directly(200.0)
    run = simulate(
        "planar-v3", times=times, t_end=200.0, model="planar", rtol=1e-10, atol=1e-10
    )  # probes, then the run
    assert run.model == "planar"
    np.testing.assert_array_equal(run.state["lambda"], X[0])
    np.testing.assert_array_equal(run.state["theta"], X[4])
    again = simulate(
        "planar-v3",
        times=times,
        t_end=200.0,
        model="planar",
        rtol=1e-10,
        atol=1e-10,
        max_nfev=10**12,
        max_wall_time=86400,
    )
    np.testing.assert_array_equal(again.y, run.y)


@pytest.mark.parametrize(
    "budget, words", [({"max_nfev": 1000}, "max_nfev = 1000"), ({"max_wall_time": 0.5}, "(the wall-clock budget)")]
)
def test_ladder_planar_stops_at_its_budget(budget, words):
    with pytest.raises(IntegrationError) as info:
        simulate("planar-v3", t_end=1e6, model="planar", **budget)
    exc = info.value
    assert exc.kind == "budget" and words in str(exc) and 0.0 < exc.t < 1e6


def test_ladder_wall_time_budget_stops_the_cli_at_once():
    """A hostile run (t = 1e6 on the planar rung, ~5 min of work before) with a 1 s budget: one line, exit 1."""
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "flatbody_env.cli",
            "simulate",
            "--scene",
            "planar-v3",
            "--t-end",
            "1e6",
            "--model",
            "planar",
            "--max-seconds",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )  # hang guard
    assert r.returncode == 1, r.stderr[-2000:]
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr and "(the wall-clock budget)" in lines[0], r.stderr


# --------------------------------------------------------------------------------------------- simulate_batch
def _batch_states(n, seed=1):
    from flatbody_env.scene import load_scene

    scene = load_scene("default")
    y = np.array([scene.state[k] for k in STATE_NAMES])
    rng = np.random.default_rng(seed)
    Y0 = np.repeat(y[None, :], n, axis=0)
    Y0[:, 4:7] += rng.uniform(-0.05, 0.05, (n, 3))
    return scene.body, Y0


def test_simulate_batch_stops_at_its_wall_time():
    """A hostile batch (64 bodies to t = 1e5: ~90 s of work on 2 cores) with a 0.5 s budget: back at once, every
    unfinished body with the budget status, none silently NaN without a status."""
    from flatbody_env.batch import simulate_batch

    body, Y0 = _batch_states(64)
    bt = simulate_batch(body, Y0, times=[1e5], method="DOP853-numba", max_wall_time=0.5)
    assert set(bt.kinds) == {"budget"}
    assert np.isnan(bt.state).all() and np.isfinite(bt.t_fail).all() and (bt.t_fail < 1e5).all()
    assert bt.wall_time < 30.0  # a hang guard (measured ~1 s with loading the kernel), not a timing


def test_simulate_batch_ample_wall_time_is_bit_for_bit():
    """Bodies that need more evaluations than the probe allows (11 000–17 000 each): the probes, then the run with
    the budget from the measured rate; equal, bit for bit, to one plain call of the kernel."""
    from flatbody_env.batch import simulate_batch
    from flatbody_env.integrators.budget import PROBE_NFEV
    from flatbody_env.integrators import batch_solve as bs
    from flatbody_env.integrators.compiled_methods import kernel_params

    body, Y0 = _batch_states(100)
    times = np.linspace(1.0, 200.0, 50)
    a = simulate_batch(
        body, Y0, times=times, method="DOP853-numba", energy_tol=1.0, max_nfev=10**9, max_wall_time=86_400
    )
    assert a.kinds == ["ok"] * 100 and a.nfev.min() > PROBE_NFEV
    kind, coeffs = bs.KIND["DOP853-numba"]
    grid = np.concatenate([[0.0], times])
    OUT, ST, NF, TF = np.empty((100, grid.size, 11)), np.zeros(100, np.int64), np.zeros(100, np.int64), np.empty(100)
    bs.batch_solve(
        kind,
        coeffs,
        Y0,
        grid,
        np.zeros(4),
        kernel_params(body),
        0.0,
        1e-10,
        1e-10,
        np.full(100, 1.0),
        10**9,
        OUT,
        ST,
        NF,
        TF,
    )
    np.testing.assert_array_equal(a.state, OUT[:, 1:])
    np.testing.assert_array_equal(a.nfev, NF)


def test_simulate_batch_fixed_step_over_its_wall_time_is_refused_up_front():
    from flatbody_env.batch import simulate_batch

    body, Y0 = _batch_states(64)
    with pytest.raises(IntegrationError) as info:
        simulate_batch(body, Y0, times=[1e4], method="RK4", step=0.01, max_wall_time=0.5)
    assert info.value.kind == "budget" and "predicted" in str(info.value)
    with pytest.raises(ValueError, match=r"^max_wall_time: must lie in \(0, 86400\], got 1000000000\.0$"):
        simulate_batch(body, Y0, times=[1.0], method="RK4", step=0.01, max_wall_time=1e9)
