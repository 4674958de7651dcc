"""What "model no more than a scene needs" buys: error against cost for every rung of the model ladder.

For each built-in scene: the rung ``simulate(model="auto")`` chooses
(:func:`flatbody_env.simulation.explain_model`), and error against wall time for every rung that
applies to the scene (:mod:`flatbody_env.integrators.ladder`) next to the full models:

=============  ==============================================  =================================
rung           integrated by                                   setting swept
=============  ==============================================  =================================
stationary     closed form                                     none (one point)
planar-V1      closed form in the plane + compiled DOP853 (ϱ)   rtol (the ϱ oscillator)
planar         compiled DOP853 on the two small systems         rtol
two-polar      ``DOP853-numba`` (the same compiled DOP853), and  rtol
               scipy ``DOP853`` (``simulate``'s default method)
regular        ``RATTLE-kahanli6`` (compiled, order 6)          step h
=============  ==============================================  =================================

Error: max over the 11 paper variables of |y(T) − y_ref(T)| at the scene's horizon
T = min(t_end, :data:`HORIZON`) (SciML's convention, as in :mod:`analysis.work_precision`). The
reference is the exact rung where the scene has one (``stationary``, ``planar-V1`` at the
tightest rtol), cross-checked by ``DOP853-numba`` at rtol 1e-13; otherwise ``DOP853-numba`` at
rtol 1e-13 cross-checked by ``RATTLE-kahanli6`` at h = 0.001. The agreement of the two is the
scene's *floor*: smaller errors are not resolved. Cost: wall time, the minimum of at least
``repeats`` runs (more while less than :data:`MIN_TIME` seconds have been spent), measured side by side in
one process; ratios are the reliable part on a shared machine.

Horizon rows (scene ``"stationary-ellipse t=1e+04"`` etc.): the ``stationary`` rung and ``two-polar``
at rtol :data:`HORIZON_RTOL` on the stationary ellipse at t = 1e2 … 1e5: the closed form costs the same
at any t, a time stepper's cost grows with t.

Public names: :func:`ladder_study` → (list of :class:`LadderPoint`, list of :class:`LadderScene`),
:func:`speedups` (the cheapest run of each rung reaching an error target against the cheapest full
model), :func:`write_csv`, :func:`read_csv`. Uses the physics, integrator and simulation layers only.
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from flatbody_env.integrators import IntegrationError, Tolerances, get_method
from flatbody_env.integrators.ladder import LADDER_RUNGS, check_rung, rung_model
from flatbody_env.output import atomic_open
from flatbody_env.physics import validation
from flatbody_env.physics.state import pack
from flatbody_env.scene import Scene, builtin_scenes
from flatbody_env.simulation import explain_model

HORIZON = 100.0
QUICK_HORIZON = 20.0
RTOLS = (1e-5, 1e-7, 1e-9, 1e-11, 1e-13)
QUICK_RTOLS = (1e-6, 1e-9, 1e-12)
STEPS = (0.1, 0.05, 0.025, 0.0125, 0.00625)
QUICK_STEPS = (0.1, 0.025)
FULL_METHODS = {"two-polar": ("DOP853-numba", "DOP853"), "regular": ("RATTLE-kahanli6",)}
"""The methods that integrate each full model in this study (the first is the compiled one)."""
DEFAULT_METHOD = "DOP853"
"""``simulate``'s default method: :func:`speedups` also reports the ratio against it."""
REFERENCE = ("DOP853-numba", 1e-13)
CROSS = ("RATTLE-kahanli6", 0.001)
MIN_TIME = 0.05
MAX_REPEATS = 50
TARGET_ERROR = 1e-9
"""Error target of :func:`speedups`."""
HORIZON_SCENE = "stationary-ellipse"
HORIZONS = (1e2, 1e3, 1e4, 1e5)
QUICK_HORIZONS = (1e2, 1e3)
HORIZON_RTOL = 1e-11
"""The horizon rows: the exact ``stationary`` rung against ``two-polar`` at this rtol on :data:`HORIZON_SCENE`
as t grows (O(1) against O(t) per output)."""


