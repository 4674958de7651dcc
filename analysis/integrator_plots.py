"""Charts of the integrator studies, drawn from their saved CSV tables (matplotlib, Agg).

* :func:`plot_work_precision` — ``work_precision.csv`` (+ ``references.json``): one column per
  scene; top row wall time (min of repeats) against error, middle row RHS evaluations against
  error; the reference's agreement floor as a grey band; under each column the runs that failed
  (method, settings, failure kinds) or were skipped.
* :func:`plot_failure_study` — ``failure_study.csv``: one column per study (closest approach to
  λ = μ, ϱ_min, horizon); rows: final-state error (energy error for the horizon) and wall time.
* :func:`plot_bench` — ``bench_integrators.json``: speed-up bars and per-step costs, with a caption
  (:data:`BENCH_CAPTION`) naming the methods and what δ, the 100x line and (env)/(integrate) mean;
  a method without a bar says why (its failure kinds, or the error not reached).
"""

from __future__ import annotations

import math
from pathlib import Path

from analysis.work_precision import read_csv
from flatbody_env.figures import FONTS, PALETTE, chart
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
"""Each integrator's colour and marker on every integrator chart."""


def _style(name):
    return _STYLE.get(name, ("#e377c2", "x"))


def _kinds(statuses) -> str:
    """``chart-singularity ×5, under-resolved ×1`` for a list of failure statuses, most frequent first."""
    counts: dict[str, int] = {}
    for s in statuses:
        counts[s] = counts.get(s, 0) + 1
    return ", ".join(f"{k} ×{n}" if n > 1 else k for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))


def failed_runs_text(rows, width: int = 70) -> str:
    """What did not run to the end in one scene's rows of ``work_precision.csv``, one method a line: which settings
    failed and how (the failure kinds), and which were skipped (predicted over the time budget)."""
    import textwrap

    lines = []
    for label, select in (
        ("failed", lambda r: r["status"] not in ("ok", "skipped")),
        ("skipped (predicted over the time budget)", lambda r: r["status"] == "skipped"),
    ):
        by_method: dict[str, list] = {}
        for r in rows:
            if select(r):
                by_method.setdefault(r["method"], []).append(r)
        if not by_method:
            continue
        lines.append(f"{label}:")
        for m, bad in by_method.items():
            total = sum(1 for r in rows if r["method"] == m)
            settings = [r["setting"] for r in bad]
            where = settings[0] if len(settings) == 1 else f"{settings[0]} … {settings[-1]}"
            kinds = "" if label.startswith("skipped") else f": {_kinds(r['status'] for r in bad)}"
            text = f"{m}, {len(bad)} of {total} settings ({where}){kinds}"
            lines += textwrap.wrap(text, width, initial_indent="  ", subsequent_indent="      ", break_on_hyphens=False)
    return "\n".join(lines) if lines else "every run reached t_end"


