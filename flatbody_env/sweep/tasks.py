"""The tasks of a sweep: each a pure function of its key.

A sweep is given by a *specification* (a JSON-able dict: the kind and its parameters, stored with
the results and checked on ``--resume``); :func:`plan` turns it into tasks. A :class:`Task` carries
its key and the plain parameters its function needs; :func:`execute` runs it on whichever worker
Dask picked and returns the outcome (a failure becomes an error record, never an exception), so the
same key gives the same rows in this process, in a local process pool or on a remote worker.

======================= =========================================== ============================
kind                    one task                                    key (sorts like the serial
                                                                    command's output)
======================= =========================================== ============================
``stability-map``       a chunk of λ rows of the shape grid         ``lam-000000-000004``
                        (:func:`analysis.families.shape_stability_grid`)
``failure-study``       one method along one study axis, with the   ``00-gap-03-RK4``
                        serial command's stop rule
                        (:func:`analysis.failure_study.failure_study`)
``family``              one body, one varied parameter, one range   ``000-00-000``
                        (:func:`analysis.families.follow_family`)
``seeds``               train one seed, evaluate it on held-apart   ``seed-000003``
                        episodes (:mod:`agents.train`, :mod:`agents.evaluate`); the seed is read
                        from the key
``benchmark``           train one algorithm on one task with one    ``ppo.FlatBody-v1.000003``
                        seed from scratch, evaluated along the way
                        (:func:`agents.benchmark.run_case`)
======================= =========================================== ============================
"""

from __future__ import annotations

import math
import os
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable

from agents.evaluate import EVAL_SEED  # the first evaluation seed of a seeds sweep (re-exported)
from flatbody_env.physics import validation
from flatbody_env.physics.validation import SWEEP_GRID_RANGE

KINDS = ("stability-map", "failure-study", "family", "seeds", "benchmark")
SERIAL_ONLY = ("work-precision", "chart", "bench")
"""Timing studies: they stay serial (concurrent runs on shared cores skew wall time)."""
MAX_GRID = SWEEP_GRID_RANGE[1]
"""Largest stability-map grid per axis (:data:`~flatbody_env.physics.validation.SWEEP_GRID_RANGE`; the serial
command stops at :data:`~flatbody_env.physics.validation.MAP_GRID_RANGE`)."""


@dataclass(frozen=True, kw_only=True)
class Task:
    """One unit of work.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    key : str
        Unique within the sweep; the output is sorted by it.
    params : dict
        Plain (JSON-able) parameters of the task's function.
    """

    kind: str
    key: str
    params: dict[str, Any]


@dataclass(frozen=True, kw_only=True)
class Outcome:
    """What a worker sends back: the rows or the error, the run time and the worker."""

    key: str
    payload: Any
    error: str | None
    seconds: float
    worker: str


# ---------------------------------------------------------------------------------------------
# the task functions (pure: everything comes from the task)
def stability_map_chunk(task: Task) -> list[dict[str, Any]]:
    """Rows of the shape stability map for λ rows ``[i0, i1)`` of the grid (every μ)."""
    import numpy as np

    from analysis.families import shape_stability_grid
    from flatbody_env.physics.body import Body

    p = task.params
    lam = np.linspace(p["lam_range"][0], p["lam_range"][1], p["grid"])
    mu = np.linspace(p["mu_range"][0], p["mu_range"][1], p["grid"])
    i0, i1 = p["rows"]
    return shape_stability_grid(Body.from_dict(p["body"]), lam[i0:i1], mu)


def failure_case(task: Task) -> list[dict[str, Any]]:
    """One method along one axis of the failure study: the rows the serial study gives for it."""
    from analysis.failure_study import failure_study
    from flatbody_env.answers import failure_rows

    p = task.params
    points = failure_study(
        (p["study"],), (p["method"],), quick=p["quick"], repeats=p["repeats"], max_run_s=p["max_run_s"], progress=False
    )
    return failure_rows(points)


