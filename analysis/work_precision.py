"""Work-precision study of the integrators: error against cost, per method and scene.

Conventions (SciML's, docs/physics.md §10): x = error of the final state (max over the 11 paper variables of
|y(T) − y_ref(T)|) against a tight reference that is cross-checked by an independent method (another
chart and algorithm); its *agreement floor* (max |y_ref − y_cross|) is recorded and drawn — errors
below it are not resolved. y = wall time, the minimum of repeats; a second measure is the number of
right-hand-side (force) evaluations. Adaptive methods sweep rtol (atol = 1e-3·rtol), fixed-step ones
sweep the step h. On the long-horizon scene the error is the energy error max_t |H(t) − H(0)|
over 101 samples instead (the orbit is only compared through its invariant there).

Public names: :func:`work_precision` → (list of :class:`WorkPrecisionPoint`, list of
:class:`ReferenceInfo`); :func:`reference_state`; :func:`timed_run`; :func:`write_records`.
Uses the physics and integrator layers only.
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from flatbody_env.physics import validation
from flatbody_env.output import atomic_open, atomic_write
from flatbody_env.physics.hamiltonian import hamiltonian, hamiltonian_series
from flatbody_env.integrators import IntegrationError, Tolerances, get_method
from flatbody_env.scene import Scene, load_scene
from flatbody_env.physics.state import pack

SCENES = ("regular", "close-approach", "small-rho-bounce", "long-horizon")
ENERGY_SCENES = ("long-horizon",)
DEFAULT_METHODS = (
    "RK45",
    "DOP853",
    "Radau",
    "LSODA",
    "DOP853-regular",
    "DOP853-numba",
    "RK4",
    "splitting-strang",
    "splitting-suzuki4",
    "splitting-yoshida4",
    "RATTLE",
    "RATTLE-suzuki4",
    "RATTLE-kahanli6",
)
RTOLS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
STEPS = (0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625)
QUICK_RTOLS = (1e-4, 1e-7, 1e-10)
QUICK_STEPS = (0.1, 0.025, 0.00625)
HORIZONS = {"regular": 100.0, "close-approach": 20.0, "small-rho-bounce": 20.0, "long-horizon": 1e4}
QUICK_HORIZONS = {"regular": 20.0, "close-approach": 10.0, "small-rho-bounce": 10.0, "long-horizon": 1e3}
LONG_HORIZON_MIN_STEP = 0.025
"""Fixed steps below this are skipped on the long-horizon scene (cost, not accuracy, would dominate)."""

ENERGY_BUDGET_FACTOR = 3.0
"""The long-horizon scene gets this many times ``max_run_s`` per run (so the reference family shows up)."""

REFERENCE = ("DOP853-numba", dict(rtol=1e-13, atol=1e-15))
CROSS_CHECK = ("RATTLE-suzuki4", dict(step=0.001))


@dataclass(frozen=True, kw_only=True)
class WorkPrecisionPoint:
    """One run of one method at one setting on one scene."""

    scene: str
    method: str
    chart: str
    compiled: bool
    adaptive: bool
    setting: str
    """``"rtol=1e-08"`` or ``"h=0.05"``."""
    rtol: float
    step: float
    t_end: float
    error: float
    """Final-state error, or the energy error on energy scenes; nan when the run failed."""
    error_kind: str
    """``"state"`` or ``"energy"``."""
    wall_time: float
    """Seconds, minimum over ``repeats``."""
    repeats: int
    nfev: int
    status: str
    """``"ok"``, the :class:`IntegrationError` kind, or ``"skipped"`` (over the time budget)."""
    reason: str = ""


@dataclass(frozen=True, kw_only=True)
class ReferenceInfo:
    """The reference of a scene and how well an independent method agrees with it."""

    scene: str
    t_end: float
    error_kind: str
    method: str
    setting: str
    cross_method: str
    cross_setting: str
    agreement: float
    """max |y_ref(T) − y_cross(T)| (state) or the round-off level of H (energy): the chart's floor."""
    wall_time: float


def _setting_text(kw: dict) -> str:
    return ", ".join(f"{k}={v:g}" for k, v in kw.items())


MAX_REPEATS = 200


