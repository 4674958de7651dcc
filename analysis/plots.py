"""Charts drawn from saved tables (matplotlib, Agg backend); no analysis happens here.

:func:`plot_family` reads a family CSV (:func:`analysis.families.write_family_csv`) and draws λ
and μ against the varied parameter, each point coloured by its stability classification, with
folds and stability changes marked; a second panel shows the largest real part of the
eigenvalues (the growth rate of the unstable ones). :func:`plot_shape_map` draws a shape stability map.
Each chart carries a caption (:data:`FAMILY_CAPTION`, :data:`SHAPE_MAP_CAPTION`) that says what branch N,
the classifications and the energy–Casimir test are.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.families import read_family_csv
from flatbody_env.figures import PALETTE, chart, log_axis_if_decades
from flatbody_env.physics import validation

COLOURS = {"elliptic": PALETTE["ours"], "hyperbolic": PALETTE["bad"], "degenerate": PALETTE["yardstick"]}
LABELS = {
    "elliptic": "elliptic (spectrally stable)",
    "hyperbolic": "hyperbolic (unstable)",
    "degenerate": "degenerate (inconclusive)",
}

FAMILY_CAPTION = (
    "Branch N (the paper's stationary motions, eqs. 52-54; docs/physics.md §8): the ellipse turns rigidly about the plate's\n"
    "normal with s1 = s2 = 0, ω1 = ω2 = 0, p_λ = p_μ = p_ϱ = 0 (isotropic J1 = J2); s3: spin about the normal, "
    "p_θ: material momentum.\n"
    "Elliptic: every eigenvalue of the linearisation on the imaginary axis (spectrally stable); hyperbolic: one with\n"
    "positive real part (unstable; max Re(eigenvalue) is its growth rate). Fold: two stationary ellipses merge."
)
"""The family chart's caption: branch N, the classifications, the lower panel."""

SHAPE_MAP_CAPTION = (
    "energy-Casimir: the energy-Casimir test certifies nonlinear (Lyapunov) stability: the Hessian of H - a|s|² - b p_θ "
    "restricted to\nfixed |s|² and p_θ is definite (filled squares); hollow: spectrally stable only (that form is indefinite or "
    "the test does not apply).\n"
    "Elliptic / hyperbolic: every eigenvalue of the linearisation on the imaginary axis / one with positive real part. "
    "Each shape (stretches λ, μ)\nis stationary (branch N: turning about the plate's normal) for two pairs of spins: "
    "rigid-like |s3| > |p_θ| (spin s3 dominates) and circulating |p_θ| > |s3|\n(material momentum p_θ dominates)."
)
"""The shape map's caption: energy–Casimir, the classifications, the two panels."""


