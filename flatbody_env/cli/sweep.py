"""Sub-commands ``sweep`` and ``tune``: the same studies on many cores or machines (``bench sweep``:
:mod:`flatbody_env.cli.bench`).

* ``flatbody sweep KIND ... --out DIR [--workers N | --scheduler tcp://HOST:8786] [--resume] [--json]``
  with KIND ``stability-map``, ``failure-study``, ``family`` or ``seeds`` (:mod:`flatbody_env.sweep`):
  tasks on an embedded Dask cluster (``--workers N``: N local processes; 1: in this process; 0: no
  Dask) or a running one (``--scheduler``); results by key in ``DIR/results.sqlite``; ``--resume``
  continues a killed sweep. ``sweep work-precision`` says why timing studies stay serial.
* ``flatbody tune --algo ppo|sac --trials N ...`` — Optuna search (:mod:`agents.tune`).
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from pathlib import Path
from typing import Any

from flatbody_env.cli.args import float_range, int_at_least, positive_float
from flatbody_env.physics import validation


def _run(args, spec) -> int:
    from flatbody_env.sweep.report import as_json, format_report
    from flatbody_env.sweep.runner import run_sweep

    report = run_sweep(
        spec,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        resume=args.resume,
        progress=not args.no_progress,
    )
    written = _write_table(spec, report, Path(args.out), getattr(args, "plot", None))
    if args.json:
        print(json.dumps(as_json(report)))
    else:
        print(format_report(report))
        print("wrote " + ", ".join(map(str, written)))
    if report.failed:
        sys.stderr.write(
            f"flatbody sweep: {len(report.failed)} of {report.total} tasks failed (recorded in {Path(args.out) / 'results.sqlite'};"
            " --resume retries them)\n"
        )
        return 1
    return 0


def _write_table(spec, report, out: Path, plot: str | None) -> list[Path]:
    """Write the sweep's table (and chart); the files the sweep holds, the results database first."""
    from flatbody_env.sweep.report import rows_of

    rows = rows_of(report)
    kind = spec["kind"]
    written = [out / "results.sqlite"]
    if kind == "stability-map":
        from analysis.families import write_table_csv

        csv = write_table_csv(rows, out / "stability_map.csv")
        written.append(csv)
        if plot is not None:
            from analysis.plots import plot_shape_map
            from flatbody_env.physics.body import Body

            plot_shape_map(csv, plot, title=f"Stationary ellipses by shape, {Body.from_dict(spec['body']).describe()}")
            written.append(Path(plot))
    elif kind in ("failure-study", "seeds") and rows:
        from analysis.families import write_table_csv

        written.append(write_table_csv(rows, out / f"{kind.replace('-', '_')}.csv", columns=tuple(rows[0])))
    elif kind == "family":
        written += sorted({out / r["csv"] for r in rows if r.get("csv")})
    return written


# ---------------------------------------------------------------------------------------------
def _stability_map(args) -> int:
    from flatbody_env.cli.analysis import resolve_body
    from flatbody_env.sweep.tasks import MAX_GRID, default_chunk

    body, _, _ = resolve_body(args, need_spins=False)
    validation.integer("--grid", args.grid, low=validation.SWEEP_GRID_RANGE[0], high=MAX_GRID)
    chunk = args.chunk or default_chunk(args.grid)
    validation.requirement("--chunk", chunk, chunk <= args.grid, f"be an integer in [1, {args.grid}] (the grid)")
    spec = {
        "kind": "stability-map",
        "body": body.to_dict(),
        "lam_range": list(args.lam_range),
        "mu_range": list(args.mu_range),
        "grid": args.grid,
        "chunk": chunk,
    }
    return _run(args, spec)


