"""Normalised scores of the v1 suite and their aggregate: rliable's interquartile mean with a stratified bootstrap.

A task's normalised score puts a success rate between two anchors measured on the same held-out episodes (the
saved reference reports, :mod:`agents.reference`):

* 0 — the best classic controller (the best of ``zero``, ``random``, ``passivity``, the LQR and, on the reach tasks,
  the LQR with centrifugal pumping); where a classic
  controller already solves the task as well as the best known (the easy rung), 0 is the zero policy instead;
* 1 — the best known: the best of the planner and, where the task certifies its starts, the witness ceiling (every
  ``FlatBodyTorque-v1`` start comes with actions that reach the target: 100 %), when that beats the classic anchor;
  else 100 %, the ideal.

score = (success − lo) / (hi − lo); above 1 beats the best known, below 0 loses to the best classic controller.
The suite's aggregate is the interquartile mean over tasks (and training seeds) with a 95 % stratified bootstrap
interval, as Agarwal et al. define them ("Deep Reinforcement Learning at the Edge of the Statistical Precipice",
NeurIPS 2021): the IQM is the mean of the middle 50 % of all run × task scores (``scipy.stats.trim_mean`` at 25 %), the
interval the 2.5th and 97.5th percentiles of the IQM over bootstrap samples that redraw each task's runs with
replacement. (Their library, ``rliable`` 1.2, pins ``arch`` < 8, whose releases break with pandas 3: a dozen lines of
numpy and scipy here instead of a pin on pandas for every user.)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

CLASSIC = ("zero", "random", "passivity", "heuristic", "pumping")
"""The classic controllers of the lower anchor (``heuristic`` is the LQR; ``pumping`` the LQR with centrifugal pumping,
:class:`agents.heuristic.PumpingController`, on the reach tasks)."""
KNOWN = ("planner", "witness")
"""The non-learned references of the upper anchor."""


@dataclass(frozen=True, kw_only=True)
class Anchors:
    """One task's anchors (module docstring), with where each came from."""

    env_id: str
    lo: float
    hi: float
    lo_from: str
    hi_from: str

    def normalise(self, success) -> np.ndarray:
        """Normalised score(s) of success rate(s) in [0, 1]."""
        return (np.asarray(success, dtype=float) - self.lo) / (self.hi - self.lo)


def _success(report: dict[str, Any], name: str) -> float | None:
    entry = report.get("policies", {}).get(name)
    if entry is None:
        return None
    summary = entry.get("summary", {})
    return None if "success_rate" not in summary else float(summary["success_rate"])


def anchors(report: dict[str, Any]) -> Anchors:
    """The anchors of the task of a saved reference report (``agents/data/reference/<id>.json``)."""
    classic = {n: s for n in CLASSIC if (s := _success(report, n)) is not None}
    known = {n: s for n in KNOWN if (s := _success(report, n)) is not None}
    lo_from = max(classic, key=classic.get)
    lo = classic[lo_from]
    hi_from, hi = "the ideal (no reference beats the classic anchor)", 1.0
    if known:
        best = max(known, key=known.get)
        if known[best] > lo:
            hi_from, hi = best, known[best]
            if best == "witness":
                hi_from = "witness (every start certified)"
    if lo >= hi:  # a classic controller solves it as well as the best known (the easy rung): anchor on zero
        lo_from, lo = "zero", classic.get("zero", 0.0)
        if lo >= hi:
            lo = 0.0
    return Anchors(env_id=report["env_id"], lo=lo, hi=hi, lo_from=lo_from, hi_from=hi_from)


def iqm(scores: np.ndarray, *, reps: int = 2000, seed: int = 0) -> dict[str, float]:
    """The interquartile mean of normalised scores (runs, tasks) and its 95 % stratified bootstrap interval (module
    docstring: each task's runs redrawn with replacement); one run gives the point estimate alone (interval = point)."""
    from scipy.stats import trim_mean

    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 2 or scores.size == 0 or not np.isfinite(scores).all():
        raise ValueError(f"scores: expected finite numbers (runs, tasks), got shape {scores.shape}")
    runs, tasks = scores.shape
    point = float(trim_mean(scores, 0.25, axis=None))
    if runs < 2:
        return {"iqm": point, "lo": point, "hi": point, "runs": runs, "tasks": tasks}
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, runs, size=(reps, runs, tasks))  # per replicate, per task: runs drawn with replacement
    boot = np.take_along_axis(np.broadcast_to(scores, (reps, runs, tasks)), pick, axis=1)
    values = trim_mean(boot.reshape(reps, -1), 0.25, axis=1)
    lo, hi = np.percentile(values, [2.5, 97.5])
    return {"iqm": point, "lo": float(lo), "hi": float(hi), "runs": runs, "tasks": tasks}


def suite_table(reports: list[dict[str, Any]]) -> dict[str, Any]:
    """Every policy's normalised score per task and, for the policies found on every task, the suite's IQM:
    ``{"anchors": {env_id: {...}}, "scores": {policy: {env_id: score}}, "iqm": {policy: {...}}}``."""
    by_task = {r["env_id"]: r for r in reports}
    out: dict[str, Any] = {"anchors": {}, "scores": {}, "iqm": {}}
    for env_id, report in by_task.items():
        a = anchors(report)
        out["anchors"][env_id] = {"lo": a.lo, "hi": a.hi, "lo_from": a.lo_from, "hi_from": a.hi_from}
        for name in report.get("policies", {}):
            s = _success(report, name)
            if s is not None:
                out["scores"].setdefault(name, {})[env_id] = float(a.normalise(s))
    tasks = sorted(by_task)
    for name, per_task in out["scores"].items():
        if set(per_task) == set(tasks):
            out["iqm"][name] = iqm(np.array([[per_task[t] for t in tasks]]))
    return out


__all__ = ["Anchors", "CLASSIC", "KNOWN", "anchors", "iqm", "suite_table"]
