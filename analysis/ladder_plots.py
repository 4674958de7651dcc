"""The chart of the model ladder, drawn from the saved tables of :mod:`analysis.ladder` (matplotlib, Agg).

:func:`plot_ladder` — ``ladder.csv`` + ``ladder_scenes.csv``: one panel per built-in scene, wall time
(min of repeats) against final-state error for every rung that applies, the rung ``model="auto"``
chooses drawn thick and named in the title, the reference's agreement floor as a grey band, failed
runs as crosses on the right edge; an error of exactly 0 (the exact rungs against themselves) is drawn at 1e-16.
A caption under the legend (:data:`CAPTION`) says what a rung, ``auto``, each model and the floor are.
"""

from __future__ import annotations

import math
from pathlib import Path

from analysis.ladder import read_csv
from flatbody_env.figures import FONTS, PALETTE, chart

RUNG_STYLE = {
    "stationary": ("#2ca02c", "*"),
    "planar-V1": ("#9467bd", "D"),
    "planar": ("#1f77b4", "o"),
    "two-polar": ("#d62728", "s"),
    "regular": ("#7f7f7f", "^"),
}
_DASHED = ("DOP853",)
"""Methods drawn dotted with open markers (scipy, ``simulate``'s default)."""
_LABELS = {
    "DOP853": "two-polar (scipy DOP853, simulate's default)",
    "two-polar": "two-polar (DOP853-numba)",
    "regular": "regular (RATTLE-kahanli6)",
    "planar": "planar (2 small DOP853)",
    "planar-V1": "planar-V1 (exact in-plane)",
    "stationary": "stationary (exact)",
}
CAPTION = (
    "Rung: one model of the same body, simplest first. stationary: the closed-form motion of a stationary ellipse; "
    "planar-V1: closed form in the plane (potential V1) + compiled DOP853 for the thickness ϱ;\n"
    "planar: two small systems (motion that stays in the plane), compiled DOP853; two-polar: the full model in two-polar "
    "coordinates (compiled DOP853-numba; dotted: scipy DOP853, simulate's default method);\n"
    "regular: the full model in the regular chart, RATTLE-kahanli6 (constrained symplectic, order 6). "
    "auto: the rung simulate(model='auto') picks for the scene (drawn thick, named in each title).\n"
    "Final-state error: max |y(T) - y_ref(T)| over the 11 state variables; grey band: below the scene's floor "
    "(agreement of two independent references: smaller errors are not resolved). Wall time: min of repeats."
)
"""The ladder chart's caption: the jargon of its titles and legend."""


def _horizon_panel(ax, rows) -> None:
    """Wall time against t for the horizon rows (``"<scene> t=<T>"``); each point labelled with its final-state
    error: the rising (time-stepper) curve above-left of its points, the flat one below its points."""
    for rung, offset, ha, va in (("stationary", (0, -8), "center", "top"), ("two-polar", (-6, 4), "right", "bottom")):
        pts = sorted([r for r in rows if r["rung"] == rung and r["status"] == "ok"], key=lambda r: r["t_end"])
        if pts:
            color, marker = RUNG_STYLE[rung]
            ax.plot([r["t_end"] for r in pts], [r["wall_time"] for r in pts], marker=marker, color=color, lw=1.5)
            for r in pts:
                ax.annotate(
                    f"{r['error']:.0e}",
                    (r["t_end"], r["wall_time"]),
                    fontsize=7,
                    xytext=offset,
                    textcoords="offset points",
                    ha=ha,
                    va=va,
                    color=color,
                )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.margins(x=0.15, y=0.12)
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("horizon t (labels: final-state error)")
    ax.set_title(f"{rows[0]['scene'].split(' t=')[0]}: cost against horizon", fontsize=FONTS["base"])


def plot_ladder(csv_path, scenes_csv, png_path) -> Path:
    """``ladder.csv`` + ``ladder_scenes.csv``: one panel per scene (module docstring), the horizon panel last."""
    rows = read_csv(csv_path)
    scenes = {r["scene"]: r for r in read_csv(scenes_csv)}
    horizon = [r for r in rows if " t=" in r["scene"]]
    rows = [r for r in rows if " t=" not in r["scene"]]
    names = list(dict.fromkeys(r["scene"] for r in rows))
    ncol = 4
    nrow = math.ceil((len(names) + (1 if horizon else 0)) / ncol)
    with chart(png_path, size=(4.4 * ncol, 3.6 * nrow + 1.6), nrows=nrow, ncols=ncol) as c:
        axes = c.axes
        seen = set()
        for k, name in enumerate(names):
            ax = axes[k // ncol, k % ncol]
            sub = [r for r in rows if r["scene"] == name]
            chosen = scenes[name]["chosen"] if name in scenes else sub[0]["chosen"]
            series = [
                (rung, method)
                for rung in RUNG_STYLE
                for method in dict.fromkeys(r["method"] for r in sub if r["rung"] == rung)
            ]
            for rung, method in series:
                pts = [r for r in sub if r["rung"] == rung and r["method"] == method]
                color, marker = RUNG_STYLE[rung]
                dashed = method in _DASHED
                key = _LABELS.get(method, _LABELS[rung])
                ok = sorted(
                    [r for r in pts if r["status"] == "ok" and math.isfinite(r["error"])], key=lambda r: r["error"]
                )
                if ok:
                    ax.plot(
                        [max(r["error"], 1e-16) for r in ok],
                        [r["wall_time"] for r in ok],
                        marker=marker,
                        color=color,
                        lw=3.0 if rung == chosen and not dashed else 1.2,
                        ms=9 if rung == "stationary" else 5,
                        label=key if key not in seen else None,
                        ls=":" if dashed else "-",
                        mfc="none" if dashed else color,
                    )
                    seen.add(key)
                bad = [r for r in pts if r["status"] not in ("ok", "skipped")]
                if bad:
                    ax.plot([3.0] * len(bad), [r["wall_time"] for r in bad], ls="none", marker="x", color=color, ms=7)
            floor = scenes.get(name, {}).get("floor", math.nan)
            if isinstance(floor, float) and math.isfinite(floor) and floor > 0:
                ax.axvspan(1e-16, floor, color=PALETTE["band"], zorder=0)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlim(3e-17, 10.0)
            ax.grid(True, alpha=0.3)
            title = (
                f"{name}: auto -> {chosen}" if " t=" in name else f"{name} (t = {sub[0]['t_end']:g}): auto -> {chosen}"
            )
            ax.set_title(title, fontsize=FONTS["base"])
            if k % ncol == 0:
                ax.set_ylabel("wall time [s]")
            if k // ncol == nrow - 1:
                ax.set_xlabel("final-state error")
        if horizon:
            k = len(names)
            _horizon_panel(axes[k // ncol, k % ncol], horizon)
            names.append("horizon")
        for k in range(len(names), nrow * ncol):
            axes[k // ncol, k % ncol].axis("off")
        c.legend(where="below", ncol=6, fontsize=FONTS["base"])
        c.title(
            "A ladder of models: error against cost per rung (thick: the rung model='auto' picks; grey: below the "
            "reference's agreement floor; x at the right: failed)"
        )
        c.caption(CAPTION, fontsize=8)
    return Path(png_path)


__all__ = ["RUNG_STYLE", "plot_ladder"]