def _failure_study(args) -> int:
    from analysis.failure_study import DEFAULT_METHODS, STUDIES
    from flatbody_env.integrators import get_method

    studies = list(args.studies or STUDIES)
    for s in studies:
        if s not in STUDIES:
            raise ValueError(f"studies: unknown study {s!r} (allowed: {', '.join(STUDIES)})")
    methods = list(args.methods or DEFAULT_METHODS)
    for m in methods:
        get_method(m)  # ValueError naming the allowed methods
    max_run_s = args.max_run_s if args.max_run_s is not None else (1.0 if args.quick else 5.0)
    spec = {
        "kind": "failure-study",
        "studies": studies,
        "methods": methods,
        "quick": bool(args.quick),
        "repeats": args.repeats,
        "max_run_s": max_run_s,
    }
    return _run(args, spec)


_BODY_FIELDS = {"V1": ("k",), "V2": ("c", "d"), "V3": ("kappa",)}


def parse_body(text: str) -> tuple[str, dict]:
    """A body for ``sweep family --bodies``: ``V3:kappa=2,a=1`` (unset constants 1) or a scene
    (built-in name or JSON file). Returns (label, the body's JSON form)."""
    from flatbody_env.physics.body import Body

    if ":" not in text and not text.startswith(("V1", "V2", "V3")):
        from flatbody_env.scene import load_scene

        return text, load_scene(text).body.to_dict()
    pot, _, rest = text.partition(":")
    if pot not in _BODY_FIELDS:
        raise ValueError(f"bodies: expected V1|V2|V3[:NAME=VALUE,...] or a scene, got {text!r}")
    allowed = (*_BODY_FIELDS[pot], "a", "b", "J", "J3")
    val = dict.fromkeys(allowed, 1.0)
    for item in filter(None, (x.strip() for x in rest.split(","))):
        name, eq, number = item.partition("=")
        if not eq or name not in allowed:
            raise ValueError(
                f"bodies: {text!r}: expected NAME=VALUE with NAME one of {', '.join(allowed)}, got {item!r}"
            )
        try:
            val[name] = float(number)
        except ValueError:
            raise validation.refusal(f"bodies: {text!r}", f"give {name} as a number", number) from None
    body = Body.from_dict(
        {
            "params": {"J": val["J"], "J3": val["J3"]},
            "potential": {"name": pot, **{c: val[c] for c in _BODY_FIELDS[pot]}},
            "thickness": {"a": val["a"], "b": val["b"]},
        },
        where="bodies",
    )
    return text, body.to_dict()


def _family(args) -> int:
    from analysis.families import DEFAULT_P_THETA, DEFAULT_S3, PARAMETERS, check_range
    from flatbody_env.cli.analysis import _box, resolve_body

    if args.bodies:
        bodies = [parse_body(b) for b in args.bodies]
    else:
        body, _, _ = resolve_body(args, need_spins=False)
        bodies = [(body.describe(), body.to_dict())]
    for v in args.vary:
        validation.string("--vary", v, choices=PARAMETERS)
    ranges = [list(r) for r in args.ranges]
    for v in args.vary:  # each range as the family of each parameter takes it: refused here naming --ranges,
        for lo_hi in ranges:  # never as a failed task naming the task's start/stop
            try:
                check_range(v, *lo_hi, names=("--ranges", "--ranges"))
            except ValueError as exc:
                raise ValueError(f"{exc} (the range {lo_hi[0]:g},{lo_hi[1]:g} with --vary {v})") from None
    lo, hi = validation.FAMILY_SEEDS_RANGE
    validation.integer("--seeds", args.seeds, low=lo, high=hi)
    box = _box(args)
    spec = {
        "kind": "family",
        "bodies": [list(b) for b in bodies],
        "vary": list(args.vary),
        "ranges": ranges,
        "s3": DEFAULT_S3 if args.s3 is None else args.s3,
        "p_theta": DEFAULT_P_THETA if args.p_theta is None else args.p_theta,
        "seeds": args.seeds,
        "step": args.step,
        "box": {"lam": list(box.lam), "mu": list(box.mu), "n": box.n},
    }
    for name in ("s3", "p_theta"):
        validation.number(f"--{name.replace('_', '-')}", spec[name])
    return _run(args, spec)


