"""``flatbody bench integrators``: same-run speed and accuracy figures of the integrators.

Not a timed test: it prints figures and writes them to JSON/CSV (+ PNG). Everything is measured
side by side in one process (ratios are the reliable part on a shared machine; the figures: the
tables of docs/integrators.md).

1. *regular* scene, t = 100: wall time (min of repeats) of each method against its final-state
   error; the wall time at the target error (1e-9) by log-log interpolation between the two
   bracketing settings; speed-up = scipy ``solve_ivp`` DOP853's time / the method's time at that
   error. Also DOP853-numba against scipy at the *same* rtol (identical steps).
2. *close approach* (σ₋ = 1e-3, the built-in scene, and σ₋ = 1e-6, 1e-9), t = 20: wall time at equal
   error (1e-8) of the regular-chart RATTLE methods and of every two-polar method; ratio = the
   cheapest two-polar time / the cheapest regular-chart time (methods that fail are left out).
3. *long horizon*, t = 1e4: the energy error max|H − H₀| (101 samples) per method/setting.
4. *one short step* dt = 0.05: µs per call through ``integrate`` (four scipy methods and every compiled one) and
   through the compiled environment stepper (the methods the environment steps compiled; single and batched over
   1024 bodies), best of repeated blocks (:func:`flatbody_env.bench.harness.best_of`).
5. *compile time*: first call with an empty numba cache and the cached call, in fresh processes.
6. *simulate vs the kernel*: ``simulate`` of the planar scene to t = 100 with the compiled DOP853 (a run longer than
   the wall-clock budget's probe, :mod:`flatbody_env.integrators.budget`) against the bare kernel call of the same run
   and against the method's ``integrate``, timed in alternation (:func:`flatbody_env.bench.harness.alternate`).

:func:`measure` → :class:`BenchReport`; :func:`report` (of a run, or of the saved JSON: :func:`load`) hands it to
:func:`flatbody_env.bench.harness.write_report` (``bench_integrators.json``, ``.csv``, and ``.png`` drawn
from the saved JSON by :func:`analysis.integrator_plots.plot_bench`) with its tables (:func:`tables`): the terminal
shows them all, the ``<!-- bench:integrators-* -->`` blocks of a docs page get theirs.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass, field

import numpy as np

from analysis.failure_study import gap_scene
from flatbody_env.bench.harness import Report, Stopwatch, Table, alternate, best_of
from flatbody_env.integrators import IntegrationError, Tolerances, get_method
from flatbody_env.physics import validation
from flatbody_env.physics.hamiltonian import hamiltonian, hamiltonian_series
from flatbody_env.physics.state import pack
from flatbody_env.scene import load_scene

NAME = "bench_integrators"
"""The file stem of the saved figures."""

TARGET_REGULAR = 1e-9
TARGET_CLOSE = 1e-8
RTOLS = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)
STEPS = (0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625, 0.003125)
REGULAR_METHODS = (
    "DOP853",
    "DOP853-numba",
    "RK4",
    "splitting-suzuki4",
    "splitting-yoshida4",
    "RATTLE-suzuki4",
    "RATTLE-kahanli6",
)
CLOSE_METHODS = ("RATTLE-suzuki4", "RATTLE-kahanli6", "DOP853-numba", "DOP853", "RK4", "splitting-suzuki4")
LONG_RUNS = (
    ("DOP853", dict(rtol=1e-6, atol=1e-9)),
    ("DOP853-numba", dict(rtol=1e-6, atol=1e-9)),
    ("DOP853-numba", dict(rtol=1e-10, atol=1e-13)),
    ("RK4", dict(step=0.1)),
    ("splitting-strang", dict(step=0.05)),
    ("splitting-suzuki4", dict(step=0.1)),
    ("splitting-yoshida4", dict(step=0.1)),
    ("RATTLE-suzuki4", dict(step=0.1)),
)


@dataclass(frozen=True, kw_only=True)
class BenchReport:
    """All figures of one bench run (see the module docstring).

    Attributes
    ----------
    machine : dict
        Where it ran (:func:`flatbody_env.provenance.machine`), the platform and whether the run was quick.
    regular, close_approach, long_horizon, short_step, compile_times
        Sections 1–5.
    auto : list
        Per built-in scene: simulate's default (method="auto") against scipy DOP853 (the former default), same run.
    simulate_vs_kernel : dict
        Section 6: seconds of ``simulate``, of ``integrate`` and of the bare kernel call, and their ratios.
    """

    machine: dict
    regular: dict
    close_approach: list
    long_horizon: list
    short_step: list
    compile_times: list = field(default_factory=list)
    auto: list = field(default_factory=list)
    simulate_vs_kernel: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """The record as saved in ``bench_integrators.json``."""
        return asdict(self)


ENOUGH_S = 0.2
"""A setting's runs stop repeating once this much time went into them (a long run is timed once)."""


