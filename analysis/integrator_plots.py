"""Charts of the integrator studies, drawn from their saved CSV tables (matplotlib, Agg).

* :func:`plot_work_precision` — ``work_precision.csv`` (+ ``references.json``): one column per
  scene; top row wall time (min of repeats) against error, bottom row RHS evaluations against
  error; the reference's agreement floor as a grey band; failed runs as crosses on the top edge.
* :func:`plot_failure_study` — ``failure_study.csv``: one column per study (closest approach to
  λ = μ, ϱ_min, horizon); rows: final-state error (energy error for the horizon) and wall time.
* :func:`plot_bench` — ``bench_integrators.json``: speed-up bars and per-step costs, with a caption
  (:data:`BENCH_CAPTION`) naming the methods and what δ, the 100x line and (env)/(integrate) mean.
"""

from __future__ import annotations

import math
from pathlib import Path

from analysis.work_precision import read_csv
from flatbody_env.chart_text import add_caption
from flatbody_env.output import save_figure
from flatbody_env.physics import validation

_STYLE = {
    "RK23": ("#bbbbbb", "v"),
    "RK45": ("#999999", "^"),
    "DOP853": ("#000000", "o"),
    "Radau": ("#8c564b", "s"),
    "BDF": ("#c49c94", "s"),
    "LSODA": ("#7f7f7f", "D"),
    "DOP853-regular": ("#17becf", "o"),
    "DOP853-numba": ("#d62728", "o"),
    "RK4": ("#ff7f0e", "s"),
    "splitting-strang": ("#aec7e8", "^"),
    "splitting-suzuki4": ("#1f77b4", "^"),
    "splitting-yoshida4": ("#9467bd", "v"),
    "RATTLE": ("#98df8a", "D"),
    "RATTLE-suzuki4": ("#2ca02c", "D"),
    "RATTLE-kahanli6": ("#006400", "P"),
}


def _style(name):
    return _STYLE.get(name, ("#e377c2", "x"))


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(plt, fig, png_path) -> Path:
    """Write the figure as PNG (creating the folder) and close it."""
    png_path = Path(png_path)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, png_path, dpi=110)
    plt.close(fig)
    return png_path


def plot_work_precision(csv_path, png_path, references_json=None) -> Path:
    plt = _plt()
    rows = read_csv(csv_path)
    refs = {}
    if references_json and Path(references_json).exists():
        refs = {r["scene"]: r for r in validation.read_json("--plot-only", references_json)}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = plt.subplots(2, len(scenes), figsize=(4.6 * len(scenes), 9.4), squeeze=False)
    for j, sc in enumerate(scenes):
        sub = [r for r in rows if r["scene"] == sc]
        ek = sub[0]["error_kind"]
        for i, ykey in enumerate(("wall_time", "nfev")):
            ax = axes[i, j]
            for m in methods:
                pts = [r for r in sub if r["method"] == m]
                ok = [r for r in pts if r["status"] == "ok" and r["error"] > 0 and math.isfinite(r["error"])]
                color, marker = _style(m)
                if ok:
                    ok.sort(key=lambda r: r["error"])
                    ax.plot(
                        [r["error"] for r in ok],
                        [r[ykey] for r in ok],
                        marker=marker,
                        color=color,
                        ms=4,
                        lw=1.2,
                        label=m if j == 0 and i == 0 else None,
                    )
                bad = [r for r in pts if r["status"] not in ("ok", "skipped")]
                if bad and ykey == "wall_time":
                    ax.plot([1.0] * len(bad), [r[ykey] for r in bad], ls="none", marker="x", color=color, ms=6)
            ref = refs.get(sc)
            if ref is not None and ref["agreement"] > 0:
                ax.axvspan(1e-17, ref["agreement"], color="0.85", zorder=0)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="major", alpha=0.3)
            T = sub[0]["t_end"]
            if i == 0:
                floor = f"; ref. floor {ref['agreement']:.1e}" if ref is not None else ""
                ax.set_title(f"{sc} (t = {T:g}){floor}", fontsize=9)
                ax.set_ylabel("wall time [s] (min of repeats)")
            else:
                ax.set_ylabel("RHS / force evaluations")
            ax.set_xlabel("energy error max|H-H0|" if ek == "energy" else "final-state error (max norm)")
            ax.set_xlim(left=1e-15, right=3.0)
    bottom = add_caption(fig, WORK_PRECISION_CAPTION, fontsize=8)
    fig.legend(loc="lower center", ncol=min(7, len(methods)), fontsize=8, frameon=False, bbox_to_anchor=(0.5, bottom))
    fig.suptitle(
        "Work-precision: x = error vs reference (grey: below the reference's agreement floor), x at 1 = failed run",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, bottom + 0.06, 1, 0.96))
    return _save(plt, fig, png_path)