def plot_work_precision(csv_path, png_path, references_json=None) -> Path:
    """``work_precision.csv`` (+ ``references.json``): one column per scene, wall time (top) and RHS evaluations
    (middle) against the error; the runs that failed or were skipped listed under each column (bottom)."""
    rows = read_csv(csv_path)
    refs = {}
    if references_json and Path(references_json).exists():
        refs = {r["scene"]: r for r in validation.read_json("--plot-only", references_json)}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    with chart(
        png_path,
        size=(4.6 * len(scenes), 10.6),
        nrows=3,
        ncols=len(scenes),
        gridspec_kw={"height_ratios": [1, 1, 0.42]},
    ) as c:
        for j, sc in enumerate(scenes):
            sub = [r for r in rows if r["scene"] == sc]
            ek = sub[0]["error_kind"]
            ref = refs.get(sc)
            for i, ykey in enumerate(("wall_time", "nfev")):
                ax = c.axes[i, j]
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
                            label=m,
                        )
                if ref is not None and ref["agreement"] > 0:
                    ax.axvspan(1e-17, ref["agreement"], color=PALETTE["band"], zorder=0)
                ax.set_xscale("log")
                ax.set_yscale("log")
                ax.grid(True, which="major", alpha=0.3)
                if i == 0:
                    floor = f"; ref. floor {ref['agreement']:.1e}" if ref is not None else ""
                    ax.set_title(f"{sc} (t = {sub[0]['t_end']:g}){floor}", fontsize=FONTS["base"])
                    ax.set_ylabel("wall time [s] (min of repeats)")
                else:
                    ax.set_ylabel("RHS / force evaluations")
                ax.set_xlabel("energy error max|H-H0|" if ek == "energy" else "final-state error (max norm)")
                ax.set_xlim(left=1e-15, right=3.0)
            note = c.axes[2, j]
            note.axis("off")
            note.text(
                0.0,
                1.0,
                failed_runs_text(sub),
                transform=note.transAxes,
                ha="left",
                va="top",
                fontsize=FONTS["tiny"],
                color="0.15",
                linespacing=1.3,
            )
        c.legend(where="below", ncol=min(7, len(methods)))
        c.title(
            "Work-precision: error against cost per method (grey: below the reference's agreement floor); "
            "under each column: the runs that failed or were skipped"
        )
        c.caption(WORK_PRECISION_CAPTION, fontsize=8)
    return Path(png_path)


