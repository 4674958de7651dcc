"""The reference charts: the v1 suite's ladder, and success against the target's settling and growth rates.

``flatbody chart --tasks`` draws them from the saved task reports (:mod:`agents.reference`), never from a
fresh evaluation:

* the ladder (:func:`plot_ladder`, ``tasks_ladder.png``): every v1 task in the order of its rung, each policy's
  success with its 95 % Wilson interval;
* success against the target (:func:`plot_task_success`, ``tasks_success.png``), one panel per task: the reaching
  tasks ``FlatBody-v1``, ``FlatBodySlow-v1`` and ``FlatBodySlowHard-v1`` against the target's settling rate r
  (:func:`flatbody_env.physics.controllability.settling_rate`: how fast optimal linear feedback can settle the
  target's slowest mode; ``FlatBody-v1`` keeps r ≥ 0.15 s⁻¹, the slow task r ≥ 0.05 s⁻¹, the hard one every r);
  ``FlatBodyHoldUnstable-v1`` against the target's growth rate γ (the unstable eigenvalue of the linearisation).
  A folder without v1 reports gives the same panels of the deprecated v0 ids.

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

SUCCESS_PANELS = (
    ("FlatBody-v1", "settling_rate", "reach, r ≥ 0.15 1/s"),
    ("FlatBodySlow-v1", "settling_rate", "reach, r ≥ 0.05 1/s"),
    ("FlatBodySlowHard-v1", "settling_rate", "reach, any r"),
    ("FlatBodyHoldUnstable-v1", "growth_rate", "hold, γ ≥ 0.25 1/s"),
)
"""(task, target feature, what the task asks) of each panel of the success chart (the v1 suite's tasks whose
difficulty follows a target feature)."""

SUCCESS_PANELS_V0 = (
    ("FlatBody-v0", "settling_rate", "reach, r ≥ 0.15 1/s"),
    ("FlatBodySlow-v0", "settling_rate", "reach, any r"),
    ("FlatBodyHoldUnstable-v0", "growth_rate", "hold an unstable ellipse"),
)
"""The same panels for the deprecated v0 ids: drawn when the folder holds no v1 report of them."""

FEATURES = {"settling_rate": "target settling rate r (1/s)", "growth_rate": "target growth rate γ (1/s)"}
"""The x label of each target feature."""

COLOURS = {
    "heuristic": "#1f77b4",
    "passivity": "#2ca02c",
    "zero": "#7f7f7f",
    "random": "#bcbd22",
    "planner": "#ff7f0e",
    "witness": "#9467bd",
    "pumping": "#8c6d31",
}
MARKERS = {"heuristic": "o", "passivity": "s", "zero": "v", "planner": "D", "witness": "P", "pumping": "X"}
"""Each policy's marker (with its colour: policies told apart in print and by colour-blind readers)."""
AGENT_COLOURS = ("#d62728", "#e377c2", "#17becf", "#8c564b", "#000000")
AGENT_MARKERS = ("^", "<", ">", "h", "*")


TASKS_CAPTION = (
    "One panel per task (its id and what it asks in the title). Policies: zero: no control; LQR: the "
    "linear-quadratic regulator baseline on the linearisation at the target; passivity: a passivity-based damping "
    "law; LQR + pumping: the LQR with the out-of-plane spin's centrifugal force pumped against the slow shape (or, "
    "under torque alone, the thickness); planner: MPPI over the env's own transition; agent (ALGO): a trained agent.\n"
    "r: how fast optimal linear feedback can settle the target's slowest mode; γ: the growth rate of the target's "
    "unstable mode (its eigenvalue).\n"
    "Points: the success rate of each of the bins of equal count along the target feature, at the bin's median "
    "(the policies shifted apart a little); bars: 95 % Wilson interval."
)
"""The chart's caption: the panels, the policies, r and γ, the points and bars."""


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


def _policy_style(names) -> dict[str, tuple[str, str]]:
    """(colour, marker) of each policy name: the baselines' fixed ones, agents in turn."""
    agents = iter(zip(AGENT_COLOURS, AGENT_MARKERS, strict=True))
    out = {}
    for n in names:
        out[n] = (COLOURS[n], MARKERS.get(n, "o")) if n in COLOURS else next(agents, ("#000000", "x"))
    return out