@dataclass(frozen=True, kw_only=True)
class LadderPoint:
    """One run of one rung at one setting on one scene."""

    scene: str
    chosen: str
    """The rung ``model="auto"`` chooses for the scene."""
    rung: str
    method: str
    setting: str
    t_end: float
    error: float
    """Final-state error (max norm over the 11 paper variables); nan when the run failed."""
    wall_time: float
    """Seconds, minimum of repeats."""
    nfev: int
    status: str
    """``"ok"``, the :class:`IntegrationError` kind, or ``"skipped"`` (over the time budget)."""


@dataclass(frozen=True, kw_only=True)
class LadderScene:
    """A scene's chosen rung, why, and the agreement floor of its reference."""

    scene: str
    chosen: str
    invariant: str
    t_end: float
    reference: str
    cross_check: str
    floor: float


def _models(rung: str) -> list:
    return [rung_model(rung)] if rung in LADDER_RUNGS else [get_method(m) for m in FULL_METHODS[rung]]


def _tol(rung: str, value: float | None) -> tuple[Tolerances, str]:
    if rung == "regular":
        return Tolerances(step=value), f"h={value:g}"
    if rung == "stationary":
        return Tolerances(), "exact"
    return Tolerances(rtol=value, atol=value), f"rtol={value:g}"


def _timed(model, scene: Scene, times: np.ndarray, tol: Tolerances, repeats: int):
    y0 = pack(scene.state)
    best, spent, runs, sol = math.inf, 0.0, 0, None
    while runs < MAX_REPEATS:
        t0 = time.perf_counter()
        try:
            sol = model.integrate(scene.body, y0, times, tol=tol)
        except IntegrationError as exc:
            return None, time.perf_counter() - t0, exc.kind
        wall = time.perf_counter() - t0
        best, spent, runs = min(best, wall), spent + wall, runs + 1
        if runs >= repeats and spent >= MIN_TIME:
            break
    return sol, best, "ok"


def applicable_rungs(scene: Scene) -> list[str]:
    """Every rung whose invariant set holds the scene's initial state, and the two full models."""
    y0 = pack(scene.state)
    out = []
    for rung in LADDER_RUNGS:
        try:
            check_rung(rung, y0, scene.body)
            out.append(rung)
        except ValueError:
            pass
    return out + ["two-polar", "regular"]


def _reference(scene: Scene, times: np.ndarray, rungs: list[str]) -> tuple[np.ndarray, str, str, float]:
    y0 = pack(scene.state)
    best = (
        get_method(REFERENCE[0])
        .integrate(scene.body, y0, times, tol=Tolerances(rtol=REFERENCE[1], atol=REFERENCE[1] * 1e-2))
        .Y[:, -1]
    )
    best_txt = f"{REFERENCE[0]} rtol={REFERENCE[1]:g}"
    exact = [r for r in ("stationary", "planar-V1") if r in rungs]
    if exact:
        ref = rung_model(exact[0]).integrate(scene.body, y0, times, tol=Tolerances(rtol=1e-13, atol=1e-15)).Y[:, -1]
        return ref, f"{exact[0]} (exact)", best_txt, float(np.max(np.abs(ref - best)))
    try:
        cross = get_method(CROSS[0]).integrate(scene.body, y0, times, tol=Tolerances(step=CROSS[1])).Y[:, -1]
        floor = float(np.max(np.abs(cross - best)))
    except (IntegrationError, ValueError) as exc:
        return best, best_txt, f"{CROSS[0]} h={CROSS[1]:g} failed ({type(exc).__name__})", math.nan
    return best, best_txt, f"{CROSS[0]} h={CROSS[1]:g}", floor