def _run(method, scene, times, tol):
    """(solution or None, wall time of the first run, status): the run that checks the method, timed once."""
    meth, y0 = get_method(method), pack(scene.state)
    with Stopwatch() as sw:
        try:
            sol = meth.integrate(scene.body, y0, times, tol=tol)
        except IntegrationError as exc:
            sol, status = None, exc.kind
        else:
            status = "ok"
    return sol, sw.seconds, status


def _curve(method, scene, t_end, ref, repeats, max_run_s):
    info = get_method(method).info
    settings = [("rtol", r) for r in RTOLS] if info.adaptive else [("step", h) for h in STEPS]
    out = []
    y0, times = pack(scene.state), np.array([0.0, t_end])
    for kind, v in settings:
        tol = Tolerances(rtol=v, atol=1e-3 * v) if kind == "rtol" else Tolerances(step=v)
        sol, wall, status = _run(method, scene, times, tol)  # the first run is the warm-up of the timed ones
        if sol is not None and repeats > 1 and wall < ENOUGH_S:
            meth = get_method(method)
            timed = best_of(
                lambda m=meth, t=tol: m.integrate(scene.body, y0, times, tol=t), repeats, warm=False, enough_s=ENOUGH_S
            )
            wall = min(wall, timed)
        err = float(np.max(np.abs(sol.Y[:, -1] - ref))) if sol is not None else math.nan
        out.append(
            {
                "setting": f"{kind}={v:g}",
                "error": err,
                "wall_time": wall,
                "nfev": sol.nfev if sol else 0,
                "status": status,
            }
        )
        if wall > max_run_s:
            break
    return out


def wall_at(curve, target):
    """Wall time at error ``target``: log-log interpolation between the bracketing settings (None if not bracketed)."""
    pts = [
        (c["error"], c["wall_time"])
        for c in curve
        if c["status"] == "ok" and c["error"] > 0 and math.isfinite(c["error"])
    ]
    pts.sort(key=lambda p: -p[0])
    best = None
    for (e1, w1), (e2, w2) in zip(pts, pts[1:], strict=False):
        if e1 >= target >= e2:
            if e1 == e2:
                w = min(w1, w2)
            else:
                s = (math.log(target) - math.log(e1)) / (math.log(e2) - math.log(e1))
                w = math.exp(math.log(w1) + s * (math.log(w2) - math.log(w1)))
            best = w if best is None else min(best, w)
    return best


def _reference(scene, t_end, method, kw, cross, cross_kw):
    y0 = pack(scene.state)
    ends = np.array([0.0, t_end])
    ref = get_method(method).integrate(scene.body, y0, ends, tol=Tolerances(**kw)).Y[:, -1]
    crs = get_method(cross).integrate(scene.body, y0, ends, tol=Tolerances(**cross_kw)).Y[:, -1]
    return ref, float(np.max(np.abs(ref - crs)))