def family_case(task: Task) -> dict[str, Any]:
    """One family (:func:`analysis.families.follow_family`): the ``family --json`` object, its
    table written to ``params["csv"]``, plus the body it belongs to."""
    from analysis.families import follow_family, write_family_csv
    from analysis.stationary import SearchBox
    from flatbody_env.answers import family_summary
    from flatbody_env.physics.body import Body

    p = task.params
    body = Body.from_dict(p["body"])
    box = SearchBox(lam=tuple(p["box"]["lam"]), mu=tuple(p["box"]["mu"]), n=p["box"]["n"])
    fam = follow_family(
        body,
        p["vary"],
        p["start"],
        p["stop"],
        s3=p["s3"],
        p_theta=p["p_theta"],
        seeds=p["seeds"],
        box=box,
        step=p["step"],
    )
    csv = Path(p["csv"])
    csv.parent.mkdir(parents=True, exist_ok=True)
    write_family_csv(fam, csv)
    return {"body": p["body_label"], **family_summary(fam, csv=p["csv_name"])}


def seed_of(key: str) -> int:
    """The seed a ``seeds`` task key names (``seed-000003`` → 3)."""
    prefix, _, number = key.partition("-")
    if prefix != "seed" or not number.isdigit():
        raise ValueError(f"key: a seeds task key is 'seed-NNNNNN', got {key!r}")
    return int(number)


def seed_case(task: Task) -> dict[str, Any]:
    """Train one configuration with the key's seed, then evaluate the agent on ``episodes``
    held-apart episodes (seeds ``eval_seed`` …). The model stays in ``params["model_dir"]``."""
    from agents.evaluate import Agent, run_episodes, summarize
    from agents.train import train

    p = task.params
    seed = seed_of(task.key)
    out = Path(p["model_dir"])
    train(
        p["algo"],
        out,
        env_id="FlatBody-v0",  # the task of the seeds sweep (its hyperparameters: the YAML's FlatBody-v0 entry)
        seed=seed,
        n_timesteps=p["n_timesteps"],
        n_envs=p["n_envs"],
        overrides=list(p["overrides"]),
        hyperparams_file=p["hyperparams_file"],
        checkpoint_freq=0,
        threads=1,
        progress=False,
        force=True,
        notes=False,
        command=["flatbody", "sweep", "seeds", f"--algo={p['algo']}", f"--seed={seed}"],
    )
    agent = Agent(out)
    summary = summarize(
        run_episodes(
            agent, episodes=p["episodes"], seed=p["eval_seed"], env_kwargs=agent.env_kwargs, env_id=agent.env_id
        )
    )
    return {"seed": seed, "model": p["model_name"], **summary}


def benchmark_case(task: Task) -> dict[str, Any]:
    """One case of the benchmark table (:func:`agents.benchmark.run_case`): its algorithm, task and seed from the
    parameters, its run folder under the benchmark's folder."""
    from agents.benchmark import run_case

    p = task.params
    overrides = list(p.get("overrides") or [])
    fixed = list(p.get("hyperparams") or [])
    device = p.get("device", "cpu")
    flags = [f"--device={device}"] if device != "cpu" else []
    flags += (["--hyperparams", *fixed] if fixed else []) + [f"--hyperparam-grid={o}" for o in overrides]
    return run_case(
        p["algo"],
        p["env_id"],
        p["seed"],
        p["budget"],
        p["run_dir"],
        eval_seed=p["eval_seed"],
        command=[
            "flatbody",
            "benchmark",
            f"--algos={p['algo']}",
            f"--envs={p['env_id']}",
            f"--seeds={p['seed']}",
            *flags,
        ],
        overrides=overrides,
        hyperparams=fixed,
        device=device,
    )


RUNNERS: dict[str, Callable[[Task], Any]] = {
    "stability-map": stability_map_chunk,
    "failure-study": failure_case,
    "family": family_case,
    "seeds": seed_case,
    "benchmark": benchmark_case,
}


