"""What a sweep prints: the serial command's JSON form, and short tables.

``sweep stability-map --json`` and ``sweep failure-study --json`` print ``{"rows": [...]}``, the
task payloads concatenated in key order — the same object as ``flatbody stability-map --json`` and
``flatbody failure-study --json``. ``sweep family --json`` prints one ``family --json`` object per
family (with its body) as ``{"rows": [...]}``; ``sweep seeds --json`` one evaluation summary per
seed plus the mean ± std over seeds. Failed tasks add ``"errors": [{"key", "error"}]``; missing
ones (an interrupted sweep) ``"missing"``.
"""

from __future__ import annotations

import math
from typing import Any

from flatbody_env.sweep.runner import SweepReport

SEED_METRICS = ("success_rate", "final_distance")


def rows_of(report: SweepReport) -> list[Any]:
    """The rows of the successful tasks, in key order (list payloads concatenated)."""
    rows: list[Any] = []
    for r in report.results:
        if r.status != "ok":
            continue
        if isinstance(r.payload, list):
            rows.extend(r.payload)
        else:
            rows.append(r.payload)
    return rows


def mean_std(values: list[float]) -> dict[str, float]:
    """Mean and sample standard deviation (ddof = 1; 0 for one value)."""
    n = len(values)
    if n == 0:
        return {"mean": math.nan, "std": math.nan, "n": 0}
    m = sum(values) / n
    s = math.sqrt(sum((v - m) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0
    return {"mean": m, "std": s, "n": n}


def seeds_summary(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Mean ± std over seeds of :data:`SEED_METRICS`."""
    return {m: mean_std([float(r[m]) for r in rows]) for m in SEED_METRICS}


def as_json(report: SweepReport) -> dict[str, Any]:
    """The sweep's JSON object (see the module docstring)."""
    rows = rows_of(report)
    out: dict[str, Any] = {"rows": rows}
    if report.spec["kind"] == "seeds":
        out["summary"] = seeds_summary(rows)
    if report.failed:
        out["errors"] = [{"key": r.key, "error": r.error} for r in report.failed]
    if report.missing:
        out["missing"] = report.missing
    return out


def format_report(report: SweepReport) -> str:
    """A few lines for the terminal: counts, then a kind-specific table."""
    kind = report.spec["kind"]
    rows = rows_of(report)
    lines = [
        f"sweep {kind}: {report.total} tasks, {len(report.results) - len(report.failed)} ok, {len(report.failed)} failed"
        + (f", {report.missing} missing" if report.missing else "")
        + f" ({report.ran} run now)"
    ]
    if kind == "stability-map":
        counts: dict[str, int] = {}
        for r in rows:
            key = f"{r['kind']} {r['classification']}" + (
                " (energy-Casimir stable)" if r["nonlinear"] == "stable" else ""
            )
            counts[key] = counts.get(key, 0) + 1
        lines.append(f"{len(rows)} stationary ellipses: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    elif kind == "failure-study":
        fails = [r for r in rows if r["status"] != "ok"]
        lines.append(f"{len(rows)} runs, {len(fails)} detected failures")
        seen = set()
        for r in fails:
            if (r["study"], r["method"]) in seen:
                continue
            seen.add((r["study"], r["method"]))
            lines.append(
                f"  {r['study']:<8} {r['method']:<20} first fails at {r['parameter_name']} = {r['parameter']:g}: {r['status']}"
            )
    elif kind == "family":
        for r in rows:
            ev = ", ".join(f"{e['kind']} at {r['param']} = {e['param']:.6g}" for e in r["events"]) or "no event"
            lines.append(
                f"  {r['body']}: {r['param']} in [{r['range'][0]:g}, {r['range'][1]:g}]: {r['branches']} branch(es), "
                f"{r['points']} points; {ev} ({r['csv']})"
            )
    elif kind == "seeds":
        lines.append("| seed | success rate | final distance (mean) | model |")
        lines.append("|---|---|---|---|")
        for r in rows:
            lines.append(f"| {r['seed']} | {r['success_rate']:.0%} | {r['final_distance']:.4f} | {r['model']} |")
        s = seeds_summary(rows)
        if rows:
            lines.append(
                f"| mean ± std ({len(rows)} seeds) | {s['success_rate']['mean']:.0%} ± {s['success_rate']['std']:.0%} | "
                f"{s['final_distance']['mean']:.4f} ± {s['final_distance']['std']:.4f} | |"
            )
    for r in report.failed:
        lines.append(f"  failed {r.key}: {r.error}")
    return "\n".join(lines)


__all__ = ["SEED_METRICS", "as_json", "format_report", "mean_std", "rows_of", "seeds_summary"]