def plot_failure_study(csv_path, png_path) -> Path:
    plt = _plt()
    rows = read_csv(csv_path)
    studies = list(dict.fromkeys(r["study"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    labels = {"gap": "closest approach min (λ-μ)/λ", "rho": "ϱ_min", "horizon": "t_end"}
    fig, axes = plt.subplots(2, len(studies), figsize=(4.8 * len(studies), 9.0), squeeze=False)
    for j, st in enumerate(studies):
        sub = [r for r in rows if r["study"] == st]
        for i, key in enumerate(("error", "wall_time")):
            ax = axes[i, j]
            for m in methods:
                pts = sorted([r for r in sub if r["method"] == m], key=lambda r: r["measured"])
                color, marker = _style(m)
                ok = [r for r in pts if r["status"] == "ok"]
                if ok:
                    ax.plot(
                        [r["measured"] for r in ok],
                        [r[key] for r in ok],
                        marker=marker,
                        color=color,
                        ms=4,
                        lw=1.2,
                        label=m if i == 0 and j == 0 else None,
                    )
                bad = [r for r in pts if r["status"] != "ok"]
                if bad and key == "error":
                    ax.plot([r["measured"] for r in bad], [1.0] * len(bad), ls="none", marker="x", color=color, ms=7)
            if key == "error":
                floors = sorted({(r["measured"], r["reference_floor"]) for r in sub})
                ax.plot([f[0] for f in floors], [f[1] for f in floors], ls=":", color="0.5", lw=1)
                ax.set_ylabel("final-state error (x at 1: failure detected)")
                ax.set_title(f"{st}: {sub[0]['setting'] if sub else ''} / h=0.01 (dotted: reference floor)", fontsize=9)
            else:
                ax.set_ylabel("wall time [s]")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, alpha=0.3)
            ax.set_xlabel(labels.get(st, st))
            if st == "rho":
                ax.invert_xaxis()
                from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

                ax.xaxis.set_major_locator(FixedLocator([0.05, 0.1, 0.2, 0.5]))
                ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
                ax.xaxis.set_minor_formatter(NullFormatter())
            if st == "gap":
                ax.invert_xaxis()
    bottom = add_caption(fig, FAILURE_CAPTION, fontsize=8)
    fig.legend(loc="lower center", ncol=min(8, len(methods)), fontsize=8, frameon=False, bbox_to_anchor=(0.5, bottom))
    fig.suptitle("Where methods fail: adaptive rtol 1e-10, fixed step h = 0.01 (harder to the right)", fontsize=10)
    fig.tight_layout(rect=(0, bottom + 0.07, 1, 0.96))
    return _save(plt, fig, png_path)


METHODS_CAPTION = (
    "Methods: DOP853, RK45, Radau, LSODA: scipy solve_ivp (adaptive; DOP853 = Dormand-Prince order 8); DOP853-numba: "
    "the same DOP853 compiled with numba; DOP853-regular: scipy DOP853 on the regular chart;\n"
    "RK4: classical Runge-Kutta, fixed step; splitting-*: Poisson splitting with exact sub-flows (strang order 2, "
    "suzuki4/yoshida4 order 4); RATTLE-*: constrained symplectic RATTLE on the regular chart (plain order 2, suzuki4 order 4, "
    "kahanli6 order 6).\n"
    "Charts (coordinates, docs/physics.md): two-polar (λ+μ, λ-μ; singular where λ = μ) and regular (Φ = [φ1, φ2, ψ]; "
    "not singular there).\n"
)
"""The caption lines naming the integrators (shared by the integrator charts)."""

BENCH_CAPTION = (
    METHODS_CAPTION
    + "Left: speed-up = scipy DOP853's wall time / the method's, both at the same final-state error (log-log interpolation "
    "between settings); the dotted line marks 100x, two orders of magnitude.\n"
    "Middle: δ = σ₋ = s3 - p_θ of the close-approach scene (smaller δ: λ and μ come closer, where the two-polar coordinates "
    "are singular); methods that never reach the error are left out.\n"
    "Right: one call for one step dt = 0.05 of the default scene; (integrate): through integrate(), (env): through the "
    "compiled environment stepper. Wall times: min of repeats, one process."
)
"""The integrator benchmark chart's caption: the methods, δ, the 100x line, (env)/(integrate)."""

WORK_PRECISION_CAPTION = (
    METHODS_CAPTION
    + "Error: max norm of y(T) - y_ref(T) over the state (long-horizon: the energy drift max|H - H0|); ref. floor: the agreement "
    "of two independent references, smaller errors are not resolved (grey band).\n"
    "Each line sweeps the method's setting (rtol for adaptive methods, step h for fixed-step ones); wall time: min of repeats; "
    "RHS / force evaluations: calls of the right-hand side (of the force for splitting and RATTLE)."
)
"""The work-precision chart's caption: the methods, the error, the floor, the evaluations."""

FAILURE_CAPTION = (
    METHODS_CAPTION
    + "gap: the close-approach scene with λ and μ coming ever closer (x axis: the smallest (λ-μ)/λ of the run); rho: the "
    "small-ϱ bounce with ever thinner ϱ_min; horizon: the regular scene to ever longer t_end.\n"
    "rtol: relative tolerance of the adaptive methods; h: step of the fixed-step ones. Error: max norm of y(T) - y_ref(T) "
    "(dotted: the reference's floor, smaller errors are not resolved); x at 1: the run failed (detected)."
)
"""The failure-study chart's caption: the methods, the three studies, rtol/h, the error."""


def plot_bench(json_path, png_path) -> Path:
    """``bench_integrators.json`` → three bar panels (speed-up, close approach, one short step), x axes
    labelled, the 100x reference line in a legend, the jargon in :data:`BENCH_CAPTION`."""
    plt = _plt()
    data = validation.read_json("--plot-only", json_path)
    fig, axes = plt.subplots(1, 3, figsize=(16, 6.6))
    reg = data["regular"]
    sp = reg["at_target"]
    names = [r["method"] for r in sp if r.get("speedup")]
    axes[0].barh(names, [r["speedup"] for r in sp if r.get("speedup")], color=[_style(n)[0] for n in names])
    axes[0].axvline(100, color="k", ls=":", lw=1, label="100x faster than scipy DOP853")
    axes[0].set_xscale("log")
    axes[0].set_xlabel(f"speed-up over scipy DOP853 at final-state error {reg['target_error']:g} (x, higher is better)")
    axes[0].set_title(f"regular scene, t = {reg['t_end']:g}: speed-up vs scipy DOP853", fontsize=9)
    axes[0].legend(loc="lower right", fontsize=8)
    ca = data["close_approach"]
    labels, vals = [], []
    for case in ca:
        for r in case["at_target"]:
            if r.get("wall_time"):
                labels.append(f"δ={case['delta']:g} {r['method']}")
                vals.append(r["wall_time"] * 1e3)
    axes[1].barh(labels, vals, color=[_style(lbl.split(" ", 1)[1])[0] for lbl in labels])
    axes[1].set_xscale("log")
    target = ca[0].get("target_error") if ca else None
    axes[1].set_xlabel(
        "wall time [ms]" + (f" to final-state error {target:g}" if target else "") + " (lower is better)"
    )
    axes[1].set_title(
        "close approach, t = " + (f"{ca[0]['t_end']:g}" if ca else "?") + ": wall time at equal error", fontsize=9
    )
    axes[1].tick_params(axis="y", labelsize=7)
    st = data["short_step"]
    labels = [r["method"] + (" (env)" if r["path"] == "env" else " (integrate)") for r in st]
    axes[2].barh(labels, [r["us_per_step"] for r in st], color=[_style(r["method"])[0] for r in st])
    axes[2].set_xscale("log")
    axes[2].set_xlabel("µs per call (one step dt = 0.05, lower is better)")
    axes[2].set_title("one short step dt = 0.05", fontsize=9)
    axes[2].tick_params(axis="y", labelsize=7)
    bottom = add_caption(fig, BENCH_CAPTION, fontsize=7.5)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    return _save(plt, fig, png_path)


__all__ = ["plot_bench", "plot_failure_study", "plot_work_precision"]
