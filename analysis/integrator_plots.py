"""Charts of the integrator studies, drawn from their saved CSV tables (matplotlib, Agg).

* :func:`plot_work_precision` — ``work_precision.csv`` (+ ``references.json``): one column per
  scene; top row wall time (min of repeats) against error, bottom row RHS evaluations against
  error; the reference's agreement floor as a grey band; failed runs as crosses on the top edge.
* :func:`plot_failure_study` — ``failure_study.csv``: one column per study (closest approach to
  λ = μ, ϱ_min, horizon); rows: final-state error (energy error for the horizon) and wall time.
* :func:`plot_bench` — ``bench_integrators.json``: speed-up bars and per-step costs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from analysis.work_precision import read_csv
from flatbody_env.output import save_figure

_STYLE = {
    "RK23": ("#bbbbbb", "v"), "RK45": ("#999999", "^"), "DOP853": ("#000000", "o"), "Radau": ("#8c564b", "s"),
    "BDF": ("#c49c94", "s"), "LSODA": ("#7f7f7f", "D"),
    "DOP853-regular": ("#17becf", "o"),
    "DOP853-numba": ("#d62728", "o"), "RK4": ("#ff7f0e", "s"),
    "splitting-strang": ("#aec7e8", "^"), "splitting-suzuki4": ("#1f77b4", "^"), "splitting-yoshida4": ("#9467bd", "v"),
    "RATTLE": ("#98df8a", "D"), "RATTLE-suzuki4": ("#2ca02c", "D"), "RATTLE-kahanli6": ("#006400", "P"),
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
        refs = {r["scene"]: r for r in json.loads(Path(references_json).read_text(encoding="utf-8"))}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = plt.subplots(2, len(scenes), figsize=(4.6 * len(scenes), 8.2), squeeze=False)
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
                    ax.plot([r["error"] for r in ok], [r[ykey] for r in ok], marker=marker, color=color, ms=4, lw=1.2,
                            label=m if j == 0 and i == 0 else None)
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
    fig.legend(loc="lower center", ncol=min(7, len(methods)), fontsize=8, frameon=False)
    fig.suptitle("Work-precision: x = error vs reference (grey: below the reference's agreement floor), "
                 "x at 1 = failed run", fontsize=10)
    fig.tight_layout(rect=(0, 0.06, 1, 0.96))
    return _save(plt, fig, png_path)


def plot_failure_study(csv_path, png_path) -> Path:
    plt = _plt()
    rows = read_csv(csv_path)
    studies = list(dict.fromkeys(r["study"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    labels = {"gap": "closest approach min (λ-μ)/λ", "rho": "ϱ_min", "horizon": "t_end"}
    fig, axes = plt.subplots(2, len(studies), figsize=(4.8 * len(studies), 7.8), squeeze=False)
    for j, st in enumerate(studies):
        sub = [r for r in rows if r["study"] == st]
        for i, key in enumerate(("error", "wall_time")):
            ax = axes[i, j]
            for m in methods:
                pts = sorted([r for r in sub if r["method"] == m], key=lambda r: r["measured"])
                color, marker = _style(m)
                ok = [r for r in pts if r["status"] == "ok"]
                if ok:
                    ax.plot([r["measured"] for r in ok], [r[key] for r in ok], marker=marker, color=color, ms=4, lw=1.2,
                            label=m if i == 0 and j == 0 else None)
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
    fig.legend(loc="lower center", ncol=min(8, len(methods)), fontsize=8, frameon=False)
    fig.suptitle("Where methods fail: adaptive rtol 1e-10, fixed step h = 0.01 (harder to the right)", fontsize=10)
    fig.tight_layout(rect=(0, 0.06, 1, 0.96))
    return _save(plt, fig, png_path)


def plot_bench(json_path, png_path) -> Path:
    plt = _plt()
    data = json.loads(Path(json_path).read_text(encoding="utf-8"))
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    sp = data["regular"]["at_target"]
    names = [r["method"] for r in sp if r.get("speedup")]
    axes[0].barh(names, [r["speedup"] for r in sp if r.get("speedup")], color=[_style(n)[0] for n in names])
    axes[0].axvline(100, color="k", ls=":", lw=1)
    axes[0].set_xscale("log")
    axes[0].set_title(f"regular, t={data['regular']['t_end']:g}: speed-up vs scipy DOP853 at error {data['regular']['target_error']:g}", fontsize=9)
    ca = data["close_approach"]
    labels, vals = [], []
    for case in ca:
        for r in case["at_target"]:
            if r.get("wall_time"):
                labels.append(f"δ={case['delta']:g} {r['method']}")
                vals.append(r["wall_time"] * 1e3)
    axes[1].barh(labels, vals, color=[_style(lbl.split(' ', 1)[1])[0] for lbl in labels])
    axes[1].set_xscale("log")
    axes[1].set_title("close approach: wall time [ms] at equal error", fontsize=9)
    axes[1].tick_params(axis="y", labelsize=7)
    st = data["short_step"]
    labels = [r["method"] + (" (env)" if r["path"] == "env" else " (integrate)") for r in st]
    axes[2].barh(labels, [r["us_per_step"] for r in st], color=[_style(r["method"])[0] for r in st])
    axes[2].set_xscale("log")
    axes[2].set_title("one short step dt=0.05 [µs]", fontsize=9)
    axes[2].tick_params(axis="y", labelsize=7)
    fig.tight_layout()
    return _save(plt, fig, png_path)


__all__ = ["plot_bench", "plot_failure_study", "plot_work_precision"]