def timed_run(
    method: str, scene: Scene, times: np.ndarray, tol: Tolerances, *, repeats: int = 3, min_time: float = 0.2
):
    """Run ``method`` ``repeats`` times, and more (up to :data:`MAX_REPEATS`) while less than ``min_time``
    seconds have been spent, so that the minimum of short runs is robust on a noisy machine; a single
    run longer than ``min_time`` is not repeated. Returns (Solution or None, min wall time, number of
    runs, status, reason)."""
    meth = get_method(method)
    y0 = pack(scene.state)
    best = math.inf
    spent = 0.0
    runs = 0
    sol = None
    while runs < MAX_REPEATS:
        t0 = time.perf_counter()
        try:
            sol = meth.integrate(scene.body, y0, times, tol=tol)
        except IntegrationError as exc:
            wall = time.perf_counter() - t0
            return None, wall, runs + 1, exc.kind, str(exc)
        wall = time.perf_counter() - t0
        best = min(best, wall)
        spent += wall
        runs += 1
        if spent >= min_time and (runs >= repeats or wall >= min_time):
            break
    return sol, best, runs, "ok", ""


def reference_state(scene: Scene, t_end: float) -> tuple[np.ndarray, ReferenceInfo]:
    """Tight final state at ``t_end`` (DOP853-numba, rtol 1e-13) and its agreement with RATTLE-suzuki4 (h = 0.001)."""
    y0 = pack(scene.state)
    times = np.array([0.0, t_end])
    t0 = time.perf_counter()
    ref = get_method(REFERENCE[0]).integrate(scene.body, y0, times, tol=Tolerances(**REFERENCE[1])).Y[:, -1]
    wall = time.perf_counter() - t0
    cross = get_method(CROSS_CHECK[0]).integrate(scene.body, y0, times, tol=Tolerances(**CROSS_CHECK[1])).Y[:, -1]
    info = ReferenceInfo(
        scene=scene.name,
        t_end=t_end,
        error_kind="state",
        method=REFERENCE[0],
        setting=_setting_text(REFERENCE[1]),
        cross_method=CROSS_CHECK[0],
        cross_setting=_setting_text(CROSS_CHECK[1]),
        agreement=float(np.max(np.abs(ref - cross))),
        wall_time=wall,
    )
    return ref, info


def _settings(adaptive: bool, quick: bool, scene: str):
    if adaptive:
        return [("rtol", r) for r in (QUICK_RTOLS if quick else RTOLS)]
    steps = QUICK_STEPS if quick else STEPS
    if scene in ENERGY_SCENES:
        steps = tuple(h for h in steps if h >= LONG_HORIZON_MIN_STEP) or steps[:1]
    return [("step", h) for h in steps]


def _predicted_wall(points, method: str, setting: str, t_end: float) -> float:
    """Wall time predicted from the same method and setting on the regular scene, scaled by the horizon."""
    for p in points:
        if p.scene == "regular" and p.method == method and p.setting == setting and p.status == "ok":
            return p.wall_time * t_end / p.t_end
    return 0.0