def _regular(repeats, max_run_s, t_end, bar):
    sc = load_scene("regular")
    ref, floor = _reference(sc, t_end, "DOP853-numba", dict(rtol=1e-13, atol=1e-15), "RATTLE-suzuki4", dict(step=0.001))
    curves = {}
    for m in REGULAR_METHODS:
        bar.set_postfix_str(f"regular {m}")
        curves[m] = _curve(m, sc, t_end, ref, repeats, max_run_s)
        bar.update(1)
    w_ref = wall_at(curves["DOP853"], TARGET_REGULAR)
    at = []
    for m in REGULAR_METHODS:
        w = wall_at(curves[m], TARGET_REGULAR)
        at.append({"method": m, "wall_time": w, "speedup": (w_ref / w) if (w and w_ref) else None})
    same = []
    for a, b in zip(curves["DOP853"], curves["DOP853-numba"], strict=False):  # a sweep may stop early
        if a["status"] == "ok" and b["status"] == "ok":
            same.append(
                {
                    "setting": a["setting"],
                    "scipy_s": a["wall_time"],
                    "numba_s": b["wall_time"],
                    "ratio": a["wall_time"] / b["wall_time"],
                    "scipy_nfev": a["nfev"],
                    "numba_nfev": b["nfev"],
                    "scipy_error": a["error"],
                    "numba_error": b["error"],
                }
            )
    return {
        "t_end": t_end,
        "target_error": TARGET_REGULAR,
        "reference_floor": floor,
        "curves": curves,
        "at_target": at,
        "same_rtol": same,
    }


def _close(repeats, max_run_s, bar, deltas):
    out = []
    for delta in deltas:
        sc = gap_scene(delta)
        t_end = sc.t_end
        ref, floor = _reference(
            sc, t_end, "DOP853-regular", dict(rtol=1e-12, atol=1e-12), "RATTLE-suzuki4", dict(step=0.002)
        )
        curves = {}
        for m in CLOSE_METHODS:
            bar.set_postfix_str(f"close δ={delta:g} {m}")
            curves[m] = _curve(m, sc, t_end, ref, repeats, max_run_s)
            bar.update(1)
        at = [
            {"method": m, "wall_time": wall_at(curves[m], TARGET_CLOSE), "chart": get_method(m).info.chart}
            for m in CLOSE_METHODS
        ]
        regs = [(a["wall_time"], a["method"]) for a in at if a["chart"] == "regular" and a["wall_time"]]
        reg, reg_name = min(regs) if regs else (None, "")
        two = [a["wall_time"] for a in at if a["chart"] == "two-polar" and a["wall_time"]]
        out.append(
            {
                "delta": delta,
                "t_end": t_end,
                "target_error": TARGET_CLOSE,
                "reference_floor": floor,
                "curves": curves,
                "at_target": at,
                "cheapest_regular": reg_name,
                "regular_vs_cheapest_two_polar": (min(two) / reg) if (two and reg) else None,
                "two_polar_reaching_target": [a["method"] for a in at if a["chart"] == "two-polar" and a["wall_time"]],
            }
        )
    return out


def _long(bar, t_end):
    sc = load_scene("long-horizon")
    y0 = pack(sc.state)
    H0 = hamiltonian(y0, sc.body)
    times = np.linspace(0.0, t_end, 101)
    out = []
    for m, kw in LONG_RUNS:
        bar.set_postfix_str(f"long {m}")
        sol, wall, status = _run(m, sc, times, Tolerances(**kw))
        dH = float(np.max(np.abs(hamiltonian_series(sol.Y, sc.body) - H0))) if sol is not None else math.nan
        out.append(
            {
                "method": m,
                "setting": ", ".join(f"{k}={v:g}" for k, v in kw.items()),
                "t_end": t_end,
                "energy_error": dH,
                "energy_error_final": float(abs(hamiltonian_series(sol.Y[:, -1:], sc.body)[0] - H0))
                if sol is not None
                else math.nan,
                "wall_time": wall,
                "nfev": sol.nfev if sol is not None else 0,
                "status": status,
            }
        )
        bar.update(1)
    return out


