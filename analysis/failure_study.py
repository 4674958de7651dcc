"""Where integrators fail: error and cost as a scene gets harder along three axes.

* ``gap`` — closest approach to λ = μ: the close-approach scene with σ₋ = s3 − p_θ = δ
  (:func:`gap_scene`); the measured relative gap min (λ − μ)/λ shrinks with δ (about ∝ δ).
  Reference: scipy DOP853 in the regular chart (rtol 1e-12), cross-checked by RATTLE-suzuki4
  (h = 0.0025); the closest approach is measured on the cross-check's samples (every 0.005,
  refined by a parabola through the three samples of (λ − μ)² around the minimum).
* ``rho`` — the thickness bounce: the small-ρ scene with initial p_ϱ (more negative: harder
  bounce); the measured ϱ_min comes from the reference (DOP853-numba rtol 1e-13, cross-check
  RATTLE-suzuki4 h = 5e-4), refined the same way.
* ``horizon`` — the regular scene at growing t_end: final-state error against DOP853-numba
  (rtol 1e-13, cross-check RATTLE-suzuki4 h = 0.005) and the energy error max|H − H₀|.

Each method runs at one fixed setting (adaptive: rtol 1e-10, atol 1e-12; fixed-step: h = 0.01),
so the records show how the *same* setting degrades, with the energy tolerances of
:func:`flatbody_env.simulate` (fixed-step: 1e-3·max(1, |H₀|)) so that a blown-up run is reported
as a failure of its kind instead of a plausible-looking state.
Public names: :func:`failure_study` → list of :class:`FailurePoint`; :func:`gap_scene`;
:func:`rho_scene`. Uses the physics and integrator layers only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flatbody_env.physics.hamiltonian import hamiltonian, hamiltonian_series
from flatbody_env.integrators import Tolerances, get_method
from flatbody_env.scene import Scene, load_scene
from flatbody_env.simulation import default_energy_tol
from flatbody_env.physics.state import pack

from analysis.work_precision import timed_run

STUDIES = ("gap", "rho", "horizon")
DEFAULT_METHODS = (
    "DOP853",
    "DOP853-regular",
    "DOP853-numba",
    "RK4",
    "splitting-strang",
    "splitting-suzuki4",
    "RATTLE",
    "RATTLE-suzuki4",
    "RATTLE-kahanli6",
)
GAP_DELTAS = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
QUICK_GAP_DELTAS = (1e-1, 1e-3, 1e-5, 1e-7)
RHO_P = (-1.0, -2.0, -3.0, -4.0, -5.0, -6.0)
QUICK_RHO_P = (-1.0, -3.0, -5.0)
HORIZONS = (10.0, 100.0, 1000.0, 10000.0)
QUICK_HORIZONS = (10.0, 100.0, 1000.0)
GAP_T_END = 6.0
RHO_T_END = 10.0
ADAPTIVE = dict(rtol=1e-10, atol=1e-12)
FIXED_STEP = 0.01


@dataclass(frozen=True, kw_only=True)
class FailurePoint:
    """One method on one scene of a study."""

    study: str
    """``"gap"``, ``"rho"`` or ``"horizon"``."""
    method: str
    chart: str
    parameter_name: str
    parameter: float
    """δ = s3 − p_θ, the initial p_ϱ, or t_end."""
    measured_name: str
    measured: float
    """min (λ − μ)/λ, ϱ_min, or t_end."""
    setting: str
    error: float
    """Final-state error against the reference (nan on failure)."""
    energy_error: float
    """max |H(t) − H(0)| over the samples (nan on failure)."""
    reference_floor: float
    """Agreement of the reference with its independent cross-check."""
    wall_time: float
    nfev: int
    status: str
    reason: str = ""


def gap_scene(delta: float) -> Scene:
    """The close-approach scene (σ₋ = 1e-3) re-centred on σ₋ = s3 − p_θ = ``delta`` (s3 + p_θ = 2 kept)."""
    return load_scene("close-approach").with_state(s3=1.0 + 0.5 * delta, p_theta=1.0 - 0.5 * delta)


def rho_scene(p_rho: float) -> Scene:
    """The small-ρ-bounce scene with initial p_ϱ = ``p_rho``."""
    return load_scene("small-rho-bounce").with_state(p_rho=p_rho)


def _parabola_min(t: np.ndarray, f: np.ndarray) -> float:
    """Minimum of samples f refined by the parabola through the three samples around the smallest."""
    k = int(np.argmin(f))
    if k == 0 or k == f.size - 1:
        return float(f[k])
    x = t[k - 1 : k + 2]
    y = f[k - 1 : k + 2]
    a, b, c = np.polyfit(x - x[1], y, 2)
    if a <= 0:
        return float(f[k])
    return float(max(c - b * b / (4 * a), 0.0))


def relative_gap_min(Z: np.ndarray, times: np.ndarray) -> float:
    """min (λ − μ)/λ along regular states Z (18, n) sampled at ``times``, parabola-refined on (λ − μ)²."""
    n11 = (Z[0:3] ** 2).sum(0)
    n22 = (Z[3:6] ** 2).sum(0)
    n12 = (Z[0:3] * Z[3:6]).sum(0)
    disc = np.sqrt(0.25 * (n11 - n22) ** 2 + n12**2)
    lam = np.sqrt(0.5 * (n11 + n22) + disc)
    mu = np.sqrt(np.maximum(0.5 * (n11 + n22) - disc, 0.0))
    gap2 = (lam - mu) ** 2
    k = int(np.argmin(gap2))
    return math.sqrt(_parabola_min(times, gap2)) / float(lam[k])


def _run(study, method, scene, t_end, ref, floor, pname, pval, mname, mval, repeats) -> FailurePoint:
    info = get_method(method).info
    # the energy tolerances of simulate(): failures must be detected, not returned as states
    energy_tol = default_energy_tol(
        hamiltonian(pack(scene.state), scene.body), ADAPTIVE["rtol"], ADAPTIVE["atol"], adaptive=info.adaptive
    )
    if info.adaptive:
        tol = Tolerances(**ADAPTIVE, energy_tol=energy_tol)
    else:
        tol = Tolerances(step=FIXED_STEP, energy_tol=energy_tol)
    setting = f"rtol={ADAPTIVE['rtol']:g}" if info.adaptive else f"h={FIXED_STEP:g}"
    times = np.linspace(0.0, t_end, 101)
    sol, wall, runs, status, reason = timed_run(method, scene, times, tol, repeats=repeats)
    if sol is None:
        err = dH = math.nan
        nfev = 0
    else:
        err = float(np.max(np.abs(sol.Y[:, -1] - ref)))
        H = hamiltonian_series(sol.Y, scene.body)
        dH = float(np.max(np.abs(H - H[0])))
        nfev = sol.nfev
    return FailurePoint(
        study=study,
        method=method,
        chart=info.chart,
        parameter_name=pname,
        parameter=pval,
        measured_name=mname,
        measured=mval,
        setting=setting,
        error=err,
        energy_error=dH,
        reference_floor=floor,
        wall_time=wall,
        nfev=nfev,
        status=status,
        reason=reason,
    )


def _gap_reference(delta: float):
    sc = gap_scene(delta)
    y0 = pack(sc.state)
    ends = np.array([0.0, GAP_T_END])
    ref = get_method("DOP853-regular").integrate(sc.body, y0, ends, tol=Tolerances(rtol=1e-12, atol=1e-12)).Y[:, -1]
    fine = np.linspace(0.0, GAP_T_END, int(GAP_T_END / 0.005) + 1)
    cross = get_method("RATTLE-suzuki4").integrate(sc.body, y0, fine, tol=Tolerances(step=0.0025))
    return sc, ref, float(np.max(np.abs(cross.Y[:, -1] - ref))), relative_gap_min(cross.stats["regular"], fine)


def _rho_reference(p_rho: float):
    sc = rho_scene(p_rho)
    y0 = pack(sc.state)
    fine = np.linspace(0.0, RHO_T_END, int(RHO_T_END / 0.002) + 1)
    ref_run = get_method("DOP853-numba").integrate(sc.body, y0, fine, tol=Tolerances(rtol=1e-13, atol=1e-15))
    cross = get_method("RATTLE-suzuki4").integrate(sc.body, y0, np.array([0.0, RHO_T_END]), tol=Tolerances(step=5e-4))
    ref = ref_run.Y[:, -1]
    rho_min = math.sqrt(_parabola_min(fine, ref_run.Y[9] ** 2))
    return sc, ref, float(np.max(np.abs(cross.Y[:, -1] - ref))), rho_min


def _horizon_reference(t_end: float):
    sc = load_scene("regular")
    y0 = pack(sc.state)
    ends = np.array([0.0, t_end])
    ref = get_method("DOP853-numba").integrate(sc.body, y0, ends, tol=Tolerances(rtol=1e-13, atol=1e-15)).Y[:, -1]
    cross = get_method("RATTLE-suzuki4").integrate(sc.body, y0, ends, tol=Tolerances(step=0.005)).Y[:, -1]
    return sc, ref, float(np.max(np.abs(cross - ref))), t_end


def _axes(quick: bool) -> dict:
    return {
        "gap": ("delta", QUICK_GAP_DELTAS if quick else GAP_DELTAS, _gap_reference, "relative_gap", GAP_T_END),
        "rho": ("p_rho", QUICK_RHO_P if quick else RHO_P, _rho_reference, "rho_min", RHO_T_END),
        "horizon": ("t_end", QUICK_HORIZONS if quick else HORIZONS, _horizon_reference, "t_end", None),
    }


def planned_runs(studies=STUDIES, methods=DEFAULT_METHODS, *, quick: bool = False) -> int:
    """Runs the study plans: one per method and axis value. :func:`failure_study` returns one point per
    run it made; the others were skipped, over the time budget (the reference runs are not counted)."""
    axes = _axes(quick)
    return sum(len(axes[s][1]) * len(methods) for s in studies)


def failure_study(
    studies=STUDIES,
    methods=DEFAULT_METHODS,
    *,
    quick: bool = False,
    repeats: int = 1,
    max_run_s: float = 10.0,
    progress: bool = True,
) -> list[FailurePoint]:
    """Run the studies; a method's sweep along an axis stops once a run exceeds ``max_run_s``
    (or, on the horizon axis, once the next run is predicted to). The progress bar counts the
    :func:`planned_runs`, skipped ones included."""
    from flatbody_env.integrators.compiled_methods import warm_up
    from flatbody_env.progress import progress_bar

    warm_up()  # load (or compile) the kernels before anything is timed
    axes = _axes(quick)
    bar = progress_bar(
        total=planned_runs(studies, methods, quick=quick), desc="failure study", unit="run", enabled=progress
    )
    out: list[FailurePoint] = []
    for study in studies:
        pname, values, make_ref, mname, t_fixed = axes[study]
        last_wall: dict[str, tuple[float, float]] = {}
        stopped: set[str] = set()
        for value in values:
            bar.set_postfix_str(f"{study} {pname}={value:g} reference")
            sc, ref, floor, measured = make_ref(value)
            t_end = t_fixed if t_fixed is not None else value
            for m in methods:
                bar.set_postfix_str(f"{study} {pname}={value:g} {m}")
                if m in stopped:
                    bar.update(1)
                    continue
                if study == "horizon" and m in last_wall:
                    w, t_prev = last_wall[m]
                    if w * value / t_prev > max_run_s:
                        stopped.add(m)
                        bar.update(1)
                        continue
                p = _run(study, m, sc, t_end, ref, floor, pname, float(value), mname, measured, repeats)
                out.append(p)
                last_wall[m] = (p.wall_time, t_end)
                if p.wall_time > max_run_s:
                    stopped.add(m)
                bar.update(1)
    bar.close()
    return out


__all__ = [
    "DEFAULT_METHODS",
    "FailurePoint",
    "STUDIES",
    "failure_study",
    "gap_scene",
    "planned_runs",
    "relative_gap_min",
    "rho_scene",
]