def ladder_study(scenes=None, *, quick: bool = False, repeats: int = 3, max_run_s: float = 5.0, log=None):
    """Run the study (module docstring); returns (points, scene records)."""
    all_scenes = builtin_scenes()
    names = list(scenes) if scenes else sorted(all_scenes)
    for n in names:
        if n not in all_scenes:
            raise ValueError(f"scenes: unknown scene {n!r} (allowed: {', '.join(sorted(all_scenes))})")
    rtols = QUICK_RTOLS if quick else RTOLS
    steps = QUICK_STEPS if quick else STEPS
    points: list[LadderPoint] = []
    records: list[LadderScene] = []
    for name in names:
        sc = all_scenes[name]
        T = min(sc.t_end, QUICK_HORIZON if quick else HORIZON)
        times = np.array([0.0, T])
        choice = explain_model(pack(sc.state), sc.body)
        rungs = applicable_rungs(sc)
        ref, ref_txt, cross_txt, floor = _reference(sc, times, rungs)
        records.append(
            LadderScene(
                scene=name,
                chosen=choice.rung,
                invariant=choice.invariant,
                t_end=T,
                reference=ref_txt,
                cross_check=cross_txt,
                floor=floor,
            )
        )
        for rung, model in [(r, m) for r in rungs for m in _models(r)]:
            settings = [None] if rung == "stationary" else (steps if rung == "regular" else rtols)
            over = False
            for value in settings:
                tol, text = _tol(rung, value)
                if over:
                    points.append(
                        LadderPoint(
                            scene=name,
                            chosen=choice.rung,
                            rung=rung,
                            method=model.info.name,
                            setting=text,
                            t_end=T,
                            error=math.nan,
                            wall_time=math.nan,
                            nfev=0,
                            status="skipped",
                        )
                    )
                    continue
                sol, wall, status = _timed(model, sc, times, tol, repeats)
                err = float(np.max(np.abs(sol.Y[:, -1] - ref))) if sol is not None else math.nan
                points.append(
                    LadderPoint(
                        scene=name,
                        chosen=choice.rung,
                        rung=rung,
                        method=model.info.name,
                        setting=text,
                        t_end=T,
                        error=err,
                        wall_time=wall,
                        nfev=int(sol.nfev) if sol is not None else 0,
                        status=status,
                    )
                )
                if log is not None:
                    log(f"{name:<20} {model.info.name:<18} {text:<12} error {err:9.2e}  {wall * 1e3:9.3f} ms  {status}")
                over = wall > max_run_s
    if not scenes or HORIZON_SCENE in names:
        sc = all_scenes[HORIZON_SCENE]
        for T in QUICK_HORIZONS if quick else HORIZONS:
            label = f"{HORIZON_SCENE} t={T:.0e}"
            times = np.array([0.0, T])
            ref = rung_model("stationary").integrate(sc.body, pack(sc.state), times, tol=Tolerances()).Y[:, -1]
            records.append(
                LadderScene(
                    scene=label,
                    chosen="stationary",
                    invariant="stationary ellipse",
                    t_end=T,
                    reference="stationary (exact)",
                    cross_check="",
                    floor=math.nan,
                )
            )
            for rung, tol, text in (
                ("stationary", Tolerances(), "exact"),
                ("two-polar", Tolerances(rtol=HORIZON_RTOL, atol=HORIZON_RTOL), f"rtol={HORIZON_RTOL:g}"),
            ):
                model = _models(rung)[0]
                sol, wall, status = _timed(model, sc, times, tol, repeats)
                err = float(np.max(np.abs(sol.Y[:, -1] - ref))) if sol is not None else math.nan
                points.append(
                    LadderPoint(
                        scene=label,
                        chosen="stationary",
                        rung=rung,
                        method=model.info.name,
                        setting=text,
                        t_end=T,
                        error=err,
                        wall_time=wall,
                        nfev=int(sol.nfev) if sol is not None else 0,
                        status=status,
                    )
                )
                if log is not None:
                    log(f"{label:<20} {rung:<11} {text:<12} error {err:9.2e}  {wall * 1e3:9.3f} ms  {status}")
    return points, records