def _short_step(bar, n_batch=1024):
    from flatbody_env.integrators.compiled_methods import ENV_METHODS, env_stepper, kernel_params
    from flatbody_env.integrators.specs import BY_NAME

    sc = load_scene("default")
    y = pack(sc.state)
    P = kernel_params(sc.body)
    u = np.zeros(4)
    dt = 0.05
    out = []
    times = np.array([0.0, dt])
    for m in ("RK45", "DOP853", "LSODA", "DOP853-regular", *BY_NAME):
        meth = get_method(m)
        tol = Tolerances(rtol=1e-8, atol=1e-10) if meth.info.adaptive else Tolerances(step=dt)
        n = 30 if not meth.info.compiled else 300

        def calls(meth=meth, tol=tol, n=n):
            for _ in range(n):
                meth.integrate(sc.body, y, times, tol=tol)

        best = best_of(calls, 3, warm=False) / n
        out.append({"method": m, "path": "integrate", "us_per_step": best * 1e6})
        bar.update(1)
    for m in ENV_METHODS:
        st = env_stepper(m)
        o = np.empty_like(y)
        h = 0.0 if not st.fixed_step else dt
        n = 20000

        def steps(st=st, o=o, h=h, n=n):
            for _ in range(n):
                st.step(y, u, P, dt, h, 1e-8, 1e-10, math.inf, o)

        best = best_of(steps, 3, warm=False) / n
        X = np.repeat(y[:, None], n_batch, axis=1)
        U = np.zeros((4, n_batch))
        OUT = np.empty_like(X)
        S = np.zeros(n_batch, np.int64)
        bbest = (
            best_of(lambda a=(X, U, P, dt, h, 1e-8, 1e-10, math.inf, OUT, S), st=st: st.batch(*a), 5, warm=False)
            / n_batch
        )
        out.append(
            {
                "method": m,
                "path": "env",
                "us_per_step": best * 1e6,
                "batch_us_per_body_step": bbest * 1e6,
                "batch_size": n_batch,
            }
        )
        bar.update(1)
    return out


SIMULATE_SCENE = "planar-v3"
SIMULATE_T_END = 100.0


def simulate_vs_kernel(rounds: int = 30) -> dict:
    """Section 6 (module docstring): ``simulate(SIMULATE_SCENE, t_end=100, method="DOP853-numba", model="two-polar")``
    against its method's ``integrate`` and the bare :func:`~flatbody_env.integrators.twopolar_kernels.dop853_solve`
    call of the same run (its arrays made beforehand), best of ``rounds`` alternated rounds."""
    from flatbody_env.bench.harness import alternate
    from flatbody_env.integrators import DEFAULT_MAX_NFEV
    from flatbody_env.integrators import twopolar_kernels as tk
    from flatbody_env.integrators.compiled_methods import kernel_params
    from flatbody_env.simulation import default_energy_tol, simulate

    sc = load_scene(SIMULATE_SCENE)
    kw = dict(t_end=SIMULATE_T_END, method="DOP853-numba", model="two-polar")
    run = simulate(sc, **kw)
    y0, P, grid, u = pack(sc.state), kernel_params(sc.body), run.t, np.zeros(4)
    etol = default_energy_tol(hamiltonian(y0, sc.body), 1e-10, 1e-10, adaptive=True)
    tol = Tolerances(rtol=1e-10, atol=1e-10, energy_tol=etol)
    meth = get_method("DOP853-numba")
    Z, counters, fail = np.empty((11, grid.size)), np.zeros(4, np.int64), np.zeros(2)

    def kernel() -> None:
        counters[:] = (0, 0, 0, DEFAULT_MAX_NFEV)
        tk.dop853_solve(y0, grid, u, P, 1e-10, 1e-10, etol, Z, counters, fail)

    kernel()
    if counters[0] != run.nfev or not np.array_equal(Z, run.y):
        raise RuntimeError("simulate and the bare kernel call do not compute the same run")

    def integrate() -> None:
        meth.integrate(sc.body, y0, grid, tol=tol)

    def simulate_run() -> None:
        simulate(sc, **kw)

    best = alternate({"kernel": kernel, "integrate": integrate, "simulate": simulate_run}, rounds)
    return {
        "scene": SIMULATE_SCENE,
        "t_end": SIMULATE_T_END,
        "method": "DOP853-numba",
        "nfev": int(run.nfev),
        "rounds": rounds,
        "kernel_s": best["kernel"],
        "integrate_s": best["integrate"],
        "simulate_s": best["simulate"],
        "integrate_over_kernel": best["integrate"] / best["kernel"],
        "simulate_over_kernel": best["simulate"] / best["kernel"],
    }