def _seeds(args) -> int:
    from agents.config import load_hyperparams
    from flatbody_env.sweep.tasks import parse_seeds

    load_hyperparams(args.algo, path=args.hyperparams_file)  # ValueError naming the file
    spec = {
        "kind": "seeds",
        "algo": args.algo,
        "seeds": parse_seeds(args.seeds),
        "n_timesteps": args.n_timesteps,
        "n_envs": args.n_envs,
        "overrides": list(args.hyperparams or []),
        "hyperparams_file": None if args.hyperparams_file is None else str(Path(args.hyperparams_file).resolve()),
        "episodes": args.episodes,
        "eval_seed": args.eval_seed,
    }
    # each seed's run folder becomes trusted once its first file is written (agents.train.train), never before
    return _run(args, spec)


def _benchmark(args) -> int:
    """``flatbody benchmark``: the benchmark table (:mod:`agents.benchmark`) on the sweep engine, then its report."""
    from agents.benchmark import ALGOS, BUDGETS, join_rows, report
    from agents.reference import REFERENCE_DIR, load_reports
    from flatbody_env.env.registration import V1_IDS, task_spec
    from flatbody_env.sweep.report import rows_of
    from flatbody_env.sweep.runner import run_sweep
    from flatbody_env.sweep.tasks import parse_seeds

    algos = [a.strip() for a in args.algos.split(",") if a.strip()]
    for a in algos:
        validation.string("--algos", a, choices=ALGOS)
    envs = (
        list(V1_IDS) if args.envs == "all" else [task_spec(e.strip()).env_id for e in args.envs.split(",") if e.strip()]
    )
    budgets = dict(BUDGETS)
    for item in args.budget or []:
        name, _, value = item.partition("=")
        validation.string("--budget", name, choices=ALGOS)
        budgets[name] = validation.integer(f"--budget.{name}", _number(value), low=1_000, high=validation.MAX_TIMESTEPS)
    seeds = parse_seeds(args.seeds)
    if len(seeds) < 2:
        raise ValueError(f"--seeds: a benchmark needs at least 2 training seeds for its intervals, got {args.seeds!r}")
    spec = {
        "kind": "benchmark",
        "algos": algos,
        "envs": envs,
        "seeds": seeds,
        "budgets": budgets,
        "eval_seed": args.eval_seed,
    }
    extra = ""
    if args.device != "cpu":  # a CPU benchmark's specification stays as it was (its store resumes as before)
        from agents.config import check_device

        sb3 = [a for a in algos if a != "rsl-ppo"]
        if sb3:
            raise ValueError(
                f"--device: {args.device} trains rsl-ppo only (SB3's {', '.join(sb3)} run on the CPU); give --algos rsl-ppo"
            )
        spec["device"] = check_device(args.device, "--device")  # no GPU: one line naming --device
        extra += f" --device {args.device}"
    if args.hyperparams:
        spec["hyperparams"] = _fixed_overrides(args.hyperparams, algos, envs)
        extra += " --hyperparams " + " ".join(shlex.quote(item) for item in spec["hyperparams"])
    if args.hyperparam_grid is not None:
        spec["grid"] = _hyperparam_grid(args.hyperparam_grid, algos, envs, spec.get("hyperparams", []))
        extra += f" --hyperparam-grid {args.hyperparam_grid}"
    command = (
        f"flatbody benchmark --algos {','.join(algos)} --envs {args.envs} --seeds {args.seeds} "
        + " ".join(f"--budget {a}={budgets[a]}" for a in algos)
        + extra
        + f" --out {args.out}"
    )
    saved_tables = []  # read and checked before anything trains; the first named wins over the later ones
    for path in args.with_table or []:
        saved_tables.append(validation.read_json("--with", path))
        join_rows([], saved_tables[-1])
        command += f" --with {path}"
    if args.retrain:
        _forget_runs(spec, args)
    result = run_sweep(spec, args.out, workers=args.workers, scheduler=args.scheduler, resume=args.resume,
                       progress=not args.no_progress)  # fmt: skip
    rows = [r for r in rows_of(result) if isinstance(r, dict) and "curve" in r]
    for saved in saved_tables:
        rows = join_rows(rows, saved)
    shown = {r["env_id"] for r in rows}
    references = [r for r in load_reports(REFERENCE_DIR) if r["env_id"] in shown]
    paths = report(rows, args.out, references) if rows else {}
    for path in paths.values():
        print(f"wrote {path}")
    if args.docs and paths:
        from agents.benchmark import markdown
        from flatbody_env.output import replace_marked_block

        replace_marked_block(
            args.docs, "benchmark", markdown(validation.read_json("benchmark report", paths["json"]), command)
        )
        print(f"updated the table in {args.docs}")
    if result.failed:
        sys.stderr.write(
            f"flatbody: {len(result.failed)} of {result.total} runs failed (recorded in "
            f"{Path(args.out) / 'results.sqlite'}; --resume retries them)\n"
        )
        return 1
    return 0