def work_precision(
    scenes=SCENES,
    methods=DEFAULT_METHODS,
    *,
    quick: bool = False,
    repeats: int = 3,
    max_run_s: float = 5.0,
    progress: bool = True,
) -> tuple[list[WorkPrecisionPoint], list[ReferenceInfo]]:
    """Sweep every method over its settings on every scene.

    A method's sweep on a scene stops once one run takes longer than ``max_run_s`` (tighter
    settings only cost more), or once the same setting on the regular scene, scaled by the
    horizon, predicts that (recorded with status ``"skipped"``). Failures are recorded with
    their kind.
    """
    from flatbody_env.integrators.compiled_methods import warm_up
    from flatbody_env.progress import progress_bar

    warm_up()  # load (or compile) the kernels before anything is timed
    horizons = QUICK_HORIZONS if quick else HORIZONS
    infos = {m: get_method(m).info for m in methods}
    jobs = []
    for sc_name in scenes:
        for m in methods:
            for s in _settings(infos[m].adaptive, quick, sc_name):
                jobs.append((sc_name, m, s))
    points: list[WorkPrecisionPoint] = []
    refs: list[ReferenceInfo] = []
    bar = progress_bar(total=len(jobs), desc="work-precision", unit="run", enabled=progress)
    ref_cache: dict[str, tuple] = {}
    stopped: set[tuple[str, str]] = set()
    for sc_name, m, (kind, value) in jobs:
        bar.set_postfix_str(f"{sc_name} {m} {kind}={value:g}")
        scene = load_scene(sc_name)
        t_end = horizons[sc_name]
        energy = sc_name in ENERGY_SCENES
        if sc_name not in ref_cache:
            if energy:
                H0 = hamiltonian(pack(scene.state), scene.body)
                info = ReferenceInfo(
                    scene=sc_name,
                    t_end=t_end,
                    error_kind="energy",
                    method="exact H(0)",
                    setting="",
                    cross_method="",
                    cross_setting="",
                    agreement=float(8 * np.finfo(float).eps * abs(H0)),
                    wall_time=0.0,
                )
                ref_cache[sc_name] = (H0, info)
            else:
                ref_cache[sc_name] = reference_state(scene, t_end)
            refs.append(ref_cache[sc_name][1])
        if (sc_name, m) in stopped:
            bar.update(1)
            continue
        ref = ref_cache[sc_name][0]
        info = infos[m]
        tol = Tolerances(rtol=value, atol=1e-3 * value) if kind == "rtol" else Tolerances(step=value)
        times = np.linspace(0.0, t_end, 101) if energy else np.array([0.0, t_end])
        setting = f"{kind}={value:g}" if kind == "rtol" else f"h={value:g}"
        budget = max_run_s * (ENERGY_BUDGET_FACTOR if energy else 1.0)
        predicted = _predicted_wall(points, m, setting, t_end)
        if predicted > budget:
            # the same method and setting on the regular scene, scaled by the horizon, says it would take too long
            points.append(
                WorkPrecisionPoint(
                    scene=sc_name,
                    method=m,
                    chart=info.chart,
                    compiled=info.compiled,
                    adaptive=info.adaptive,
                    setting=setting,
                    rtol=value if kind == "rtol" else math.nan,
                    step=value if kind == "step" else math.nan,
                    t_end=t_end,
                    error=math.nan,
                    error_kind="energy" if energy else "state",
                    wall_time=math.nan,
                    repeats=0,
                    nfev=0,
                    status="skipped",
                    reason=f"predicted {predicted:.1f} s > budget {budget:g} s",
                )
            )
            stopped.add((sc_name, m))
            bar.update(1)
            continue
        sol, wall, runs, status, reason = timed_run(m, scene, times, tol, repeats=repeats)
        if sol is None:
            err = math.nan
            nfev = 0
        elif energy:
            err = float(np.max(np.abs(hamiltonian_series(sol.Y, scene.body) - ref)))
            nfev = sol.nfev
        else:
            err = float(np.max(np.abs(sol.Y[:, -1] - ref)))
            nfev = sol.nfev
        points.append(
            WorkPrecisionPoint(
                scene=sc_name,
                method=m,
                chart=info.chart,
                compiled=info.compiled,
                adaptive=info.adaptive,
                setting=f"{kind}={value:g}" if kind == "rtol" else f"h={value:g}",
                rtol=value if kind == "rtol" else math.nan,
                step=value if kind == "step" else math.nan,
                t_end=t_end,
                error=err,
                error_kind="energy" if energy else "state",
                wall_time=wall,
                repeats=runs,
                nfev=nfev,
                status=status,
                reason=reason,
            )
        )
        if wall > budget:
            stopped.add((sc_name, m))
        bar.update(1)
    bar.close()
    return points, refs


def write_records(records, path: str | Path) -> Path:
    """Write a list of dataclass records as CSV (header = field names)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not records:
        raise ValueError("records: nothing to write")
    names = [f.name for f in fields(records[0])]
    with atomic_open(path) as fh:
        w = csv.DictWriter(fh, fieldnames=names)
        w.writeheader()
        for r in records:
            w.writerow(asdict(r))
    return path


def write_json(records, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, json.dumps([asdict(r) for r in records], indent=2) + "\n")
    return path


def read_csv(path: str | Path) -> list[dict]:
    """Rows of a CSV written by :func:`write_records`, numbers parsed."""
    out = []
    for row in validation.read_csv("csv", path):  # the one reading door: a regular file, bounded
        parsed = {}
        for k, v in row.items():
            if v in ("True", "False"):
                parsed[k] = v == "True"
                continue
            try:
                parsed[k] = float(v)
            except ValueError:
                parsed[k] = v
        out.append(parsed)
    return out


__all__ = [
    "DEFAULT_METHODS",
    "ReferenceInfo",
    "SCENES",
    "WorkPrecisionPoint",
    "read_csv",
    "reference_state",
    "timed_run",
    "work_precision",
    "write_json",
    "write_records",
]
