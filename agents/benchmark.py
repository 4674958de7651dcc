"""The benchmark table: algorithms trained from scratch on the v1 suite over several seeds, their learning curves and
their normalised scores — what an RL user reads to know what an algorithm does at a budget.

One *case* is one (algorithm, task, training seed) (:func:`run_case`): the algorithm trained from scratch, without any
controller prior, with its task's hyperparameters (``agents/hyperparams/ALGO.yml``) for a fixed budget of env steps into
a run folder of its own (:mod:`agents.train`), evaluated along the way — at :data:`EVAL_POINTS` fractions of the budget —
on held-out episodes (seeds :data:`~agents.evaluate.EVAL_SEED` …, never trained on), the deterministic policy as it is at
that moment; the wall time of each point is training time alone (the evaluations are not counted). The last point is the
final evaluation on :data:`FINAL_EPISODES` episodes. ``flatbody benchmark`` runs the cases on the sweep engine (Dask:
an embedded local cluster, or ``--scheduler`` for more machines; rows stored by key, so ``--resume`` continues a killed
benchmark) and :func:`report` turns the stored rows into the saved tables (JSON, CSV), the learning curves over env
steps and over wall time (mean and 95 % t-interval over the training seeds) and the final table of normalised scores
(:mod:`agents.scores`: per task, 0 the best classic controller and 1 the best known, from the reference reports; the
suite's interquartile mean with its stratified bootstrap interval per algorithm).
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

EVAL_POINTS = (0.1, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0)
"""Fractions of the budget where a case is evaluated (the learning curve's points)."""
CURVE_EPISODES = 40
"""Held-out episodes of each intermediate evaluation."""
FINAL_EPISODES = 100
"""Held-out episodes of the final evaluation (the table's)."""
ALGOS = ("ppo", "sac", "td3", "rsl-ppo")
BUDGETS = {"ppo": 300_000, "sac": 300_000, "td3": 300_000, "rsl-ppo": 1_000_000}
"""Env steps per run: the budgets of the v1 suite's table (docs/tasks.md, "Learned baselines"), chosen so that its 120
runs fit on 2 CPU cores (rsl_rl's PPO, whose vectorised rollout makes a step cheap, more steps in about the minutes an
SB3 run takes); ``flatbody benchmark --out DIR`` with no other flag trains that table."""
DATA_DIR = Path(__file__).resolve().parent / "data" / "benchmark"
"""The saved tables of the v1 suite's benchmark (``benchmark.json``, ``.csv``; docs/tasks.md, "Learned baselines")."""


def variant_label(algo: str, overrides: list[str] | None) -> str:
    """The name of an algorithm run with ``overrides`` in the tables and charts: ``"ppo learning_rate=0.0003"`` (the
    algorithm itself without them)."""
    return " ".join([algo, *(overrides or [])])


def _order(label: str) -> tuple:
    """Sort key of a table column: the algorithms in :data:`ALGOS` order, a grid's points by their value."""
    base, _, rest = label.partition(" ")
    _, _, value = rest.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = math.inf
    return (ALGOS.index(base) if base in ALGOS else len(ALGOS), number, label)


def run_case(algo: str, env_id: str, seed: int, budget: int, out: str | Path, *, eval_seed: int, curve_episodes: int = CURVE_EPISODES,
             final_episodes: int = FINAL_EPISODES, command: list[str] | None = None,
             overrides: list[str] | None = None, hyperparams: list[str] | None = None,
             device: str = "cpu") -> dict[str, Any]:  # fmt: skip
    """Train ``algo`` from scratch on ``env_id`` with ``seed`` for ``budget`` env steps into ``out`` and evaluate it
    along the way (module docstring); the row: ``{"algo", "env_id", "seed", "budget", "curve": [...], "final": {...},
    "train_seconds", "run"}``. ``overrides``: one point of a hyperparameter grid (``["learning_rate=0.0003"]``, as
    ``flatbody train --hyperparams``); its row's ``algo`` is then the variant's label (:func:`variant_label`), and
    ``"base_algo"`` and ``"overrides"`` say what it is. ``hyperparams``: fixed overrides of every case (``flatbody
    benchmark --hyperparams``) and ``device`` the torch device (rsl-ppo; ``"cuda"``: env and policy on the GPU); both
    are named in the label (``"rsl-ppo n_envs=65536 device=cuda"``) and kept in the row (``"hyperparams"``,
    ``"device"``), so that such rows join a CPU table as columns of their own."""
    from agents.evaluate import Agent, HeldOutEvaluations
    from agents.train import train

    fixed = list(hyperparams or [])
    at = [max(1, int(round(f * budget))) for f in EVAL_POINTS[:-1]]
    curve = HeldOutEvaluations(env_id, at, seed=eval_seed, episodes=curve_episodes)
    result = train(
        algo, out, seed=seed, n_timesteps=int(budget), env_id=env_id, checkpoint_freq=0, threads=1, progress=False,
        force=True, notes=False, command=command, overrides=[*fixed, *(overrides or [])], evaluations=curve,
        device=device,
    )  # fmt: skip
    train_s = curve.train_seconds()
    final = curve.figures(Agent(out), final_episodes)
    curve.points.append({"env_steps": int(result.timesteps), "train_seconds": float(train_s), **final})
    variant = {"base_algo": algo, "overrides": list(overrides)} if overrides else {}
    if fixed:
        variant.update(base_algo=algo, hyperparams=fixed)
    if device != "cpu":
        variant.update(base_algo=algo, device=device)
    label = variant_label(algo, [*fixed, *(overrides or []), *([f"device={device}"] if device != "cpu" else [])])
    return {
        "algo": label,
        **variant,
        "env_id": env_id,
        "seed": int(seed),
        "budget": int(budget),
        "curve": curve.points,
        "final": final,
        "train_seconds": float(train_s),
        "run": str(out),
    }


# --------------------------------------------------------------------------------------------- the report
ROW_KEYS = ("algo", "env_id", "seed", "budget", "curve", "final", "train_seconds")
"""The fields of a stored case (:func:`run_case`) the report reads."""


def join_rows(rows: list[dict[str, Any]], saved: Any, where: str = "--with") -> list[dict[str, Any]]:
    """This run's rows and the rows of a saved table (``benchmark.json`` of an earlier benchmark or of another
    machine's) as one report's: a saved case is kept unless this run has its (algorithm, task, seed), so a benchmark
    that trains one algorithm again replaces that algorithm's rows and keeps the others'; sorted as the store orders
    its cases (algorithm, task, seed).

    Raises
    ------
    ValueError
        Naming ``where`` when ``saved`` is not a saved table (no ``rows``, or a row without the fields of
        :data:`ROW_KEYS`).
    """
    listed = saved.get("rows") if isinstance(saved, dict) else None
    if not isinstance(listed, list):
        raise ValueError(f"{where}: expected a saved benchmark table (benchmark.json, with its rows)")
    for i, row in enumerate(listed):
        missing = [k for k in ROW_KEYS if not isinstance(row, dict) or k not in row]
        if missing:
            raise ValueError(f"{where}: row {i} is not a benchmark case (it lacks {', '.join(missing)})")
    mine = {(r["algo"], r["env_id"], r["seed"]) for r in rows}
    joined = list(rows) + [r for r in listed if (r["algo"], r["env_id"], r["seed"]) not in mine]
    return sorted(joined, key=lambda r: (r["algo"], r["env_id"], r["seed"]))  # the store's order of its keys


def _t95(n: int) -> float:
    """The two-sided 95 % Student t quantile with n − 1 degrees of freedom (n ≥ 2)."""
    from scipy.stats import t

    return float(t.ppf(0.975, n - 1))


def mean_interval(values) -> tuple[float, float, float]:
    """(mean, lo, hi): the mean of ``values`` and its 95 % t-interval (one value: the value itself)."""
    v = np.asarray(values, dtype=float)
    m = float(v.mean())
    if v.size < 2:
        return m, m, m
    half = _t95(v.size) * float(v.std(ddof=1)) / math.sqrt(v.size)
    return m, m - half, m + half


def curves(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per ``algo|env_id``: the learning curve over the seeds (points aligned by their index along the budget):
    env steps, training seconds (means), success and return (mean, lo, hi)."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(f"{r['algo']}|{r['env_id']}", []).append(r)
    out = {}
    for key, rs in groups.items():
        k = min(len(r["curve"]) for r in rs)
        pts = []
        for i in range(k):
            col = [r["curve"][i] for r in rs]
            succ = mean_interval([c["success_rate"] for c in col])
            ret = mean_interval([c["return"] for c in col])
            pts.append({
                "env_steps": float(np.mean([c["env_steps"] for c in col])),
                "train_seconds": float(np.mean([c["train_seconds"] for c in col])),
                "success": succ, "return": ret,
            })  # fmt: skip
        out[key] = {"seeds": sorted(r["seed"] for r in rs), "points": pts}
    return out


def final_table(rows: list[dict[str, Any]], reports: list[dict[str, Any]]) -> dict[str, Any]:
    """The final table: per ``algo|env_id`` the success over the seeds (mean and interval), the normalised score and
    the training compute; per algorithm the suite's IQM (tasks × seeds, stratified bootstrap); the anchors used."""
    from agents.scores import anchors, iqm

    anchor = {r["env_id"]: anchors(r) for r in reports}
    table: dict[str, Any] = {"cells": {}, "iqm": {}, "anchors": {k: vars(a) for k, a in anchor.items()}}
    by_algo: dict[str, dict[str, dict[int, float]]] = {}
    for r in rows:
        key = f"{r['algo']}|{r['env_id']}"
        cell = table["cells"].setdefault(key, {"algo": r["algo"], "env_id": r["env_id"], "seeds": [], "success": [],
                                               "train_seconds": [], "budget": r["budget"]})  # fmt: skip
        cell["seeds"].append(r["seed"])
        cell["success"].append(r["final"]["success_rate"])
        cell["train_seconds"].append(r["train_seconds"])
        if r["env_id"] in anchor:
            by_algo.setdefault(r["algo"], {}).setdefault(r["env_id"], {})[r["seed"]] = float(
                anchor[r["env_id"]].normalise(r["final"]["success_rate"])
            )
    for cell in table["cells"].values():
        cell["success_mean"] = mean_interval(cell["success"])
        if cell["env_id"] in anchor:
            cell["score_mean"] = mean_interval(anchor[cell["env_id"]].normalise(cell["success"]))
    tasks = sorted(anchor)
    for algo, per_task in by_algo.items():
        if set(per_task) != set(tasks):
            continue
        seeds = sorted(set.intersection(*(set(v) for v in per_task.values())))
        if not seeds:
            continue
        scores = np.array([[per_task[t][s] for t in tasks] for s in seeds])
        table["iqm"][algo] = iqm(scores)
    return table


def report(rows: list[dict[str, Any]], out: str | Path, reports: list[dict[str, Any]]) -> dict[str, Path]:
    """Write ``benchmark.json`` (rows, curves, the final table, a hyperparameter grid's sensitivity), ``benchmark.csv``
    (one row per case) and the charts (``benchmark_curves.png``: success against env steps and against training time
    per task; ``benchmark_iqm.png``; with a grid ``benchmark_sensitivity.png``) into ``out``; returns the paths."""
    from flatbody_env.output import atomic_write, shown_path, write_csv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = [{**r, "run": shown_path(r["run"])} if "run" in r else r for r in rows]
    data = {"rows": rows, "curves": curves(rows), "final": final_table(rows, reports), "sensitivity": sensitivity(rows)}
    paths = {"json": atomic_write(out / "benchmark.json", json.dumps(data, indent=1) + "\n")}
    header = ["algo", "env_id", "seed", "budget", "success", "return", "final_distance", "train_seconds"]
    paths["csv"] = write_csv(
        out / "benchmark.csv",
        header,
        [
            [
                r["algo"],
                r["env_id"],
                r["seed"],
                r["budget"],
                r["final"]["success_rate"],
                r["final"]["return"],
                r["final"]["final_distance"],
                r["train_seconds"],
            ]
            for r in rows
        ],  # fmt: skip
    )
    paths["curves"] = plot_curves(data, out / "benchmark_curves.png")
    if data["final"]["iqm"]:
        paths["iqm"] = plot_iqm(data, out / "benchmark_iqm.png")
    if data["sensitivity"]:
        paths["sensitivity"] = plot_sensitivity(data, out / "benchmark_sensitivity.png")
    return paths


COLOURS = {"ppo": "#1f77b4", "sac": "#2ca02c", "td3": "#9467bd", "rsl-ppo": "#d62728"}


def _colours(labels) -> dict[str, str]:
    """A colour per column: an algorithm's own (:data:`COLOURS`); a hyperparameter grid's points in the figure
    helper's colour cycle, in grid order."""
    from flatbody_env.figures import CYCLE

    out, k = {}, 0
    for label in sorted(set(labels), key=_order):
        if label in COLOURS:
            out[label] = COLOURS[label]
        else:
            out[label] = CYCLE[k % len(CYCLE)]
            k += 1
    return out


CURVES_CAPTION = (
    "Each line: one algorithm trained from scratch (no controller prior) with its task's hyperparameters, evaluated "
    "deterministically on held-out episodes (never trained on) at fixed fractions of its budget; the line is the mean "
    "over the training seeds, the band its 95 % t-interval. Top: against env steps; bottom: against training time on "
    "2 shared CPU cores (the evaluations left out)."
)
IQM_CAPTION = (
    "IQM: the interquartile mean of the normalised score over every (task, training seed) run — 0 is the best classic "
    "controller of the task, 1 the best known reference (planner or witness, else 100 %); the bar is its 95 % "
    "stratified bootstrap interval (resampling the seeds within each task)."
)


def plot_curves(data: dict[str, Any], png: str | Path) -> Path:
    """Success against env steps (top row) and against training time (bottom row), one column per task: mean over the
    seeds and its 95 % t-interval, one line per algorithm."""
    from flatbody_env.env.registration import V1_IDS
    from flatbody_env.figures import chart, fraction_axis

    envs = [e for e in V1_IDS if any(k.endswith(f"|{e}") for k in data["curves"])]
    colours = _colours(k.split("|")[0] for k in data["curves"])
    with chart(png, size=(max(6.4, 3.2 * len(envs)), 7.0), nrows=2, ncols=len(envs), sharey=True) as c:
        for j, env_id in enumerate(envs):
            for key, curve in sorted(data["curves"].items(), key=lambda kv: _order(kv[0].split("|")[0])):
                algo, env = key.split("|")
                if env != env_id:
                    continue
                for i, x in enumerate(("env_steps", "train_seconds")):
                    xs = [p[x] for p in curve["points"]]
                    m = [p["success"][0] for p in curve["points"]]
                    lo = [p["success"][1] for p in curve["points"]]
                    hi = [p["success"][2] for p in curve["points"]]
                    ax = c.axes[i, j]
                    ax.plot(xs, m, color=colours[algo], lw=1.6, marker="o", ms=3,
                            label=f"{algo} ({len(curve['seeds'])} seeds)")  # fmt: skip
                    ax.fill_between(xs, np.clip(lo, 0, 1), np.clip(hi, 0, 1), color=colours[algo], alpha=0.15)
            c.axes[0, j].set_title(env_id)
            c.axes[0, j].set_xlabel("env steps")
            c.axes[1, j].set_xlabel("training time (s)")
            for i in range(2):
                fraction_axis(c.axes[i, j], "success on held-out episodes" if j == 0 else None)
                c.axes[i, j].grid(alpha=0.3)
        c.title("Learning curves from scratch: mean over the training seeds, 95 % t-interval")
        c.legend(where="below", ncol=4)
        c.caption(CURVES_CAPTION)
    return Path(png)


def plot_iqm(data: dict[str, Any], png: str | Path) -> Path:
    """The suite's IQM of the normalised score per algorithm with its 95 % stratified bootstrap interval."""
    from flatbody_env.figures import PALETTE, chart

    q = data["final"]["iqm"]
    algos = sorted(q, key=lambda a: q[a]["iqm"])
    colours = _colours(algos)
    with chart(png, size=(7.0, 1.6 + 0.45 * len(algos))) as c:
        ax = c.ax
        for i, a in enumerate(algos):
            ax.errorbar([q[a]["iqm"]], [i], xerr=[[q[a]["iqm"] - q[a]["lo"]], [q[a]["hi"] - q[a]["iqm"]]], fmt="o",
                        color=colours[a], capsize=4)  # fmt: skip
        ax.set_yticks(range(len(algos)), [f"{a} ({q[a]['runs']} seeds × {q[a]['tasks']} tasks)" for a in algos])
        ax.axvline(0.0, color=PALETTE["goal"], lw=0.8, ls=":")
        ax.axvline(1.0, color=PALETTE["goal"], lw=0.8, ls=":")
        ax.set_xlabel("IQM of the normalised score (0: best classic controller, 1: best known)")
        ax.grid(axis="x", alpha=0.3)
        c.caption(IQM_CAPTION)
    return Path(png)


SENSITIVITY_CAPTION = (
    "Each point: the algorithm trained from scratch with one value of the hyperparameter (every other entry as in its "
    "YAML file), its final success on the held-out episodes, mean over the training seeds and its 95 % t-interval."
)


def sensitivity(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """A hyperparameter grid's answer (rows from ``--hyperparam-grid``): per ``base_algo|env_id`` the grid's values
    (sorted) and the final success at each (mean, lo, hi over the seeds); empty without a grid."""
    groups: dict[str, dict[float, list[float]]] = {}
    name = None
    for r in rows:
        if not r.get("overrides"):
            continue
        key, _, value = r["overrides"][0].partition("=")
        name = key
        cell = groups.setdefault(f"{r['base_algo']}|{r['env_id']}", {})
        cell.setdefault(float(value), []).append(r["final"]["success_rate"])
    out = {}
    for key, by_value in groups.items():
        values = sorted(by_value)
        out[key] = {"values": values, "success": [mean_interval(by_value[v]) for v in values],
                    "seeds": [len(by_value[v]) for v in values]}  # fmt: skip
    return {"hyperparam": name, "cells": out} if out else {}


def plot_sensitivity(data: dict[str, Any], png: str | Path) -> Path:
    """Final success against the grid's hyperparameter (:func:`sensitivity`), one line per algorithm and task; a
    logarithmic axis for a positive grid that spans a decade or more."""
    from flatbody_env.figures import CYCLE, chart, fraction_axis

    sens = data["sensitivity"]
    with chart(png, size=(7.0, 4.4)) as c:
        ax = c.ax
        values = [v for cell in sens["cells"].values() for v in cell["values"]]
        for k, (key, cell) in enumerate(sorted(sens["cells"].items())):
            algo, env_id = key.split("|")
            xs = cell["values"]
            m, lo, hi = (np.array([p[i] for p in cell["success"]]) for i in range(3))
            colour = COLOURS.get(algo) if len(sens["cells"]) == 1 else CYCLE[k % len(CYCLE)]
            ax.plot(
                xs, m, color=colour, lw=1.6, marker="o", ms=4, label=f"{algo} on {env_id} ({min(cell['seeds'])} seeds)"
            )
            ax.fill_between(xs, np.clip(lo, 0, 1), np.clip(hi, 0, 1), color=colour, alpha=0.15)
        if min(values) > 0 and max(values) >= 10 * min(values):
            ax.set_xscale("log")
        ax.set_xlabel(sens["hyperparam"])
        fraction_axis(ax, "final success on held-out episodes")
        ax.grid(alpha=0.3)
        c.title(f"Sensitivity to {sens['hyperparam']}: final success, mean and 95 % t-interval over the seeds")
        c.legend(where="below", ncol=2)
        c.caption(SENSITIVITY_CAPTION)
    return Path(png)


LONGER_BUDGETS = DATA_DIR / "rsl-ppo-longer-budgets.json"
"""rsl-ppo's v1 entry trained past the table's budget (docs/tasks.md, "Longer budgets on the hard tasks"): each run's
commands and final held-out success (``rows``), the checkpoints evaluated on the way (``checkpoints``)."""
MARK = 2_500_000
"""Env steps between the marks where the longer-budget chart averages over the training seeds."""
LONGER_CAPTION = (
    "Each thin line: one training seed of rsl-ppo's v1 entry (unchanged but for its budget), its deterministic policy "
    "on the table's 100 held-out episodes (seeds 10000-10099, never trained on) at checkpoints along the run. Black: "
    "the mean over the seeds with its 95 % t-interval, where every seed (three or more) has a point. Dashed: the best "
    "classic controller on the same episodes (LQR: the linear-quadratic regulator; LQR + pumping: the LQR with the "
    "out-of-plane spin's centrifugal force pumped against the mode it cannot settle); dotted: the model-predictive "
    "planner; dash-dotted, open triangles: a run of the entry with the overrides its label names (another task where "
    "they change the environment), outside the mean."
)


def longer_budget_points(data: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Per task of the longer-budget table (:data:`LONGER_BUDGETS`): each training seed's held-out success along its
    run (``seeds``: seed -> sorted (env steps, success) from the evaluated checkpoints and the rows of the entry as it
    is, without hyperparameter overrides), each variant's run apart (``variants``: (overrides, seed) -> sorted points,
    the overrides joined by spaces as ``flatbody train --hyperparams`` took them) and, at each mark of :data:`MARK`
    env steps where every seed of the entry (three or more) has a point within a tenth of a mark, the mean over those
    seeds with its 95 % t-interval (``means``: (mark, mean, lo, hi))."""
    out: dict[str, dict[str, Any]] = {}
    for r in [*data.get("rows", []), *data.get("checkpoints", [])]:
        task = out.setdefault(r["env_id"], {"seeds": {}, "variants": {}, "means": []})
        # a variant of the entry (its own rows in the table) is drawn apart, never in the entry's mean
        runs, key = ((task["variants"], (" ".join(r["hyperparams"]), int(r["seed"]))) if r.get("hyperparams")
                     else (task["seeds"], int(r["seed"])))  # fmt: skip
        runs.setdefault(key, {})[int(r["n_timesteps"])] = float(r["success_rate"])
    for task in out.values():
        task["seeds"] = {s: sorted(pts.items()) for s, pts in sorted(task["seeds"].items())}
        task["variants"] = {k: sorted(pts.items()) for k, pts in sorted(task["variants"].items())}
        if len(task["seeds"]) < 3:  # two seeds: a t-interval of 12.7 standard errors says nothing
            continue
        last = max(n for pts in task["seeds"].values() for n, _ in pts)
        for k in range(1, round(last / MARK) + 1):
            near = [[v for n, v in pts if abs(n - k * MARK) <= MARK / 10] for pts in task["seeds"].values()]
            if all(near):
                task["means"].append((k * MARK, *mean_interval([v[0] for v in near])))
    return out


def plot_longer_budgets(png: str | Path, data: dict[str, Any] | None = None, reports=None) -> Path:
    """The longer-budget chart: held-out success against env steps per task (:func:`longer_budget_points`), the
    best classic controller and the planner of the task's saved reference report as lines. ``data``: the table
    (default :data:`LONGER_BUDGETS`); ``reports``: the reference reports (default the shipped ones)."""
    from agents.reference import POLICY_LABELS, load_reports
    from agents.scores import CLASSIC, anchors
    from flatbody_env.env.registration import V1_IDS
    from flatbody_env.figures import CYCLE, PALETTE, chart, fraction_axis
    from flatbody_env.physics import validation
    from matplotlib.ticker import FuncFormatter

    if data is None:
        data = validation.read_json("longer budgets", LONGER_BUDGETS)
    by_env = {r["env_id"]: r for r in (reports if reports is not None else load_reports())}
    points = longer_budget_points(data)
    envs = [e for e in V1_IDS if e in points]
    variant_colour = itertools.count(max(len(points[e]["seeds"]) for e in envs))
    with chart(png, size=(max(6.4, 3.6 * len(envs)), 4.6), ncols=len(envs), sharey=True) as c:
        for j, env_id in enumerate(envs):
            ax, task = c.axes[0, j], points[env_id]
            for k, (seed, pts) in enumerate(task["seeds"].items()):
                xs, ys = zip(*pts)
                ax.plot(xs, ys, color=CYCLE[k % len(CYCLE)], lw=1.0, marker="o", ms=3, alpha=0.8,
                        label=f"seed {seed}" if j == 0 else None)  # fmt: skip
            for (overrides, seed), pts in task["variants"].items():  # colours after every task's seeds'
                xs, ys = zip(*pts)
                ax.plot(xs, ys, color=CYCLE[next(variant_colour) % len(CYCLE)], lw=1.0, ls="-.", marker="^",
                        ms=4, mfc="none", label=f"seed {seed}, {overrides}")  # fmt: skip
            if task["means"]:
                x, m, lo, hi = (np.array(v) for v in zip(*task["means"]))
                ax.errorbar(x, m, yerr=[m - np.clip(lo, 0, 1), np.clip(hi, 0, 1) - m], color=PALETTE["reference"],
                            lw=1.8, capsize=4, marker="s", ms=4,
                            label=f"mean over {len(task['seeds'])} seeds")  # fmt: skip
            lines = []
            report = by_env.get(env_id)
            if report is not None:
                a = anchors(report)
                if a.lo_from in CLASSIC:
                    ax.axhline(a.lo, color=PALETTE["goal"], lw=1.0, ls="--",
                               label="best classic controller" if j == 0 else None)  # fmt: skip
                    lines.append(f"{POLICY_LABELS.get(a.lo_from, a.lo_from)} {a.lo:.0%}")
                planner = report.get("policies", {}).get("planner", {}).get("summary", {}).get("success_rate")
                if planner is not None:
                    ax.axhline(planner, color=PALETTE["goal"], lw=1.0, ls=":", label="planner" if j == 0 else None)
                    lines.append(f"planner {planner:.0%}")
            ax.set_title("\n".join([env_id, " · ".join(lines)] if lines else [env_id]))
            ax.set_xlabel("env steps (millions)")
            ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1e6:g}"))
            ax.set_xlim(0, None)
            fraction_axis(ax, "success on held-out episodes" if j == 0 else None)
            ax.grid(alpha=0.3)
        c.title("rsl-ppo past the table's budget: held-out success along each training run")
        c.legend(where="below", ncol=min(6, 3 * len(envs)))
        c.caption(LONGER_CAPTION)
    return Path(png)


def markdown(data: dict[str, Any], command: str) -> str:
    """The docs block of the final table (the command that made it beside it)."""
    from agents.reference import POLICY_LABELS
    from flatbody_env.env.registration import V1_IDS

    f = data["final"]
    algos = sorted({c["algo"] for c in f["cells"].values()}, key=_order)
    lines = [
        "| task | score 0 (best classic) → 1 | " + " | ".join(algos) + " |",
        "|---|---|" + "---|" * len(algos),
    ]
    for env_id in [e for e in V1_IDS if any(c["env_id"] == e for c in f["cells"].values())]:
        a = f["anchors"].get(env_id)
        anchor = "—"
        if a:
            lo_from, hi_from = (POLICY_LABELS.get(a[k], a[k]) for k in ("lo_from", "hi_from"))
            anchor = f"{a['lo']:.0%} ({lo_from}) → {a['hi']:.0%} ({hi_from.split(' (')[0]})"
        row = [env_id, anchor]
        for algo in algos:
            c = f["cells"].get(f"{algo}|{env_id}")
            if c is None:
                row.append("—")
                continue
            m, lo, hi = c["success_mean"]
            score = c.get("score_mean")
            extra = f"; score {score[0]:.2f}" if score is not None else ""
            row.append(f"{m:.0%} ({max(lo, 0):.0%}–{min(hi, 1):.0%}){extra}; {c['budget']:,} steps, "
                       f"{np.mean(c['train_seconds']) / 60:.1f} min")  # fmt: skip
        lines.append("| " + " | ".join(row) + " |")
    if f["iqm"]:
        lines += [
            "",
            "| algorithm | IQM of the normalised score (95 % stratified bootstrap) | seeds × tasks |",
            "|---|---|---|",
        ]
        for a in algos:
            if a in f["iqm"]:
                q = f["iqm"][a]
                lines.append(f"| {a} | {q['iqm']:.2f} ({q['lo']:.2f}–{q['hi']:.2f}) | {q['runs']} × {q['tasks']} |")
    lines += ["", f"Success on {FINAL_EPISODES} held-out episodes, mean over the training seeds with its 95 % t-interval; "
              f"training time per run on 2 shared cores. Regenerate: `{command}`."]  # fmt: skip
    return "\n".join(lines)


__all__ = [
    "ALGOS",
    "BUDGETS",
    "EVAL_POINTS",
    "curves",
    "final_table",
    "markdown",
    "mean_interval",
    "plot_sensitivity",
    "report",
    "run_case",
    "sensitivity",
    "variant_label",
]