def _forget_runs(spec: dict[str, Any], args) -> None:
    """``--retrain A,B``: the stored runs of these algorithms are removed once the stored benchmark is known to be this
    one (or one it extends), so the resumed benchmark trains them again — after their hyperparameters changed."""
    from flatbody_env.sweep.store import ResultStore
    from flatbody_env.sweep.tasks import extends, plan

    names = [a.strip() for a in args.retrain.split(",") if a.strip()]
    for a in names:
        validation.string("--retrain", a, choices=spec["algos"])
    if not args.resume:
        raise ValueError("--retrain: trains stored runs again, so it needs --resume (and the benchmark's folder)")
    with ResultStore(args.out) as store:
        store.begin(spec, resume=True, extends=extends)  # refuses another benchmark before anything is removed
        keys = [t.key for t in plan(spec, args.out) if t.params["algo"] in names]
        removed = store.forget(keys)
    print(f"--retrain: {removed} stored runs of {', '.join(names)} removed; they train again")


MAX_GRID_VALUES = 16
"""Values of one ``--hyperparam-grid``: each one trains every algorithm, task and seed once more."""


def _fixed_overrides(items: list[str], algos: list[str], envs: list[str]) -> list[str]:
    """``--hyperparams KEY=VALUE ...`` of a benchmark, checked now for every algorithm and task as the runs would check
    them (:func:`agents.config.resolve`), so a bad value stops the benchmark before anything trains."""
    validation.requirement(
        "--hyperparams", items, len(items) <= MAX_GRID_VALUES, f"hold at most {MAX_GRID_VALUES} items"
    )
    for item in items:
        key, sep, _ = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--hyperparams: expected KEY=VALUE (e.g. n_envs=65536), got {item!r:.60}")
    _check_overrides("--hyperparams", list(items), algos, envs)
    return list(items)


def _check_overrides(flag: str, overrides: list[str], algos: list[str], envs: list[str]) -> None:
    """``overrides`` resolved for every algorithm and task as a run resolves them (:func:`agents.config.resolve`);
    ``ValueError`` naming ``flag``, the algorithm and the task otherwise."""
    from agents.config import resolve

    for algo in algos:
        for env_id in envs:
            try:
                resolve(algo, env_id, overrides=overrides)
            except ValueError as e:
                raise ValueError(f"{flag}: {algo} on {env_id}: {e}") from None