_COMPILE_SNIPPET = """
import time, json, sys
t0 = time.perf_counter()
from flatbody_env.integrators.compiled_methods import warm_up
t_import = time.perf_counter() - t0
out = {"import_s": t_import}
for name in sys.argv[1:]:
    t0 = time.perf_counter()
    warm_up([name])
    out[name] = time.perf_counter() - t0
print(json.dumps(out))
"""


def compile_times(names=None) -> list[dict]:
    """First-call time with an empty numba cache and with the cache filled, each in a fresh process (default: every
    compiled method)."""
    from flatbody_env.integrators.specs import BY_NAME

    names = list(names or BY_NAME)
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as cache:
        env["NUMBA_CACHE_DIR"] = cache
        runs = []
        for _ in range(2):
            res = subprocess.run(
                [sys.executable, "-c", _COMPILE_SNIPPET, *names], env=env, capture_output=True, text=True, check=True
            )
            runs.append(json.loads(res.stdout.strip().splitlines()[-1]))
    cold, warm = runs
    return [{"method": n, "first_call_s": cold[n], "cached_s": warm[n]} for n in names] + [
        {"method": "(import)", "first_call_s": cold["import_s"], "cached_s": warm["import_s"]},
        {"method": "(all)", "first_call_s": sum(cold[n] for n in names), "cached_s": sum(warm[n] for n in names)},
    ]


def _auto(repeats: int, bar, t_cap: float) -> list[dict]:
    """``simulate(scene)`` (method="auto": the rung, then the fastest method meeting rtol = atol = 1e-10)
    against ``simulate(scene, method="DOP853")`` on every built-in scene, t = min(t_end, t_cap), timed in
    alternation (:func:`~flatbody_env.bench.harness.alternate`)."""
    from flatbody_env.scene import builtin_scenes
    from flatbody_env.simulation import simulate

    rows = []
    for name, sc in sorted(builtin_scenes().items()):
        t_end = min(sc.t_end, t_cap)
        auto = simulate(sc, t_end=t_end)  # compiled kernels loaded; what auto runs
        row = {
            "scene": name,
            "t_end": t_end,
            "method": auto.method,
            "model": auto.model,
            "reason": auto.extra.get("method_reason", ""),
            "auto_step": auto.extra.get("auto_step"),
        }
        try:
            ref = simulate(sc, t_end=t_end, method="DOP853")
        except IntegrationError as exc:
            row["auto_s"] = best_of(lambda sc=sc, t=t_end: simulate(sc, t_end=t), repeats, warm=False)
            row.update(scipy_method="DOP853", scipy_s=None, speedup=None, max_difference=None, scipy_failure=exc.kind)
        else:
            best = alternate(
                {
                    "auto": lambda sc=sc, t=t_end: simulate(sc, t_end=t) and None,
                    "scipy": lambda sc=sc, t=t_end: simulate(sc, t_end=t, method="DOP853") and None,
                },
                repeats,
                warm=False,
            )
            row["auto_s"] = best["auto"]
            row.update(
                scipy_method=ref.method,
                scipy_model=ref.model,
                scipy_s=best["scipy"],
                speedup=best["scipy"] / max(best["auto"], 1e-9),
                max_difference=float(np.max(np.abs(auto.y - ref.y))),
            )
        rows.append(row)
        bar.update(1)
    return rows