def plot_task_success(png_path: str | Path, folder: str | Path = REFERENCE_DIR, *, bins: int = 5) -> Path:
    """Draw the chart (module docstring) from the reports saved in ``folder`` into ``png_path``: one panel per task of
    :data:`SUCCESS_PANELS` (or, when the folder holds none of the v1 ones, of :data:`SUCCESS_PANELS_V0`)."""
    from flatbody_env.figures import chart, fraction_axis

    reports = {r["env_id"]: r for r in load_reports(folder)}
    panels = [p for p in SUCCESS_PANELS if p[0] in reports] or [p for p in SUCCESS_PANELS_V0 if p[0] in reports]
    if not panels:
        ids = ", ".join(p[0] for p in SUCCESS_PANELS + SUCCESS_PANELS_V0)
        raise ValueError(f"--from: {str(folder)!r} holds no report of {ids}")
    names = list(
        dict.fromkeys(
            n
            for p in panels
            for n, e in reports[p[0]]["policies"].items()
            if "episodes" in e and n not in ("random", "witness")
        )
    )
    style = _policy_style(names)
    ncols = 2 if len(panels) == 4 else len(panels)
    nrows = -(-len(panels) // ncols)
    with chart(png_path, size=(5.6 * ncols, 4.0 * nrows + 2.0), nrows=nrows, ncols=ncols, sharey=True) as c:
        for k, (env_id, feature, asks) in enumerate(panels):
            ax = c.axes[k // ncols, k % ncols]
            rep = reports[env_id]
            x = np.asarray(rep["targets"][feature], dtype=float)
            shift = 0.012 * float(np.ptp(x) if x.size else 1.0)
            drawn = [n for n in names if "episodes" in rep["policies"].get(n, {})]
            for j, name in enumerate(drawn):
                entry = rep["policies"][name]
                pts = binned_success(x, entry["episodes"]["success"], bins)
                colour, marker = style[name]
                ax.errorbar(
                    [p[0] + (j - (len(drawn) - 1) / 2) * shift for p in pts],
                    [p[1] for p in pts],
                    yerr=[[p[1] - p[2] for p in pts], [p[3] - p[1] for p in pts]],
                    color=colour,
                    marker=marker,
                    ms=5,
                    lw=1.4,
                    capsize=3,
                    label=_label(name, entry),
                )
            ax.set_xlabel(FEATURES[feature])
            fraction_axis(ax, f"success rate ({bins} bins, 95 % interval)" if k % ncols == 0 else None)
            ax.set_title(f"{env_id}: {asks}")
            ax.grid(alpha=0.3)
        for k in range(len(panels), nrows * ncols):
            c.axes[k // ncols, k % ncols].axis("off")
        first = next(iter(reports.values()))
        c.legend(where="below", ncol=min(6, len(names)))
        c.title(f"Success against the target, {first['episodes']} seeded episodes per task (seeds {first['seed']}…)")
        c.caption(TASKS_CAPTION)
    return Path(png_path)


LADDER_CAPTION = (
    "Each v1 task, easy to hard (its rung under the name): the success rate of each policy over the same held-out\n"
    "episodes, with its 95 % Wilson interval. zero, random, passivity, LQR and the LQR with centrifugal pumping\n"
    "(reach tasks): classic references; planner: MPPI over the env's own transition from the observed state;\n"
    "witness: the solvability certificate of FlatBodyTorque-v1's starts (the open-loop actions that reach the target\n"
    "by construction), not a policy; agent (ALGO): the shipped agents — agent (distilled): the planner distilled\n"
    "into a network by DAgger (the prior track: it imitates the planner, which plans with the true model);\n"
    "agent (distilled-clock): the same with the episode's elapsed time in its observation."
)


def plot_ladder(png_path: str | Path, folder: str | Path = REFERENCE_DIR) -> Path:
    """The ladder (module docstring) from the v1 reports saved in ``folder`` into ``png_path``."""
    from agents.evaluate import ALL_BASELINES, success_interval
    from flatbody_env.env.registration import TASKS, V1_IDS
    from flatbody_env.figures import PALETTE, chart, fraction_axis

    rungs = {spec.env_id: spec.rung for spec in TASKS}
    reports = [r for r in load_reports(folder) if r["env_id"] in V1_IDS]
    if not reports:
        raise ValueError(f"--from: {str(folder)!r} holds no report of the v1 suite ({', '.join(V1_IDS)})")
    order = {"easy": 0, "medium": 1, "hard": 2}
    reports.sort(key=lambda r: (order[rungs[r["env_id"]]], V1_IDS.index(r["env_id"])))
    names: list[str] = []
    for rep in reports:
        names += [n for n, e in rep["policies"].items() if "episodes" in e and n not in names]
    names.sort(key=lambda n: ALL_BASELINES.index(n) if n in ALL_BASELINES else len(ALL_BASELINES))  # baselines first
    style = _policy_style([n for n in names if n != "witness"])
    style["witness"] = (COLOURS["witness"], "")
    width = 0.8 / len(names)
    with chart(png_path, size=(12, 6.4)) as c:
        ax = c.ax
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
            ax.bar(
                xs,
                ys,
                width=width * 0.92,
                color=style[name][0],
                label=_label(name, entry),
                yerr=[lo, hi],
                capsize=2,
                error_kw={"lw": 0.8},
                hatch="//" if witness else None,
                edgecolor="#4b2d73" if witness else "white",
            )
        ax.set_xticks(range(len(reports)), [f"{r['env_id']}\n({rungs[r['env_id']]})" for r in reports])
        fraction_axis(ax, "success rate (95 % interval)")
        ax.axhline(
            0.9,
            color=PALETTE["goal"],
            lw=0.8,
            ls=":",
            label="90 %: no medium or hard task may be solved this well by a classic law",
        )
        ax.grid(axis="y", alpha=0.3)
        first = reports[0]
        ax.set_title(f"The v1 ladder: {first['episodes']} held-out episodes per task (seeds {first['seed']}…)")
        c.legend(where="below", ncol=4)
        c.caption(LADDER_CAPTION)
    return Path(png_path)


def _label(name: str, entry: dict[str, Any]) -> str:
    return f"agent ({name})" if entry.get("kind") == "agent" else POLICY_LABELS.get(name, name)


__all__ = ["FEATURES", "SUCCESS_PANELS", "SUCCESS_PANELS_V0", "binned_success", "plot_ladder", "plot_task_success"]