def _hyperparam_grid(text: str, algos: list[str], envs: list[str], fixed: list[str] = ()) -> dict[str, Any]:
    """``KEY=V1,V2,...`` as ``{"key", "values"}``, each value checked now — for every algorithm and task, with the
    fixed overrides ``fixed``, as the run would check it (:func:`agents.config.resolve`) — so a bad value stops the
    benchmark before anything trains."""
    key, sep, rest = text.partition("=")
    values = [v.strip() for v in rest.split(",") if v.strip()]
    if not sep or not key.strip() or not values:
        raise ValueError(
            f"--hyperparam-grid: expected KEY=V1,V2,... (e.g. learning_rate=1e-4,3e-4,1e-3), got {text!r:.60}"
        )
    validation.requirement(
        "--hyperparam-grid", text, 2 <= len(values) <= MAX_GRID_VALUES, f"hold 2 to {MAX_GRID_VALUES} values"
    )
    key = key.strip()
    if len(set(values)) != len(values):
        raise ValueError(f"--hyperparam-grid: a value is given twice, got {text!r:.60}")
    for value in values:
        _check_overrides("--hyperparam-grid", [*fixed, f"{key}={value}"], algos, envs)
    return {"key": key, "values": values}


def _number(text: str) -> int:
    """An integer budget written as 500000, 5e5 or 500_000; ValueError naming --budget otherwise."""
    try:
        value = float(text.replace("_", ""))
    except ValueError:
        raise ValueError(f"--budget: expected ALGO=STEPS (e.g. ppo=5e5), got {text!r:.40}") from None
    validation.requirement(
        "--budget", text[:40], math.isfinite(value) and value == int(value), "give steps as a whole number"
    )
    return int(value)


class _SerialOnly(argparse.ArgumentParser):
    """Accepts any arguments: its handler only says why the timing study stays serial."""

    def parse_known_args(self, args=None, namespace=None):
        ns = namespace or argparse.Namespace()
        ns.handler = _serial_only
        ns.sweep_kind = self.prog.split()[-1]
        return ns, []


def _serial_only(args) -> int:
    from flatbody_env.sweep.tasks import serial_only_message

    raise ValueError(serial_only_message(args.sweep_kind))


# ---------------------------------------------------------------------------------------------
def _tune(args) -> int:
    from agents.tune import DEFAULT_STORAGE, TuneConfig, load_search_space, prepare, shares, summary, tune_worker

    cfg = TuneConfig(
        algo=args.algo,
        study=args.study or f"{args.algo}-FlatBody-v0",
        storage=args.storage or DEFAULT_STORAGE,
        trials=args.trials,
        n_timesteps=args.n_timesteps,
        evaluations=args.evaluations,
        eval_episodes=args.eval_episodes,
        n_envs=args.n_envs,
        seed=args.seed,
        overrides=tuple(args.hyperparams or ()),
        search_file=args.search_file,
        out=args.out,
        hyperparams_file=None if args.hyperparams_file is None else str(Path(args.hyperparams_file).resolve()),
    )
    load_search_space(cfg.algo, path=cfg.search_file)  # bad files fail here, in one line
    left = prepare(cfg)
    if args.workers <= 1 and args.scheduler is None:
        tune_worker(cfg)
    elif left > 0:
        from distributed import as_completed

        from flatbody_env.sweep.cluster import dask_client

        with dask_client(workers=args.workers, scheduler=args.scheduler) as client:
            n = args.workers if args.scheduler is None else max(1, len(client.scheduler_info()["workers"]))
            futures = [client.submit(tune_worker, cfg, i, k, pure=False) for i, k in enumerate(shares(left, n))]
            try:
                for fut in as_completed(
                    futures
                ):  # not client.gather: a Ctrl-C there leaves Dask's tasks to print tracebacks
                    fut.result()
            finally:
                for fut in futures:
                    fut.cancel()
    rep = summary(cfg.study, cfg.storage)
    if args.json:
        print(json.dumps(rep))
        return 0
    states: dict[str, int] = {}
    for t in rep["trials"]:
        states[t["state"]] = states.get(t["state"], 0) + 1
    print(
        f"study {rep['study']} ({rep['algo']}) in {cfg.storage}: {len(rep['trials'])} trials ("
        + ", ".join(f"{v} {k.lower()}" for k, v in sorted(states.items()))
        + ")"
    )
    best = rep["best"]
    if best is not None:
        print(
            f"best: trial {best['number']}, final distance {best['value']:.4f}"
            + (f", success rate {best['success_rate']:.0%}" if best["success_rate"] is not None else "")
        )
        for k, v in best["params"].items():
            print(f"  {k} = {v}")
        print(f"retrain: flatbody train --study {rep['study']} --trial-id {best['number']} --storage {cfg.storage}")
    return 0