def execute(task: Task) -> Outcome:
    """Run ``task`` and return its :class:`Outcome`; an exception becomes the one-line error
    ``"Type: message (file:line)"`` so that the sweep goes on."""
    t0 = time.perf_counter()
    try:
        from distributed import get_worker

        worker = get_worker().address
    except (ImportError, ValueError):
        worker = f"local:{os.getpid()}"
    try:
        payload = RUNNERS[task.kind](task)
        error = None
    except Exception as exc:  # recorded, the sweep goes on
        payload = None
        frame = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
        where = f" ({Path(frame.filename).name}:{frame.lineno})" if frame else ""
        error = f"{type(exc).__name__}: {' '.join(str(exc).split())}{where}"
    return Outcome(key=task.key, payload=payload, error=error, seconds=time.perf_counter() - t0, worker=worker)


# ---------------------------------------------------------------------------------------------
# plans: specification → tasks
TASK_POINTS = 512
"""Grid points a stability-map task holds by default: enough that a task's cost dwarfs the scheduler
overhead per task (both measured by ``flatbody bench sweep``; docs/scaling.md, "Measured scaling")."""


def default_chunk(grid: int) -> int:
    """λ rows per stability-map task: about :data:`TASK_POINTS` grid points, at least one row (so
    a large grid gives one task per row: enough tasks for any cluster)."""
    return max(1, min(grid, math.ceil(TASK_POINTS / grid)))


def extends(stored: dict[str, Any], spec: dict[str, Any]) -> bool:
    """Whether ``spec`` only adds algorithms to the benchmark ``stored``: same tasks, seeds and evaluation seed, the
    stored algorithms a subset, each at its stored budget — so no stored row (keyed by algorithm, task and seed) changes
    meaning, and a resumed benchmark trains only the new algorithm's runs.

    Parameters
    ----------
    stored, spec : dict
        The stored sweep specification and the requested one.
    """
    if stored.get("kind") != "benchmark" or spec.get("kind") != "benchmark":
        return False
    if any(stored.get(k) != spec.get(k) for k in ("envs", "seeds", "eval_seed", "grid", "device", "hyperparams")):
        return False
    old, new = stored.get("algos") or [], spec.get("algos") or []
    if not set(old) <= set(new):
        return False
    budgets_old, budgets_new = stored.get("budgets") or {}, spec.get("budgets") or {}
    return all(budgets_old.get(a) == budgets_new.get(a) for a in old)


