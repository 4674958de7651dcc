"""Sub-commands of the integrator studies: ``chart``, ``failure-study`` (``bench integrators``: :mod:`flatbody_env.cli.bench`).

* ``flatbody chart [--quick] [--scenes ...] [--methods ...] [--out DIR]`` — the work-precision
  study (:mod:`analysis.work_precision`) → ``DIR/work_precision.csv``, ``references.json``,
  ``work_precision.png``.
* ``flatbody chart --ladder [--quick] [--scenes ...] [--out DIR]`` — the model ladder
  (:mod:`analysis.ladder`): every built-in scene's rung and error against cost per rung →
  ``DIR/ladder.csv``, ``ladder_scenes.csv``, ``ladder.png``.
* ``flatbody chart --tasks [--from DIR] [--out DIR]`` — the tasks' reference chart
  (:mod:`agents.reference_chart`): success against the target's settling rate and growth rate, drawn
  from the saved task reports (``flatbody evaluate --env all --out-dir DIR``) → ``DIR/tasks_ladder.png`` (the v1
  suite's ladder; left out, with a line saying so, when the folder holds no v1 report) and ``DIR/tasks_success.png``.
* ``flatbody chart --longer-budgets [--out DIR]`` — rsl-ppo past the benchmark's budget
  (:func:`agents.benchmark.plot_longer_budgets`): each training run's held-out success along its budget, drawn from
  ``agents/data/benchmark/rsl-ppo-longer-budgets.json`` → ``DIR/rsl_ppo_longer_budgets.png``.
* ``flatbody failure-study [--quick] [--studies gap rho horizon] [--out DIR]`` —
  :mod:`analysis.failure_study` → ``DIR/failure_study.csv``, ``failure_study.png``.

Every command can redraw its PNG from the saved tables with ``--plot-only``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from flatbody_env.answers import failure_rows
from flatbody_env.cli.args import int_at_least, positive_float, output_dir
from flatbody_env.physics import validation

DEFAULT_OUT = "runs/integrators"


def _methods(text_list):
    from flatbody_env.integrators import get_method

    for m in text_list:
        get_method(m)  # ValueError naming the allowed methods
    return tuple(text_list)


def _budget(args) -> float:
    if args.max_run_s is not None:
        return args.max_run_s
    return 1.0 if args.quick else 5.0


def _ratio(value: float, against: str, why: str) -> str:
    """``x12.3 vs AGAINST``, or ``vs AGAINST n/a (WHY)`` when the ratio was not measured."""
    return f"x{value:.3g} vs {against}" if math.isfinite(value) else f"vs {against} n/a ({why or 'not measured'})"


def _ladder(args) -> int:
    from analysis.ladder import ladder_study, speedups, write_csv, write_scenes
    from analysis.ladder_plots import plot_ladder

    out = Path(args.out)
    csv_path, scenes_path, png_path = out / "ladder.csv", out / "ladder_scenes.csv", out / "ladder.png"
    if not args.plot_only:
        points, records = ladder_study(
            args.scenes, quick=args.quick, repeats=1 if args.quick else args.repeats, max_run_s=_budget(args)
        )
        write_csv(points, csv_path)
        write_scenes(records, scenes_path)
        for r in records:
            floor = (
                f"floor {r.floor:.1e}" if math.isfinite(r.floor) else f"floor n/a ({r.cross_check or 'no cross-check'})"
            )
            print(f"{r.scene:<20} auto -> {r.chosen:<10} (reference {r.reference}; {floor})")
        for s in speedups(points):
            txt = (
                f"{_ratio(s['speedup_vs_full'], 'the cheapest full model', s['why_no_full'])}, "
                f"{_ratio(s['speedup_vs_default'], 'scipy DOP853', s['why_no_default'])}"
                if s["reached_target"]
                else "error target not reached"
            )
            print(
                f"  {s['scene']:<26} {s['rung']:<10} {s['method']:<17} {s['setting']:<11} error {s['error']:.1e} "
                f"in {s['wall_time'] * 1e3:.3f} ms: {txt}"
            )
    elif not csv_path.exists():
        raise ValueError(f"out: no {csv_path} to plot (run without --plot-only first)")
    plot_ladder(csv_path, scenes_path, png_path)
    print(f"wrote {png_path}" if args.plot_only else f"wrote {csv_path}, {scenes_path}, {png_path}")
    return 0


def _chart(args) -> int:
    if args.longer_budgets:  # rsl-ppo past the table's budget (agents.benchmark), from its saved table
        from agents.benchmark import plot_longer_budgets

        print(f"wrote {plot_longer_budgets(Path(args.out) / 'rsl_ppo_longer_budgets.png')}")
        return 0
    if args.tasks:  # the tasks' reference chart (agents.reference_chart), from the saved reports
        from agents.reference import REFERENCE_DIR
        from agents.reference_chart import plot_ladder, plot_task_success

        folder = args.reports or REFERENCE_DIR
        try:
            print(f"wrote {plot_ladder(Path(args.out) / 'tasks_ladder.png', folder)}")
        except ValueError as exc:
            if "no report of the v1 suite" not in str(exc):
                raise
            print(f"left out tasks_ladder.png: {exc} ('flatbody evaluate --env all' writes them)")
        print(f"wrote {plot_task_success(Path(args.out) / 'tasks_success.png', folder)}")
        return 0
    if args.ladder:
        return _ladder(args)
    from analysis.integrator_plots import plot_work_precision
    from analysis.work_precision import DEFAULT_METHODS, SCENES, work_precision, write_json, write_records

    out = Path(args.out)
    csv_path, ref_path, png_path = out / "work_precision.csv", out / "references.json", out / "work_precision.png"
    if not args.plot_only:
        scenes = tuple(args.scenes) if args.scenes else SCENES
        for s in scenes:
            if s not in SCENES:
                raise ValueError(f"scenes: unknown scene {s!r} (allowed: {', '.join(SCENES)})")
        methods = _methods(args.methods) if args.methods else DEFAULT_METHODS
        repeats = 1 if args.quick else args.repeats
        points, refs = work_precision(scenes, methods, quick=args.quick, repeats=repeats, max_run_s=_budget(args))
        write_records(points, csv_path)
        write_json(refs, ref_path)
        for r in refs:
            print(
                f"reference {r.scene} (t = {r.t_end:g}): {r.method} {r.setting}; cross-check {r.cross_method} "
                f"{r.cross_setting}: agreement floor {r.agreement:.2e}"
            )
    elif not csv_path.exists():
        raise ValueError(f"out: no {csv_path} to plot (run without --plot-only first)")
    plot_work_precision(csv_path, png_path, ref_path)
    print(f"wrote {png_path}" if args.plot_only else f"wrote {csv_path}, {ref_path}, {png_path}")
    return 0


def _failure(args) -> int:
    from analysis.failure_study import DEFAULT_METHODS, STUDIES, failure_study, planned_runs
    from analysis.integrator_plots import plot_failure_study
    from analysis.work_precision import write_records

    out = Path(args.out)
    csv_path, png_path = out / "failure_study.csv", out / "failure_study.png"
    if not args.plot_only:
        studies = tuple(args.studies) if args.studies else STUDIES
        for s in studies:
            if s not in STUDIES:
                raise ValueError(f"studies: unknown study {s!r} (allowed: {', '.join(STUDIES)})")
        methods = _methods(args.methods) if args.methods else DEFAULT_METHODS
        points = failure_study(
            studies, methods, quick=args.quick, repeats=args.repeats, max_run_s=_budget(args), progress=not args.json
        )
        write_records(points, csv_path)
        if args.json:
            order = {(s, m): (i, j) for i, s in enumerate(studies) for j, m in enumerate(methods)}
            print(json.dumps({"rows": failure_rows(sorted(points, key=lambda p: order[p.study, p.method]))}))
            plot_failure_study(csv_path, png_path)
            return 0
        fails = [p for p in points if p.status != "ok"]
        planned = planned_runs(studies, methods, quick=args.quick)
        skipped = (
            f" ({planned - len(points)} skipped: over the {_budget(args):g} s budget per run, --max-run-s)"
            if planned > len(points)
            else ""
        )
        print(f"{len(points)} of {planned} runs{skipped}, {len(fails)} detected failures:")
        seen = set()
        for p in fails:
            key = (p.study, p.method)
            if key in seen:
                continue
            seen.add(key)
            print(
                f"  {p.study:<8} {p.method:<20} first fails at {p.parameter_name} = {p.parameter:g} "
                f"({p.measured_name} = {p.measured:.3g}): {p.status}"
            )
    elif not csv_path.exists():
        raise ValueError(f"out: no {csv_path} to plot (run without --plot-only first)")
    plot_failure_study(csv_path, png_path)
    print(f"wrote {png_path}" if args.plot_only else f"wrote {csv_path}, {png_path}")
    return 0


def _common(p, what):
    p.add_argument("--quick", action="store_true", help=f"a short {what} (shorter horizons, fewer settings, 1 repeat)")
    p.add_argument(
        "--methods", nargs="+", metavar="NAME", help="methods (see 'flatbody methods'); default: a representative set"
    )
    p.add_argument(
        "--repeats",
        type=int_at_least("repeats", 1, validation.MAX_REPEATS),
        default=3,
        help="timing repeats (minimum taken; default 3)",
    )
    p.add_argument(
        "--max-run-s",
        type=positive_float("max_run_s", validation.MAX_SECONDS),
        default=None,
        metavar="S",
        help="stop a method's sweep once one run takes (or is predicted to take) longer (default 5; 1 with --quick)",
    )
    p.add_argument(
        "--out",
        type=output_dir("out"),
        default=DEFAULT_OUT,
        metavar="DIR",
        help=f"output folder, made if missing (default {DEFAULT_OUT})",
    )
    p.add_argument("--plot-only", action="store_true", help="redraw the PNG from the saved table")


def register(sub) -> None:
    p = sub.add_parser("chart", help="work-precision diagram of the integrators (CSV + PNG)")
    _common(p, "chart")
    p.add_argument(
        "--scenes",
        nargs="+",
        metavar="SCENE",
        help="regular close-approach small-rho-bounce long-horizon (default all; "
        "with --ladder: any built-in scene, default all)",
    )
    p.add_argument(
        "--ladder",
        action="store_true",
        help="the model ladder: each scene's rung, error vs cost per rung (ladder.csv, ladder.png)",
    )
    p.add_argument(
        "--tasks",
        action="store_true",
        help="the tasks' reference chart: success against the target's settling rate and growth rate (tasks_success.png), "
        "drawn from the saved task reports",
    )
    p.add_argument(
        "--longer-budgets",
        action="store_true",
        help="rsl-ppo past the benchmark's budget: held-out success along each training run "
        "(rsl_ppo_longer_budgets.png), drawn from agents/data/benchmark/rsl-ppo-longer-budgets.json",
    )
    p.add_argument(
        "--from",
        dest="reports",
        default="",
        metavar="DIR",
        help="with --tasks: the folder of saved task reports (default: the shipped ones, agents/data/reference)",
    )
    p.set_defaults(handler=_chart)

    p = sub.add_parser(
        "failure-study",
        help="where integrators fail: error and cost vs closest approach to lambda = mu, rho_min, horizon",
    )
    _common(p, "study")
    p.add_argument("--studies", nargs="+", metavar="STUDY", help="gap rho horizon (default all)")
    p.add_argument("--json", action="store_true", help="also print the rows as JSON (by study, then method)")
    p.set_defaults(handler=_failure, repeats=1)