def speedups(points, target: float = TARGET_ERROR) -> list[dict]:
    """Per scene and method: the cheapest run with error ≤ ``target`` (or the most accurate one), and the
    ratios of the cheapest full-model run (compiled or not) and of ``simulate``'s default method
    (:data:`DEFAULT_METHOD`) reaching the same target to it.

    A ratio that cannot be computed is nan, and ``why_no_full`` / ``why_no_default`` say why (empty
    when the ratio is a number): the row itself missed the target, no full model (or the default
    method) reached it on the scene, or the default method was not run there (the horizon rows).
    """
    out = []
    scenes = list(dict.fromkeys(p.scene for p in points))
    for sc in scenes:
        sub = [p for p in points if p.scene == sc and p.status == "ok"]
        ran = {p.method for p in points if p.scene == sc}
        best = {}
        for method in dict.fromkeys(p.method for p in sub):
            pts = [p for p in sub if p.method == method]
            good = [p for p in pts if p.error <= target]
            best[method] = (
                (min(good, key=lambda p: p.wall_time), True) if good else (min(pts, key=lambda p: p.error), False)
            )
        full = [p for p, ok in best.values() if ok and p.rung in ("two-polar", "regular")]
        full_time = min((p.wall_time for p in full), default=math.nan)
        default = best.get(DEFAULT_METHOD)
        default_time = default[0].wall_time if default is not None and default[1] else math.nan
        no_full = "" if full else f"no full model reached {target:g}"
        if DEFAULT_METHOD not in ran:
            no_default = "not run on this scene"
        elif default is None or not default[1]:
            cut = any(p.scene == sc and p.method == DEFAULT_METHOD and p.status == "skipped" for p in points)
            no_default = f"it did not reach {target:g}" + (" within the time budget" if cut else "")
        else:
            no_default = ""
        for method, (p, reached) in best.items():
            missed = f"this row did not reach {target:g}"
            out.append(
                {
                    "scene": sc,
                    "chosen": p.chosen,
                    "rung": p.rung,
                    "method": method,
                    "setting": p.setting,
                    "error": p.error,
                    "wall_time": p.wall_time,
                    "reached_target": reached,
                    "speedup_vs_full": full_time / p.wall_time if reached else math.nan,
                    "speedup_vs_default": default_time / p.wall_time if reached else math.nan,
                    "why_no_full": "" if reached and full else (no_full or missed),
                    "why_no_default": "" if reached and not no_default else (no_default or missed),
                }
            )
    return out


def write_csv(points, path) -> Path:
    """The points as CSV (one row per run)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = [f.name for f in fields(LadderPoint)]
    with atomic_open(path) as fh:
        w = csv.DictWriter(fh, fieldnames=names)
        w.writeheader()
        for p in points:
            w.writerow(asdict(p))
    return path


def write_scenes(records, path) -> Path:
    """The scene records as CSV (chosen rung, why, reference and its floor)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = [f.name for f in fields(LadderScene)]
    with atomic_open(path) as fh:
        w = csv.DictWriter(fh, fieldnames=names)
        w.writeheader()
        for r in records:
            w.writerow(asdict(r))
    return path


def read_csv(path) -> list[dict]:
    """Rows of a CSV written by :func:`write_csv` or :func:`write_scenes` (numbers as floats)."""
    out = []
    for row in validation.read_csv("csv", path):  # the one reading door: a regular file, bounded
        for k in ("t_end", "error", "wall_time", "floor"):
            if k in row:
                row[k] = float(row[k])
        if "nfev" in row:
            row["nfev"] = int(row["nfev"])
        out.append(row)
    return out


__all__ = [
    "LadderPoint",
    "LadderScene",
    "applicable_rungs",
    "ladder_study",
    "read_csv",
    "speedups",
    "write_csv",
    "write_scenes",
]