def plan(spec: dict[str, Any], out: str | Path) -> list[Task]:
    """The tasks of the sweep ``spec`` (their outputs go under ``out``), in key order."""
    kind = spec.get("kind")
    if kind in SERIAL_ONLY:
        raise ValueError(serial_only_message(kind))
    validation.requirement("kind", kind, kind in KINDS, f"be one of {', '.join(KINDS)}")
    out = Path(out).resolve()  # workers elsewhere write files (family tables, models) at this absolute path
    tasks: list[Task] = []
    if kind == "stability-map":
        grid, chunk = spec["grid"], spec["chunk"]
        for i0 in range(0, grid, chunk):
            i1 = min(grid, i0 + chunk)
            tasks.append(
                Task(
                    kind=kind,
                    key=f"lam-{i0:06d}-{i1:06d}",
                    params={
                        "body": spec["body"],
                        "lam_range": spec["lam_range"],
                        "mu_range": spec["mu_range"],
                        "grid": grid,
                        "rows": [i0, i1],
                    },
                )
            )
    elif kind == "failure-study":
        for si, study in enumerate(spec["studies"]):
            for mi, method in enumerate(spec["methods"]):
                tasks.append(
                    Task(
                        kind=kind,
                        key=f"{si:02d}-{study}-{mi:02d}-{method}",
                        params={
                            "study": study,
                            "method": method,
                            "quick": spec["quick"],
                            "repeats": spec["repeats"],
                            "max_run_s": spec["max_run_s"],
                        },
                    )
                )
    elif kind == "family":
        for bi, (label, body) in enumerate(spec["bodies"]):
            for vi, vary in enumerate(spec["vary"]):
                for ri, (start, stop) in enumerate(spec["ranges"]):
                    key = f"{bi:03d}-{vi:02d}-{ri:03d}"
                    name = f"families/{key}.csv"
                    tasks.append(
                        Task(
                            kind=kind,
                            key=key,
                            params={
                                "body": body,
                                "body_label": label,
                                "vary": vary,
                                "start": start,
                                "stop": stop,
                                "s3": spec["s3"],
                                "p_theta": spec["p_theta"],
                                "seeds": spec["seeds"],
                                "box": spec["box"],
                                "step": spec["step"],
                                "csv": str(out / name),
                                "csv_name": name,
                            },
                        )
                    )
    elif kind == "benchmark":  # seed by seed: a benchmark stopped early holds whole seeds of every algorithm and task
        grid = spec.get("grid")  # a hyperparameter grid: each algorithm once per value
        variants = [[f"{grid['key']}={v}"] for v in grid["values"]] if grid else [[]]
        fixed = list(spec.get("hyperparams") or [])
        device = spec.get("device", "cpu")
        for seed in spec["seeds"]:
            for algo in spec["algos"]:
                for overrides in variants:
                    for env_id in spec["envs"]:
                        name = "@".join([algo, *fixed, *overrides, *([f"device={device}"] if device != "cpu" else [])])
                        key = f"{name}.{env_id}.{seed:06d}"
                        tasks.append(
                            Task(
                                kind=kind,
                                key=key,
                                params={
                                    "algo": algo,
                                    "overrides": overrides,
                                    **({"hyperparams": fixed} if fixed else {}),
                                    **({"device": device} if device != "cpu" else {}),
                                    "env_id": env_id,
                                    "seed": seed,
                                    "budget": spec["budgets"][algo],
                                    "eval_seed": spec["eval_seed"],
                                    "run_dir": str(out / "runs" / key),
                                },
                            )
                        )
    else:  # seeds
        for seed in spec["seeds"]:
            name = f"models/seed-{seed}"
            tasks.append(
                Task(
                    kind=kind,
                    key=f"seed-{seed:06d}",
                    params={
                        "algo": spec["algo"],
                        "n_timesteps": spec["n_timesteps"],
                        "n_envs": spec["n_envs"],
                        "overrides": spec["overrides"],
                        "hyperparams_file": spec["hyperparams_file"],
                        "episodes": spec["episodes"],
                        "eval_seed": spec["eval_seed"],
                        "model_dir": str(out / name),
                        "model_name": name,
                    },
                )
            )
    if kind == "benchmark":
        return tasks  # in the order made above (seed by seed); the output is sorted by key all the same
    return sorted(tasks, key=lambda t: t.key)


def serial_only_message(kind: str) -> str:
    return (
        f"kind: {kind} is a timing study and stays serial (concurrent runs on shared cores skew wall time); "
        "run 'flatbody chart' or 'flatbody bench ...' instead"
    )


def parse_seeds(text: str) -> list[int]:
    """``"0-7"``, ``"0,3,5"`` or ``"0-3,9"`` → sorted distinct seeds (each ≥ 0); ``ValueError``
    naming ``seeds`` otherwise."""
    seeds: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part:
                lo, hi = (int(x) for x in part.split("-"))
            else:
                lo = hi = int(part)
        except ValueError:
            raise ValueError(
                f"seeds: expected ranges like 0-7 or lists like 0,3,5 (integers >= 0), got {text!r}"
            ) from None
        if lo < 0 or hi < lo or hi - lo > 10_000:
            raise ValueError(f"seeds: need 0 <= FIRST <= LAST (at most 10000 apart), got {part!r}")
        seeds.update(range(lo, hi + 1))
    return sorted(seeds)


__all__ = [
    "EVAL_SEED",
    "KINDS",
    "MAX_GRID",
    "Outcome",
    "RUNNERS",
    "SERIAL_ONLY",
    "TASK_POINTS",
    "Task",
    "extends",
    "default_chunk",
    "execute",
    "parse_seeds",
    "plan",
    "seed_of",
    "serial_only_message",
]