def measure(
    *, quick: bool = False, repeats: int = 3, max_run_s: float = 5.0, progress: bool = True, with_compile: bool = True
) -> BenchReport:
    """Run sections 1–5 (see the module docstring) in one process.

    Parameters
    ----------
    quick : bool
        Shorter horizons, one close-approach case, 1 repeat.
    repeats : int
        Timing repeats (the minimum is taken).
    max_run_s : float
        Stop a method's sweep once one run takes longer.
    progress : bool
        Show a progress bar on stderr.
    with_compile : bool
        Also measure the compile times (two fresh processes).
    """
    import platform

    from flatbody_env.integrators.compiled_methods import ENV_METHODS, warm_up
    from flatbody_env.integrators.specs import BY_NAME
    from flatbody_env.progress import progress_bar
    from flatbody_env.provenance import machine
    from flatbody_env.scene import builtin_scenes

    warm_up()  # compile time is measured separately (in fresh processes)
    deltas = (1e-3,) if quick else (1e-3, 1e-6, 1e-9)
    total = (
        len(REGULAR_METHODS)
        + len(deltas) * len(CLOSE_METHODS)
        + len(LONG_RUNS)
        + 4
        + len(BY_NAME)
        + len(ENV_METHODS)
        + len(builtin_scenes())
        + 1
    )
    bar = progress_bar(total=total, desc="bench integrators", unit="task", enabled=progress)
    regular = _regular(1 if quick else repeats, max_run_s, 20.0 if quick else 100.0, bar)
    close = _close(1 if quick else repeats, max_run_s, bar, deltas)
    long_h = _long(bar, 1e3 if quick else 1e4)
    short = _short_step(bar)
    auto = _auto(1 if quick else repeats, bar, 20.0 if quick else 100.0)
    bar.set_postfix_str("simulate vs kernel")
    versus = simulate_vs_kernel(10 if quick else 10 * repeats)
    bar.update(1)
    bar.close()
    comp = compile_times() if with_compile else []
    return BenchReport(
        machine={**machine(), "platform": platform.platform(), "quick": quick},
        regular=regular,
        close_approach=close,
        long_horizon=long_h,
        short_step=short,
        compile_times=comp,
        auto=auto,
        simulate_vs_kernel=versus,
    )


