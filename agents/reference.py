"""Reference scores of the registered tasks: the saved table, its Markdown, and the docs block.

``flatbody evaluate --env ID --out-dir DIR`` writes one report per task (:func:`agents.evaluate.evaluate_task`)
as ``DIR/<ID>.json`` (:func:`save_report`); the shipped reports live in :data:`REFERENCE_DIR`. With
``--docs FILE.md`` the command regenerates the block between ``<!-- bench:tasks -->`` and
``<!-- /bench:tasks -->`` in FILE.md from every report in the folder (:func:`markdown`,
:func:`flatbody_env.output.replace_marked_block`, the mechanism of the benchmark tables), so that a
task's trained agent, evaluated later into the same folder, joins the table. ``flatbody chart
--tasks`` draws from the same saved reports (:mod:`agents.reference_chart`).

A report holds, per policy, the summary of :func:`agents.evaluate.summarize` (success rate with its
95 % Wilson interval, mean and median final distance, return, episode length) and the per-episode
columns (success, final distance, return, length), and per episode the target's settling rate and
growth rate (:func:`agents.evaluate.target_features`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

REFERENCE_DIR = Path(__file__).resolve().parent / "data" / "reference"
"""The shipped reference reports (one JSON per task)."""
DOCS_BLOCK = "tasks"
"""The name of the docs block of the v1 suite (``<!-- bench:tasks -->``)."""
DOCS_BLOCK_V0 = "tasks-v0"
"""The name of the docs block of the deprecated v0 ids (``<!-- bench:tasks-v0 -->``), where the page has one."""
REPORT_VERSION = 1
"""Layout version of a saved report (``"version"``)."""


def report_path(folder: str | Path, env_id: str) -> Path:
    """Where the report of ``env_id`` lives in ``folder``."""
    return Path(folder) / f"{env_id}.json"


def save_report(report: dict[str, Any], folder: str | Path = REFERENCE_DIR) -> Path:
    """Write ``report`` (:func:`agents.evaluate.evaluate_task`) as ``folder/<env id>.json`` (atomically)."""
    from flatbody_env.output import atomic_write

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    data = {"version": REPORT_VERSION, **report}
    return atomic_write(report_path(folder, report["env_id"]), json.dumps(data, separators=(",", ":")) + "\n")


def load_reports(folder: str | Path = REFERENCE_DIR) -> list[dict[str, Any]]:
    """The saved reports in ``folder``, in the order of the registered tasks (others after, by name).

    Raises
    ------
    ValueError
        Naming ``--from`` when the folder holds no report or a report of another layout version.
    """
    from flatbody_env.env.registration import TASK_IDS

    folder = Path(folder)
    files = sorted(folder.glob("*.json")) if folder.is_dir() else []
    if not files:
        raise ValueError(
            f"--from: no saved task reports (*.json) in {str(folder)!r}; write them with "
            "'flatbody evaluate --env all --out-dir DIR'"
        )
    reports = []
    from flatbody_env.physics import validation

    for f in files:
        data = validation.read_json("--from", f)  # the one reading door: a regular file, bounded
        if (
            not isinstance(data, dict)
            or data.get("version") != REPORT_VERSION
            or "env_id" not in data
            or "policies" not in data
        ):
            raise ValueError(f"--from: {str(f)!r} is not a task report of version {REPORT_VERSION}")
        reports.append(data)
    order = {k: i for i, k in enumerate(TASK_IDS)}
    return sorted(reports, key=lambda r: (order.get(r["env_id"], len(order)), r["env_id"]))


POLICY_LABELS = {
    "zero": "zero",
    "random": "random",
    "passivity": "passivity",
    "heuristic": "LQR",
    "pumping": "LQR + pumping",
    "planner": "planner (MPPI)",
    "witness": "witness (certificate, open loop)",
}
"""Row labels of the baselines; agents are labelled ``agent (<algo>)``."""


def _label(name: str, entry: dict[str, Any]) -> str:
    if entry.get("kind") == "agent":
        return f"agent ({name})" if name != "agent" else "agent"
    return POLICY_LABELS.get(name, name)


def markdown(reports: list[dict[str, Any]]) -> str:
    """The reference table: one row per task and policy (module docstring); for the v1 suite also each policy's
    normalised score (:mod:`agents.scores`), the anchors of each task, the planner's compute and the suite's IQM."""
    from agents.planner import PlannerSettings
    from agents.planner import label as planner_label
    from agents.scores import suite_table
    from flatbody_env.env.registration import TASK_IDS, TASKS

    rungs = {spec.env_id: spec.rung for spec in TASKS}
    v1 = [r for r in reports if rungs.get(r["env_id"])]
    table = suite_table(v1) if v1 else {"anchors": {}, "scores": {}, "iqm": {}}
    head = (
        "| task | rung | policy | success (95 % interval) | normalised score | final distance (median) | return (mean) "
        "| episode length (median, s) |"
    )
    lines = [head, "|" + "---|" * 8]
    compute = []
    for rep in reports:
        dt = rep.get("dt", 0.05)
        env_id = rep["env_id"]
        for name, entry in rep["policies"].items():
            label = _label(name, entry)
            s = entry["summary"]
            rung = rungs.get(env_id) or "v0"
            if s.get("status"):
                lines.append(
                    f"| {env_id} | {rung} | {label} | {s['status']} ({s['reason'].split(':')[0]}) | — | — | — | — |"
                )
                continue
            lo, hi = s["success_ci95"]
            score = table["scores"].get(name, {}).get(env_id)
            score_text = "—" if score is None else f"{score:.2f}"
            lines.append(
                f"| {env_id} | {rung} | {label} | {s['success_rate']:.0%} ({lo:.0%}–{hi:.0%}) | {score_text} | "
                f"{s['final_distance_median']:.4f} | {s['return']:.1f} | {s['length_median'] * dt:.2f} |"
            )
            if "compute" in s:
                c = s["compute"]
                name = planner_label(PlannerSettings(**c["settings"])) if "settings" in c else c["label"]
                compute.append(
                    f"{env_id}: {name}, {c['body_steps_per_step']:,} body-steps and "
                    f"{1e3 * c['seconds_per_step']:.1f} ms per control step"
                )
    first = reports[0] if reports else {"episodes": 0, "seed": 0}
    lines.append("")
    lines.append(
        f"{first['episodes']} seeded episodes per task (episode i reset with seed {first['seed']} + i; the same targets and "
        "starts for every policy); regenerate with `flatbody evaluate --env all --out-dir agents/data/reference --docs docs/tasks.md`."
    )
    if table["anchors"]:
        lines += ["", "Normalised score = (success − lo)/(hi − lo) per task (agents/scores.py):", ""]
        lines += ["| task | lo | from | hi | from |", "|---|---|---|---|---|"]
        order = {k: i for i, k in enumerate(TASK_IDS)}
        for env_id in sorted(table["anchors"], key=order.get):
            a = table["anchors"][env_id]
            lo_from, hi_from = (POLICY_LABELS.get(a[k], a[k]) for k in ("lo_from", "hi_from"))
            lines.append(f"| {env_id} | {a['lo']:.0%} | {lo_from} | {a['hi']:.0%} | {hi_from} |")
    if table["iqm"]:
        lines += ["", "The suite's interquartile mean of the normalised score (every v1 task):", ""]
        lines += ["| policy | IQM (95 % stratified bootstrap interval) | runs × tasks |", "|---|---|---|"]
        for name, q in sorted(table["iqm"].items(), key=lambda kv: -kv[1]["iqm"]):
            interval = f" ({q['lo']:.2f}–{q['hi']:.2f})" if q["runs"] > 1 else " (one run)"
            lines.append(f"| {POLICY_LABELS.get(name, name)} | {q['iqm']:.2f}{interval} | {q['runs']} × {q['tasks']} |")
    if compute:
        lines += ["", "Planner compute (per episode, 2 shared CPU cores): " + "; ".join(compute) + "."]
    return "\n".join(lines)


def update_docs(path: str | Path, folder: str | Path = REFERENCE_DIR) -> None:
    """Regenerate the ``<!-- bench:tasks -->`` block of ``path`` from the reports saved in ``folder``."""
    from flatbody_env.env.registration import V1_IDS
    from flatbody_env.physics import validation
    from flatbody_env.output import replace_marked_block

    reports = load_reports(folder)
    replace_marked_block(path, DOCS_BLOCK, markdown([r for r in reports if r["env_id"] in V1_IDS]))
    v0 = [r for r in reports if r["env_id"] not in V1_IDS]
    if v0 and f"<!-- bench:{DOCS_BLOCK_V0} -->" in validation.read_text("docs", path):
        replace_marked_block(path, DOCS_BLOCK_V0, markdown(v0))


__all__ = [
    "DOCS_BLOCK",
    "POLICY_LABELS",
    "REFERENCE_DIR",
    "REPORT_VERSION",
    "load_reports",
    "markdown",
    "report_path",
    "save_report",
    "update_docs",
]
