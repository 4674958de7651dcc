"""The reference charts: the v1 suite's ladder, and success against the target's settling and growth rates.

``flatbody chart --tasks`` draws them from the saved task reports (:mod:`agents.reference`), never from a
fresh evaluation:

* the ladder (:func:`plot_ladder`, ``tasks_ladder.png``): every v1 task in the order of its rung, each policy's
  success with its 95 % Wilson interval;
* success against the target (:func:`plot_task_success`, ``tasks_success.png``), two panels: the reaching tasks
  ``FlatBody-v1``, ``FlatBodySlow-v1`` and ``FlatBodySlowHard-v1`` against the target's settling rate r
  (:func:`flatbody_env.physics.controllability.settling_rate`: how fast optimal linear feedback can settle the
  target's slowest mode; ``FlatBody-v1`` keeps r ≥ 0.15 s⁻¹, the slow task r ≥ 0.05 s⁻¹, the hard one every r);
  ``FlatBodyHoldUnstable-v1`` against the target's growth rate γ (the unstable eigenvalue of the linearisation).

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
        ("FlatBody-v1", "FlatBodySlow-v1", "FlatBodySlowHard-v1"),
        "settling_rate",
        "target settling rate r (1/s)",
        "reach: success against r",
        "center right",
    ),
    (
        ("FlatBodyHoldUnstable-v1",),
        "growth_rate",
        "target growth rate γ (1/s)",
        "hold an unstable ellipse: success against γ",
        "center right",
    ),
)
"""(tasks, target feature, x label, title, legend place) of each panel."""
COLOURS = {
    "heuristic": "#1f77b4",
    "passivity": "#2ca02c",
    "zero": "#7f7f7f",
    "random": "#bcbd22",
    "planner": "#ff7f0e",
    "witness": "#9467bd",
}
MARKERS = {"FlatBody-v1": "s", "FlatBodySlow-v1": "o", "FlatBodySlowHard-v1": "^", "FlatBodyHoldUnstable-v1": "o"}
STYLES = {"FlatBody-v1": ":", "FlatBodySlow-v1": "--", "FlatBodySlowHard-v1": "-"}


TASKS_CAPTION = (
    "Policies: zero: no control; LQR: the linear-quadratic regulator baseline on the linearisation at the target; passivity: a\n"
    "passivity-based damping law; planner: MPPI over the env's own transition; agent (ALGO): a trained agent. Tasks: FlatBody-v1\n"
    "reaches a target with r >= 0.15 1/s (dotted), FlatBodySlow-v1 r >= 0.05 1/s (dashed), FlatBodySlowHard-v1 any r (solid);\n"
    "FlatBodyHoldUnstable-v1 holds an unstable stationary ellipse. "
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
                    ls=STYLES.get(env_id, "-"),
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


LADDER_CAPTION = (
    "Each v1 task, easy to hard (its rung under the name): the success rate of each policy over the same held-out\n"
    "episodes, with its 95 % Wilson interval. zero, random, passivity, LQR: classic references; planner: MPPI over the\n"
    "env's own transition from the observed state; witness: the solvability certificate of FlatBodyTorque-v1's starts\n"
    "(the open-loop actions that reach the target by construction), not a policy; agent (ALGO): trained agents."
)


def plot_ladder(png_path: str | Path, folder: str | Path = REFERENCE_DIR) -> Path:
    """The ladder (module docstring) from the v1 reports saved in ``folder`` into ``png_path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.evaluate import success_interval
    from flatbody_env.chart_text import add_caption
    from flatbody_env.env.registration import TASKS, V1_IDS
    from flatbody_env.output import save_figure

    rungs = {spec.env_id: spec.rung for spec in TASKS}
    reports = [r for r in load_reports(folder) if r["env_id"] in V1_IDS]
    if not reports:
        raise ValueError(f"--from: {str(folder)!r} holds no report of the v1 suite ({', '.join(V1_IDS)})")
    order = {"easy": 0, "medium": 1, "hard": 2}
    reports.sort(key=lambda r: (order[rungs[r["env_id"]]], V1_IDS.index(r["env_id"])))
    names: list[str] = []
    for rep in reports:
        names += [n for n, e in rep["policies"].items() if "episodes" in e and n not in names]
    fig, ax = plt.subplots(figsize=(12, 5.6))
    width = 0.8 / len(names)
    agent_colours = iter(["#d62728", "#8c564b", "#e377c2", "#17becf", "#000000"])
    colours = {n: COLOURS.get(n) or next(agent_colours, "#000000") for n in names}
    for k, name in enumerate(names):
        xs, ys, lo, hi = [], [], [], []
        for i, rep in enumerate(reports):
            entry = rep["policies"].get(name)
            if entry is None or "episodes" not in entry:
                continue
            ok = np.asarray(entry["episodes"]["success"], dtype=bool)
            a, b = success_interval(int(ok.sum()), ok.size)
            xs.append(i - 0.4 + (k + 0.5) * width)
            ys.append(ok.mean())
            lo.append(max(ok.mean() - a, 0.0))
            hi.append(max(b - ok.mean(), 0.0))
        entry = next(r["policies"][name] for r in reports if name in r["policies"])
        witness = name == "witness"
        ax.bar(xs, ys, width=width * 0.92, color=colours[name], label=_label(name, entry), yerr=[lo, hi], capsize=2,
               error_kw={"lw": 0.8}, hatch="//" if witness else None, edgecolor="#4b2d73" if witness else "white")  # fmt: skip
    ax.set_xticks(range(len(reports)), [f"{r['env_id']}\n({rungs[r['env_id']]})" for r in reports], fontsize=8)
    ax.set_ylim(0, 1.1)
    ax.set_yticks(np.linspace(0, 1, 6))
    ax.set_ylabel("success rate (95 % interval)")
    ax.axhline(0.9, color="#555555", lw=0.8, ls=":")
    ax.text(-0.45, 0.915, "90 %: no medium or hard task may be solved this well by a classic law", ha="left",
            va="bottom", fontsize=7, color="#555555", bbox={"facecolor": "white", "edgecolor": "none", "pad": 1})  # fmt: skip
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7.5, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.16), frameon=False)
    first = reports[0]
    ax.set_title(f"The v1 ladder: {first['episodes']} held-out episodes per task (seeds {first['seed']}…)", fontsize=10)
    bottom = add_caption(fig, LADDER_CAPTION, fontsize=7.5)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    out = save_figure(fig, png_path, dpi=110)
    plt.close(fig)
    return out


def _label(name: str, entry: dict[str, Any]) -> str:
    return f"agent ({name})" if entry.get("kind") == "agent" else POLICY_LABELS.get(name, name)


__all__ = ["PANELS", "binned_success", "plot_ladder", "plot_task_success"]