def tables(rep: dict) -> list[Table]:
    """The tables of a ``bench_integrators.json`` report (the terminal's text); each docs table in its block of
    docs/integrators.md (``<!-- bench:integrators-* -->``, rewritten by ``flatbody bench integrators --docs``)."""
    out = []
    if rep.get("auto"):
        rows = []
        for x in rep["auto"]:
            step = f", h = {x['auto_step']:g}" if x.get("auto_step") else ""
            if x.get("scipy_s"):
                vs = [
                    f"{x['scipy_s'] * 1e3:.1f} ms ({x['scipy_method']})",
                    f"**{x['speedup']:.0f}×**",
                    f"{x['max_difference']:.0e}",
                ]
            else:
                vs = [f"fails ({x.get('scipy_failure')})", "–", "–"]
            rows.append(
                [
                    f"{x['scene']} (t = {x['t_end']:g})",
                    x["model"],
                    x["method"] + step,
                    f"{x['auto_s'] * 1e3:.2f} ms",
                    *vs,
                ]
            )
        out.append(
            Table(
                columns=[
                    "scene",
                    "model (rung)",
                    "method auto runs",
                    "auto",
                    "scipy DOP853 (former default)",
                    "speed-up",
                    "max difference",
                ],
                rows=rows,
                block="integrators-auto",
            )
        )
    r = rep["regular"]
    out.append(
        Table(
            columns=[
                "method",
                f"wall time at error {r['target_error']:g} (regular scene, t = {r['t_end']:g})",
                "vs scipy DOP853",
            ],
            rows=[
                [
                    a["method"],
                    f"{a['wall_time'] * 1e3:.3g} ms" if a["wall_time"] else "not bracketed",
                    f"{a['speedup']:.1f}×" if a.get("speedup") else "–",
                ]
                for a in r["at_target"]
            ],
            notes=[f"reference floor {r['reference_floor']:.1e}"],
            block="integrators-regular",
        )
    )
    out.append(
        Table(
            title="same rtol, DOP853-numba vs scipy DOP853 (identical steps)",
            columns=["setting", "scipy", "numba", "ratio", "nfev scipy / numba", "error"],
            rows=[
                [
                    x["setting"],
                    f"{x['scipy_s'] * 1e3:.2f} ms",
                    f"{x['numba_s'] * 1e3:.3f} ms",
                    f"{x['ratio']:.1f}×",
                    f"{x['scipy_nfev']} / {x['numba_nfev']}",
                    f"{x['numba_error']:.1e}",
                ]
                for x in r["same_rtol"]
            ],
            block=None,
        )
    )
    close = rep["close_approach"]
    if close:
        notes = []
        for c in close:
            ratio = c["regular_vs_cheapest_two_polar"]
            notes.append(
                f"s3 − p_θ = {c['delta']:g}: cheapest two-polar / cheapest regular-chart ({c['cheapest_regular']}) = "
                f"{ratio:.2f}×"
                if ratio
                else f"s3 − p_θ = {c['delta']:g}: no two-polar method reaches the error; {c['cheapest_regular']} does"
            )
        out.append(
            Table(
                columns=["s3 − p_θ", *(a["method"] for a in close[0]["at_target"])],
                rows=[
                    [f"{c['delta']:g}"]
                    + [
                        f"{a['wall_time'] * 1e3:.3g} ms" if a["wall_time"] else "fails / not reached"
                        for a in c["at_target"]
                    ]
                    for c in close
                ],
                notes=notes,
                block="integrators-close",
            )
        )
    out.append(
        Table(
            columns=["method and setting", "energy error", "wall time"],
            rows=[
                [
                    f"{x['method']}, {x['setting']} (t = {x['t_end']:g})",
                    f"{x['energy_error']:.1e}",
                    f"{x['wall_time']:.2f} s",
                ]
                for x in rep["long_horizon"]
            ],
            block="integrators-long",
        )
    )
    out.append(
        Table(
            columns=["method", "path", "µs per step", "batched, µs per body-step"],
            rows=[
                [
                    x["method"],
                    x["path"],
                    f"{x['us_per_step']:.1f}",
                    f"{x['batch_us_per_body_step']:.2f}" if x["path"] == "env" else "",
                ]
                for x in rep["short_step"]
            ],
            block="integrators-short-step",
        )
    )
    v = rep.get("simulate_vs_kernel")
    if v:
        out.append(
            Table(
                columns=[
                    f"{v['scene']}, t = {v['t_end']:g}, {v['method']} ({v['nfev']} evaluations)",
                    "wall time",
                    "/ kernel",
                ],
                rows=[
                    [what, f"{v[key] * 1e3:.3f} ms", f"{ratio:.3f}×"]
                    for what, key, ratio in (
                        ("bare kernel call", "kernel_s", 1.0),
                        ("`integrate`", "integrate_s", v["integrate_over_kernel"]),
                        ("`simulate(...)`", "simulate_s", v["simulate_over_kernel"]),
                    )
                ],
                notes=[f"alternated, best of {v['rounds']}"],
                block="integrators-simulate",
            )
        )
    if rep.get("compile_times"):
        out.append(
            Table(
                columns=["method", "first call, empty cache", "cached"],
                rows=[
                    [x["method"], f"{x['first_call_s']:.2f} s", f"{x['cached_s']:.3f} s"] for x in rep["compile_times"]
                ],
                block="integrators-compile",
            )
        )
    return out


CSV_HEADER = ("section", "case", "method", "setting_or_path", "figure", "value")
"""The columns of ``bench_integrators.csv``: one figure a row."""