def plot_family(csv_path: str | Path, png_path: str | Path, *, title: str | None = None) -> Path:
    """Draw the family chart of ``csv_path`` into ``png_path`` (PNG) and return the path; a parameter whose
    values are positive and span more than two decades (J from 1e-6 to 1e6) is drawn on a log axis."""
    rows = read_family_csv(csv_path)
    points = [r for r in rows if not r["event"]]
    events = [r for r in rows if r["event"]]
    if not points:
        raise ValueError(f"family: {Path(csv_path).name} holds no points (no stationary ellipse in the range)")
    pname = points[0]["param_name"]
    with chart(png_path, size=(7.5, 8.4), nrows=2, sharex=True, gridspec_kw={"height_ratios": [3, 1.3]}) as c:
        ax, ax2 = c.axes[0, 0], c.axes[1, 0]
        branches = sorted({r["branch"] for r in points})
        seen: set[str] = set()
        for b in branches:
            pts = [r for r in points if r["branch"] == b]
            p = np.array([r["param"] for r in pts])
            lam = np.array([r["lambda"] for r in pts])
            mu = np.array([r["mu"] for r in pts])
            mre = np.array([r["max_real_part"] for r in pts])
            cls = [r["classification"] for r in pts]
            ax.plot(p, lam, "-", color=PALETTE["neutral"], lw=1, zorder=1)
            ax.plot(p, mu, "--", color=PALETTE["neutral"], lw=1, zorder=1)
            ax2.plot(p, mre, "-", color=PALETTE["neutral"], lw=1, zorder=1)
            for cl in COLOURS:
                m = np.array([x == cl for x in cls])
                if not m.any():
                    continue
                label = LABELS[cl] if cl not in seen else None
                seen.add(cl)
                ax.scatter(p[m], lam[m], s=12, color=COLOURS[cl], marker="o", label=label, zorder=2)
                ax.scatter(p[m], mu[m], s=12, color=COLOURS[cl], marker="s", zorder=2)
                ax2.scatter(p[m], mre[m], s=10, color=COLOURS[cl], zorder=2)
        for ev in events:
            if ev["event"] == "fold":
                ax.plot([ev["param"]], [ev["lambda"]], "k*", ms=11, zorder=3)
                ax.plot([ev["param"]], [ev["mu"]], "k*", ms=11, zorder=3)
            else:
                ax.axvline(ev["param"], color="k", lw=0.7, ls=":", zorder=0)
                ax2.axvline(ev["param"], color="k", lw=0.7, ls=":", zorder=0)
        ax.plot([], [], "ko", ms=4, label="λ (circles)")
        ax.plot([], [], "ks", ms=4, label="μ (squares)")
        if any(ev["event"] == "fold" for ev in events):
            ax.plot([], [], "k*", ms=9, label="fold")
        if any(ev["event"] == "stability-change" for ev in events):
            ax.plot([], [], "k:", lw=0.8, label="stability change")
        log = log_axis_if_decades(ax2, [r["param"] for r in points])
        ax.set_ylabel("stretches λ, μ")
        ax.grid(alpha=0.3)
        ax2.set_ylabel("max Re(eigenvalue)")
        name = {"s3": "s3", "p_theta": "p_θ"}.get(pname, pname)
        ax2.set_xlabel(name + (" (log scale)" if log else ""))
        ax2.grid(alpha=0.3, which="both" if log else "major")
        first = points[0]
        if title is None:
            fixed = [] if pname == "s3" else [f"s3 = {first['s3']:g}"]
            fixed += [] if pname == "p_theta" else [f"p_θ = {first['p_theta']:g}"]
            title = f"Stationary ellipses (branch N) vs {name}" + (f", {', '.join(fixed)}" if fixed else "")
        ax.set_title(title)
        c.legend(where="below", ncol=3)
        c.caption(FAMILY_CAPTION, fontsize=7)
    return Path(png_path)


def plot_shape_map(csv_path: str | Path, png_path: str | Path, *, title: str | None = None) -> Path:
    """Draw a shape stability map (CSV of :func:`analysis.families.shape_stability_grid`): one panel per kind
    (rigid-like, circulating), each shape (λ, μ) coloured by classification; energy–Casimir certified
    stable points filled, spectrally stable but uncertified ones hollow."""
    path = Path(csv_path)
    if not path.exists():
        raise ValueError(f"map: no file {str(path)!r}")
    rows = validation.read_csv("map", path)  # the one reading door
    if not rows or "classification" not in rows[0]:
        raise ValueError(f"map: {path.name} holds no shape rows")
    with chart(png_path, size=(10, 6.2), ncols=2, sharey=True) as c:
        for ax, kind in zip(c.axes[0], ("rigid", "circulating"), strict=True):
            sel = [r for r in rows if r["kind"] == kind]
            for cl, colour in COLOURS.items():
                for certified in (True, False):
                    pts = [r for r in sel if r["classification"] == cl and ((r["nonlinear"] == "stable") == certified)]
                    if not pts:
                        continue
                    label = LABELS[cl] + (" + energy-Casimir" if certified and cl == "elliptic" else "")
                    ax.scatter(
                        [float(r["lambda"]) for r in pts],
                        [float(r["mu"]) for r in pts],
                        s=14,
                        marker="s",
                        label=label,
                        facecolors=colour if certified or cl != "elliptic" else "none",
                        edgecolors=colour,
                    )
            ax.set_title("rigid-like |s3| > |p_θ|" if kind == "rigid" else "circulating |p_θ| > |s3|")
            ax.set_xlabel("λ")
            ax.grid(alpha=0.3)
        c.axes[0, 0].set_ylabel("μ")
        c.legend(where="below", ncol=3)
        c.title(title or "Stationary ellipses by shape: stability (inverse problem)")
        c.caption(SHAPE_MAP_CAPTION, fontsize=7)
    return Path(png_path)


__all__ = ["COLOURS", "plot_family", "plot_shape_map"]
