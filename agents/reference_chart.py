"""The reference chart: success against the target's settling rate and instability growth rate.

``flatbody chart --tasks`` draws it from the saved task reports (:mod:`agents.reference`), never from a
fresh evaluation. Two panels:

* the reaching tasks ``FlatBody-v0`` and ``FlatBodySlow-v0`` — success against the target's settling
  rate r (:func:`flatbody_env.physics.controllability.settling_rate`: how fast optimal linear feedback
  can settle the target's slowest mode; ``FlatBody-v0`` keeps r ≥ 0.15 s⁻¹, the slow task every r);
* ``FlatBodyHoldUnstable-v0`` — success against the target's growth rate γ (the unstable eigenvalue of
  the linearisation).

Each policy's episodes (baselines and any trained agent in the reports) are grouped into bins of equal
count along the target feature; a point is the bin's success rate at the bin's median feature, its bar
the 95 % Wilson interval (:func:`agents.evaluate.success_interval`). Where the LQR's curve falls off
and where an agent's does are read off the same axes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from agents.reference import POLICY_LABELS, REFERENCE_DIR, load_reports

PANELS = (
    (
        ("FlatBody-v0", "FlatBodySlow-v0"),
        "settling_rate",
        "target settling rate r (1/s)",
        "reach: success against r",
        "center right",
    ),
    (
        ("FlatBodyHoldUnstable-v0",),
        "growth_rate",
        "target growth rate γ (1/s)",
        "hold an unstable ellipse: success against γ",
        "center right",
    ),
)
"""(tasks, target feature, x label, title, legend place) of each panel."""
COLOURS = {"heuristic": "#1f77b4", "passivity": "#2ca02c", "zero": "#7f7f7f", "random": "#bcbd22", "witness": "#9467bd"}
MARKERS = {"FlatBody-v0": "s", "FlatBodySlow-v0": "o", "FlatBodyHoldUnstable-v0": "o"}


TASKS_CAPTION = (
    "Policies: zero: no control; LQR: the linear-quadratic regulator baseline on the linearisation at the target; passivity: a\n"
    "passivity-based damping law; agent (ALGO): a trained agent (e.g. PPO). Tasks: FlatBody-v0 reaches a target ellipse with "
    "r >= 0.15 1/s (dotted),\nFlatBodySlow-v0 any r (solid); FlatBodyHoldUnstable-v0 holds an unstable stationary ellipse. "
    "r: how fast optimal linear feedback can settle\nthe target's slowest mode; γ: the growth rate of the target's unstable mode "
    "(its eigenvalue). Bars: 95 % Wilson interval of each bin's success rate."
)
"""The chart's caption: the policies, the tasks, r and γ, the bars."""


def binned_success(feature, success, bins: int) -> list[tuple[float, float, float, float, int]]:
    """(median feature, success rate, interval lo, hi, count) of ``bins`` bins of equal count along ``feature``."""
    from agents.evaluate import success_interval

    feature = np.asarray(feature, dtype=float)
    success = np.asarray(success, dtype=bool)
    order = np.argsort(feature, kind="stable")
    out = []
    for part in np.array_split(order, max(1, min(bins, feature.size))):
        if part.size == 0:
            continue
        k = int(success[part].sum())
        lo, hi = success_interval(k, part.size)
        out.append((float(np.median(feature[part])), k / part.size, lo, hi, int(part.size)))
    return out


def plot_task_success(png_path: str | Path, folder: str | Path = REFERENCE_DIR, *, bins: int = 5) -> Path:
    """Draw the chart (module docstring) from the reports saved in ``folder`` into ``png_path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flatbody_env.chart_text import add_caption
    from flatbody_env.output import save_figure

    reports = {r["env_id"]: r for r in load_reports(folder)}
    panels = [p for p in PANELS if any(t in reports for t in p[0])]
    if not panels:
        raise ValueError(f"--from: {str(folder)!r} holds no report of {', '.join(t for p in PANELS for t in p[0])}")
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 5.3), squeeze=False)
    agent_colours = iter(["#d62728", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"])
    colours: dict[str, str] = {}
    for ax, (tasks, feature, xlabel, title, legend) in zip(axes[0], panels):
        for env_id in tasks:
            rep = reports.get(env_id)
            if rep is None:
                continue
            x = rep["targets"][feature]
            for name, entry in rep["policies"].items():
                if "episodes" not in entry or name == "random":
                    continue
                colour = colours.setdefault(name, COLOURS.get(name) or next(agent_colours, "#000000"))
                pts = binned_success(x, entry["episodes"]["success"], bins)
                xs = [p[0] for p in pts]
                ys = [p[1] for p in pts]
                err = [[p[1] - p[2] for p in pts], [p[3] - p[1] for p in pts]]
                label = f"{_label(name, entry)}, {env_id}"
                ax.errorbar(
                    xs,
                    ys,
                    yerr=err,
                    color=colour,
                    marker=MARKERS.get(env_id, "o"),
                    ms=5,
                    lw=1.4,
                    capsize=3,
                    ls="-" if env_id != "FlatBody-v0" else ":",
                    label=label,
                )
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"success rate ({bins} bins of equal count, 95 % interval)")
        ax.set_ylim(-0.03, 1.03)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc=legend)
    first = next(iter(reports.values()))
    fig.suptitle(
        f"Reference scores, {first['episodes']} seeded episodes per task (seeds {first['seed']}…)", fontsize=10
    )
    bottom = add_caption(fig, TASKS_CAPTION, fontsize=7.5)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    out = save_figure(fig, png_path, dpi=110)
    plt.close(fig)
    return out


def _label(name: str, entry: dict[str, Any]) -> str:
    return f"agent ({name})" if entry.get("kind") == "agent" else POLICY_LABELS.get(name, name)


__all__ = ["PANELS", "binned_success", "plot_task_success"]