def csv_rows(rep: dict) -> list[tuple]:
    """The rows of ``bench_integrators.csv`` (:data:`CSV_HEADER`) from a report as saved."""
    rows = []
    r = rep["regular"]
    for a in r["at_target"]:
        rows.append(
            ("regular", f"t={r['t_end']:g}", a["method"], f"error={r['target_error']:g}", "wall_time_s", a["wall_time"])
        )
        rows.append(
            (
                "regular",
                f"t={r['t_end']:g}",
                a["method"],
                f"error={r['target_error']:g}",
                "speedup_vs_scipy_DOP853",
                a["speedup"],
            )
        )
    for s in r["same_rtol"]:
        rows.append(("regular", "same rtol", "DOP853-numba", s["setting"], "ratio_vs_scipy_DOP853", s["ratio"]))
    for c in rep["close_approach"]:
        for a in c["at_target"]:
            rows.append(
                (
                    "close-approach",
                    f"delta={c['delta']:g}",
                    a["method"],
                    f"error={c['target_error']:g}",
                    "wall_time_s",
                    a["wall_time"],
                )
            )
        rows.append(
            (
                "close-approach",
                f"delta={c['delta']:g}",
                c["cheapest_regular"],
                "",
                "cheapest_two_polar_over_regular",
                c["regular_vs_cheapest_two_polar"],
            )
        )
    for x in rep["long_horizon"]:
        rows.append(("long-horizon", f"t={x['t_end']:g}", x["method"], x["setting"], "energy_error", x["energy_error"]))
    for x in rep["short_step"]:
        rows.append(("short-step", "dt=0.05", x["method"], x["path"], "us_per_step", x["us_per_step"]))
        if x["path"] == "env":
            rows.append(
                ("short-step", "dt=0.05", x["method"], "batch", "us_per_body_step", x["batch_us_per_body_step"])
            )
    for x in rep["auto"]:
        rows.append(("auto", f"{x['scene']} t={x['t_end']:g}", x["method"], x["model"], "wall_time_s", x["auto_s"]))
        rows.append(
            (
                "auto",
                f"{x['scene']} t={x['t_end']:g}",
                "DOP853",
                "scipy (former default)",
                "wall_time_s",
                x.get("scipy_s"),
            )
        )
    v = rep.get("simulate_vs_kernel")
    if v:
        case = f"{v['scene']} t={v['t_end']:g}"
        for path in ("kernel", "integrate", "simulate"):
            rows.append(("simulate-vs-kernel", case, v["method"], path, "wall_time_s", v[f"{path}_s"]))
        for path in ("integrate", "simulate"):
            rows.append(("simulate-vs-kernel", case, v["method"], path, "ratio_vs_kernel", v[f"{path}_over_kernel"]))
    for x in rep["compile_times"]:
        rows.append(("compile", "", x["method"], "first call", "seconds", x["first_call_s"]))
        rows.append(("compile", "", x["method"], "cached", "seconds", x["cached_s"]))
    return rows


def load(json_path: str | os.PathLike) -> dict:
    """A saved ``bench_integrators.json`` (the report as :func:`report` takes it)."""
    return validation.read_json("--plot-only", json_path)


def report(rep: BenchReport | dict) -> Report:
    """``rep`` (a run, or a saved report) for :func:`flatbody_env.bench.harness.write_report`:
    ``bench_integrators.json``, ``.csv``, ``.png`` (:func:`analysis.integrator_plots.plot_bench`, from the saved JSON)
    and the tables (:func:`tables`, several docs blocks)."""
    from analysis.integrator_plots import plot_bench

    record = rep.as_dict() if isinstance(rep, BenchReport) else dict(rep)
    return Report(
        name=NAME,
        record=record,
        header=CSV_HEADER,
        rows=csv_rows(record),
        chart=plot_bench,
        tables=tables(record),
        block="integrators-regular",
    )


__all__ = [
    "CSV_HEADER",
    "NAME",
    "BenchReport",
    "compile_times",
    "csv_rows",
    "load",
    "measure",
    "report",
    "simulate_vs_kernel",
    "tables",
    "wall_at",
]