# ---------------------------------------------------------------------------------------------
def _engine_arguments(p) -> None:
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (results.sqlite, tables, models)")
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--workers",
        type=int_at_least("workers", 0, validation.MAX_WORKERS),
        default=1,
        metavar="N",
        help="embedded Dask cluster: N local worker processes (1: in this process; 0: no Dask); default 1",
    )
    g.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://HOST:8786")
    p.add_argument(
        "--resume", action="store_true", help="continue the sweep in DIR: run only the tasks without a result"
    )
    p.add_argument(
        "--json", action="store_true", help="print all rows sorted by key (the serial command's --json form)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def register(sub) -> None:
    from analysis.families import DEFAULT_FAMILY_RANGE, DEFAULT_SEEDS
    from agents.evaluate import EVAL_SEED
    from flatbody_env.cli.analysis import add_body_arguments, add_box_arguments, add_map_arguments

    sweep = sub.add_parser("sweep", help="run a study as many tasks on Dask (local processes or a cluster), resumable")
    kinds = sweep.add_subparsers(dest="sweep_kind", metavar="KIND", parser_class=sub._parser_class)
    sweep.set_defaults(handler=lambda args: (sweep.print_help(), 2)[1])

    p = kinds.add_parser(
        "stability-map", help="the shape stability map (flatbody stability-map), the grid split into chunks"
    )
    add_body_arguments(p)
    add_map_arguments(p, grid_range=validation.SWEEP_GRID_RANGE, grid_name="grid")
    p.add_argument(
        "--chunk",
        type=int_at_least("chunk", 1, validation.SWEEP_GRID_RANGE[1]),
        default=None,
        metavar="ROWS",
        help="lambda rows per task (default: about 512 grid points per task, at least one row)",
    )
    p.add_argument("--plot", metavar="FILE.png", help="draw the map (PNG)")
    _engine_arguments(p)
    p.set_defaults(handler=_stability_map)

    p = kinds.add_parser(
        "failure-study",
        help="the integrator failure study (flatbody failure-study), one task per study axis and method",
    )
    p.add_argument("--studies", nargs="+", metavar="STUDY", help="gap rho horizon (default all)")
    p.add_argument("--methods", nargs="+", metavar="NAME", help="methods (default: the study's set)")
    p.add_argument("--quick", action="store_true", help="fewer cases per axis")
    p.add_argument(
        "--repeats",
        type=int_at_least("repeats", 1, validation.MAX_REPEATS),
        default=1,
        help="timing repeats (default 1)",
    )
    p.add_argument(
        "--max-run-s",
        type=positive_float("max_run_s", validation.MAX_SECONDS),
        default=None,
        metavar="S",
        help="stop a method's axis once one run takes longer (default 5; 1 with --quick)",
    )
    _engine_arguments(p)
    p.set_defaults(handler=_failure_study)

    p = kinds.add_parser("family", help="families of stationary ellipses for several bodies, parameters and ranges")
    add_body_arguments(p)
    add_box_arguments(p)
    p.add_argument(
        "--bodies",
        nargs="+",
        metavar="BODY",
        help="V1|V2|V3[:NAME=VALUE,...] (unset constants 1) or a scene; default: the body flags",
    )
    p.add_argument(
        "--vary",
        nargs="+",
        default=["s3"],
        metavar="PARAM",
        help="parameters to vary (s3, p_theta or a constant); default s3",
    )
    start, stop = DEFAULT_FAMILY_RANGE
    p.add_argument(
        "--ranges",
        nargs="+",
        type=float_range("--ranges", low=-validation.MOMENTUM_MAX, high=validation.MOMENTUM_MAX),
        default=[DEFAULT_FAMILY_RANGE],
        metavar="LO,HI",
        help=f"parameter ranges (default {start:g},{stop:g})",
    )
    p.add_argument(
        "--seeds",
        type=int_at_least("seeds", *validation.FAMILY_SEEDS_RANGE),
        default=DEFAULT_SEEDS,
        help=f"parameter values at which all solutions are sought (default {DEFAULT_SEEDS})",
    )
    p.add_argument(
        "--step",
        type=positive_float("step", validation.STRETCH_RANGE[1]),
        default=None,
        help="largest continuation step (default range/60)",
    )
    _engine_arguments(p)
    p.set_defaults(handler=_family)

    from agents.config import SB3_ALGOS as ALGOS

    p = kinds.add_parser("seeds", help="train and evaluate one configuration over many seeds (one task per seed)")
    p.add_argument("--algo", required=True, choices=ALGOS, help="algorithm")
    p.add_argument("--seeds", default="0-7", metavar="RANGE", help="seeds, e.g. 0-7 or 0,3,5 (default 0-7)")
    p.add_argument(
        "--n-timesteps",
        type=int_at_least("n_timesteps", 1, validation.MAX_TIMESTEPS),
        default=None,
        metavar="N",
        help="steps per seed (default: the YAML's)",
    )
    p.add_argument(
        "--n-envs",
        type=int_at_least("n_envs", 1, validation.MAX_BATCH),
        default=None,
        metavar="N",
        help="parallel bodies (default: the YAML's)",
    )
    p.add_argument(
        "--hyperparams", nargs="*", metavar="KEY=VALUE", help="override YAML entries (values parsed as YAML)"
    )
    p.add_argument("--hyperparams-file", metavar="FILE", help="YAML file (default: agents/hyperparams/ALGO.yml)")
    p.add_argument(
        "--episodes",
        type=int_at_least("episodes", 1, validation.MAX_EPISODES),
        default=100,
        metavar="N",
        help="evaluation episodes per seed (default 100)",
    )
    p.add_argument(
        "--eval-seed",
        type=int_at_least("eval_seed", 0, validation.MAX_SEED),
        default=EVAL_SEED,
        metavar="S",
        help=f"evaluation episode i is reset with seed S + i (default {EVAL_SEED}, held apart from training)",
    )
    _engine_arguments(p)
    p.set_defaults(handler=_seeds)

    p = sub.add_parser(
        "benchmark",
        help="train algorithms from scratch on the v1 suite over seeds, learning curves and normalised scores (Dask, resumable)",
    )
    p.add_argument(
        "--algos", default="ppo,sac,td3,rsl-ppo", metavar="A,B", help="algorithms (default ppo,sac,td3,rsl-ppo)"
    )
    p.add_argument("--envs", default="all", metavar="ID,ID", help="v1 ids, or all (default)")
    p.add_argument(
        "--hyperparams",
        nargs="*",
        metavar="KEY=VALUE",
        help="fixed overrides of every algorithm's YAML entries (e.g. n_envs=65536 on a GPU), named in the rows",
    )
    p.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        default="cpu",
        help="torch device of rsl-ppo's env and policy (cuda: the whole env step and PPO on the GPU; default cpu)",
    )
    p.add_argument(
        "--retrain",
        metavar="A,B",
        help="with --resume: train these algorithms' stored runs again (after their hyperparameters changed)",
    )
    p.add_argument(
        "--with",
        dest="with_table",
        action="append",
        metavar="TABLE.json",
        help="a saved benchmark table (an earlier benchmark's or another machine's benchmark.json) whose cases join "
        "this run's in the report; this run's replace those of the same algorithm, task and seed; repeatable, a "
        "table named earlier replacing the cases of one named later",
    )
    p.add_argument(
        "--hyperparam-grid",
        metavar="KEY=V1,V2",
        help="train each algorithm once per value of one hyperparameter (e.g. learning_rate=1e-4,3e-4,1e-3): a "
        "sensitivity study, charted as benchmark_sensitivity.png",
    )
    p.add_argument("--seeds", default="0-4", metavar="RANGE", help="training seeds, e.g. 0-4 (default; at least 2)")
    p.add_argument(
        "--budget",
        action="append",
        metavar="ALGO=STEPS",
        help="env steps of ALGO's runs (default: agents.benchmark.BUDGETS)",
    )
    p.add_argument(
        "--eval-seed",
        type=int_at_least("eval_seed", 0, validation.MAX_SEED),
        default=EVAL_SEED,
        metavar="S",
        help=f"held-out evaluation episode i is reset with seed S + i (default {EVAL_SEED})",
    )
    p.add_argument(
        "--docs", metavar="FILE.md", help="regenerate the table between <!-- bench:benchmark --> markers in FILE.md"
    )
    _engine_arguments(p)
    p.set_defaults(handler=_benchmark)

    for name in ("work-precision", "chart"):
        p = kinds.add_parser(name, help="timing study: stays serial (run 'flatbody chart')")
        # whatever flags follow (--workers N, the chart's own), the answer is the one line of _serial_only
        kinds._name_parser_map[name] = _SerialOnly(prog=p.prog)

    p = sub.add_parser(
        "tune", help="Optuna hyperparameter search (TPE sampler, median pruner) over the YAML hyperparameters"
    )
    p.add_argument("--algo", required=True, choices=ALGOS, help="algorithm")
    p.add_argument(
        "--trials",
        type=int_at_least("trials", 1, validation.MAX_REPEATS),
        default=20,
        metavar="N",
        help="trials in the study, over all workers (default 20)",
    )
    p.add_argument(
        "--n-timesteps",
        type=int_at_least("n_timesteps", 1, validation.MAX_TIMESTEPS),
        default=20_000,
        metavar="N",
        help="training steps per trial (default 20000)",
    )
    p.add_argument(
        "--evaluations",
        type=int_at_least("evaluations", 1, validation.MAX_REPEATS),
        default=4,
        metavar="N",
        help="intermediate evaluations per trial (pruning points; default 4)",
    )
    p.add_argument(
        "--eval-episodes",
        type=int_at_least("eval_episodes", 1, validation.MAX_EPISODES),
        default=20,
        metavar="N",
        help="episodes per evaluation (default 20)",
    )
    p.add_argument(
        "--n-envs",
        type=int_at_least("n_envs", 1, validation.MAX_BATCH),
        default=None,
        metavar="N",
        help="parallel bodies while training (default: the YAML's)",
    )
    p.add_argument(
        "--seed",
        type=int_at_least("seed", 0, validation.MAX_SEED),
        default=0,
        help="training seed of every trial (default 0)",
    )
    p.add_argument("--hyperparams", nargs="*", metavar="KEY=VALUE", help="fixed overrides of YAML entries")
    p.add_argument("--hyperparams-file", metavar="FILE", help="YAML file (default: agents/hyperparams/ALGO.yml)")
    p.add_argument("--search-file", metavar="FILE", help="search space (default: agents/hyperparams/ALGO_search.yml)")
    p.add_argument(
        "--storage",
        metavar="URL",
        help="journal file or database URL, e.g. postgresql://USER@HOST/DB (default sqlite:///runs/tune/optuna.sqlite3, with a heartbeat)",
    )
    p.add_argument(
        "--study", metavar="NAME", help="study name (default ALGO-FlatBody-v0); workers of one study share it"
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--workers",
        type=int_at_least("workers", 1, validation.MAX_WORKERS),
        default=1,
        metavar="N",
        help="local worker processes sharing the study (default 1)",
    )
    g.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="one search worker per worker of a running Dask scheduler (the storage: a database URL, or a journal file all of them see)",
    )
    p.add_argument("--out", default="runs/tune", metavar="DIR", help="folder of the trials' runs (default runs/tune)")
    p.add_argument("--json", action="store_true", help="print the study's trials as JSON")
    p.set_defaults(handler=_tune)