def plot_failure_study(csv_path, png_path) -> Path:
    """``failure_study.csv``: one column per study; final-state error (top, failures drawn at 1) and wall time."""
    rows = read_csv(csv_path)
    studies = list(dict.fromkeys(r["study"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    labels = {"gap": "closest approach min (λ-μ)/λ", "rho": "ϱ_min", "horizon": "t_end"}
    with chart(png_path, size=(4.8 * len(studies), 9.4), nrows=2, ncols=len(studies)) as c:
        for j, st in enumerate(studies):
            sub = [r for r in rows if r["study"] == st]
            for i, key in enumerate(("error", "wall_time")):
                ax = c.axes[i, j]
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
                            label=m,
                        )
                    bad = [r for r in pts if r["status"] != "ok"]
                    if bad and key == "error":
                        ax.plot(
                            [r["measured"] for r in bad], [1.0] * len(bad), ls="none", marker="x", color=color, ms=7
                        )
                if key == "error":
                    floors = sorted({(r["measured"], r["reference_floor"]) for r in sub})
                    ax.plot([f[0] for f in floors], [f[1] for f in floors], ls=":", color="0.5", lw=1)
                    ax.set_ylabel("final-state error (x at 1: failure detected)")
                    ax.set_title(
                        f"{st}: {sub[0]['setting'] if sub else ''} / h=0.01 (dotted: reference floor)",
                        fontsize=FONTS["base"],
                    )
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
        c.legend(where="below", ncol=min(8, len(methods)))
        c.title("Where methods fail: adaptive rtol 1e-10, fixed step h = 0.01 (harder to the right)")
        c.caption(FAILURE_CAPTION, fontsize=8)
    return Path(png_path)


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
    "are singular); ✗: the method never reaches the error (its failure kinds, or not bracketed).\n"
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


def _why_not(curve) -> str:
    """Why a method has no wall time at the target error: the failure kinds of its runs, or not reached."""
    bad = [c["status"] for c in curve if c["status"] != "ok"]
    if bad and len(bad) == len(curve):
        return "fails: " + _kinds(bad)
    return "does not reach the error" + (f" ({_kinds(bad)} at some settings)" if bad else "")


def _missing(ax, ys, texts) -> None:
    """At rows ``ys`` of a bar panel (log x): a hollow marker at the left edge and why the bar is missing."""
    x0 = ax.get_xlim()[0]
    for y, text in zip(ys, texts, strict=True):
        ax.annotate(
            "✗ " + text,
            (x0, y),
            xytext=(4, 0),
            textcoords="offset points",
            va="center",
            ha="left",
            fontsize=FONTS["tiny"],
            color=PALETTE["bad"],
        )


def plot_bench(json_path, png_path) -> Path:
    """``bench_integrators.json`` → three bar panels (speed-up, close approach, one short step), x axes
    labelled, the 100x reference line in a legend, every method of a panel on it (a missing bar says why),
    the jargon in :data:`BENCH_CAPTION`."""
    data = validation.read_json("--plot-only", json_path)
    with chart(png_path, size=(16, 7.2), ncols=3) as c:
        ax0, ax1, ax2 = c.axes[0]
        reg = data["regular"]
        sp = reg["at_target"]
        names = [r["method"] for r in sp]
        values = [r["speedup"] or 0.0 for r in sp]
        ax0.barh(names, values, color=[_style(n)[0] for n in names])
        for y, v in enumerate(values):
            if v:
                ax0.text(v, y, f" {v:.3g}×", va="center", fontsize=FONTS["small"])
        ax0.axvline(100, color="k", ls=":", lw=1, label="100x faster than scipy DOP853")
        ax0.set_xscale("log")
        ax0.set_xlim(0.3, 6 * max([100.0, *values]))
        gone = [(n, _why_not(reg["curves"].get(n, []))) for n, r in zip(names, sp, strict=True) if not r["speedup"]]
        _missing(ax0, [names.index(n) for n, _ in gone], [w for _, w in gone])
        ax0.set_xlabel(f"speed-up over scipy DOP853 at final-state error {reg['target_error']:g} (x, higher is better)")
        ax0.set_title(f"regular scene, t = {reg['t_end']:g}: speed-up vs scipy DOP853", fontsize=FONTS["base"])
        ca = data["close_approach"]
        labels, vals, colours, gone_y, gone_why = [], [], [], [], []
        for case in ca:
            for r in case["at_target"]:
                y = len(labels)
                labels.append(f"δ={case['delta']:g}  {r['method']}")
                vals.append(r["wall_time"] * 1e3 if r.get("wall_time") else 0.0)
                colours.append(_style(r["method"])[0])
                if not r.get("wall_time"):
                    gone_y.append(y)
                    gone_why.append(_why_not(case["curves"].get(r["method"], [])))
        ax1.barh(range(len(labels)), vals, color=colours)
        ax1.set_yticks(range(len(labels)), labels)
        ax1.set_xscale("log")
        ax1.set_xlim(0.2, 30 * max([1.0, *vals]))
        for k in range(1, len(ca)):
            ax1.axhline(k * len(ca[0]["at_target"]) - 0.5, color="0.6", lw=0.8)
        _missing(ax1, gone_y, gone_why)
        ax1.invert_yaxis()
        target = ca[0].get("target_error") if ca else None
        ax1.set_xlabel(
            "wall time [ms]" + (f" to final-state error {target:g}" if target else "") + " (lower is better)"
        )
        ax1.set_title(
            "close approach, t = " + (f"{ca[0]['t_end']:g}" if ca else "?") + ": wall time at equal error",
            fontsize=FONTS["base"],
        )
        ax1.tick_params(axis="y", labelsize=FONTS["tiny"])
        st = data["short_step"]
        labels = [r["method"] + (" (env)" if r["path"] == "env" else " (integrate)") for r in st]
        ax2.barh(labels, [r["us_per_step"] for r in st], color=[_style(r["method"])[0] for r in st])
        ax2.set_xscale("log")
        ax2.set_xlabel("µs per call (one step dt = 0.05, lower is better)")
        ax2.set_title("one short step dt = 0.05", fontsize=FONTS["base"])
        ax2.tick_params(axis="y", labelsize=FONTS["tiny"])
        c.legend(where="below")
        c.caption(BENCH_CAPTION)
    return Path(png_path)


__all__ = ["failed_runs_text", "plot_bench", "plot_failure_study", "plot_work_precision"]
