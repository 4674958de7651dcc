"""``flatbody bench TARGET``: every benchmark's parser and handler, in one place.

Each target's measurement lives in its module of :mod:`flatbody_env.bench` (``env``, ``gpu``, ``integrators``,
``recording``, ``service``, ``sweep``, ``train`` and ``train --to-goal``, ``compare``); a handler here runs it,
prints its :class:`~flatbody_env.bench.harness.Report`'s tables (the same tables ``--docs`` writes into a page) and
writes its files (:func:`~flatbody_env.bench.harness.write_report`). ``--plot-only`` redraws a chart (and, with
``--docs``, the page's tables) from the saved JSON. Heavy imports happen in the handlers.
"""

from __future__ import annotations

import sys
from pathlib import Path

from flatbody_env.cli.args import int_at_least, int_list, name_list, output_dir, output_file, positive_float
from flatbody_env.physics import validation

INTEGRATORS_OUT = "runs/integrators"
"""``bench integrators``' default folder (the integrator studies' own)."""


def _wrote(paths, docs=None) -> None:
    print("wrote " + ", ".join(str(p) for p in paths if docs is None or Path(p) != Path(docs)))
    if docs:
        print(f"regenerated the tables in {docs}")


def _show(report) -> None:
    text = report.text()
    if text:
        print(text)


# --------------------------------------------------------------------------------------------- handlers
def _env(args) -> int:
    from flatbody_env.bench.env import report, run
    from flatbody_env.bench.harness import write_report

    bench = run(
        steps=args.steps,
        batch=args.batch,
        batch_steps=args.batch_steps,
        repeats=args.repeats,
        episode_steps=args.episode_steps,
    )
    rep = report(bench)
    _show(rep)
    _wrote(write_report(rep, args.out_dir, docs=args.docs or None), args.docs or None)
    return 0


def _gpu(args) -> int:
    from flatbody_env.bench.gpu import report, run
    from flatbody_env.bench.harness import write_report
    from flatbody_env.progress import progress_bar

    import json

    from flatbody_env.output import atomic_write

    out = Path(args.out)
    bar = progress_bar(desc="bench gpu", unit="row")
    rows: list[dict] = []

    def progress(row: dict) -> None:
        """Each row as it is measured: a line on stderr, and ``--out`` rewritten with the rows so far (marked partial),
        so that a run stopped early (by a time limit, say) keeps what it measured."""
        rows.append(row)
        atomic_write(out, json.dumps({"partial": True, "rows": rows}, indent=1) + "\n")
        bar.update(1)
        bar.set_postfix_str(f"{row['backend']} {row['method']} N={row['n']}")
        sys.stderr.write(
            f"bench gpu: {row['what'].split(' (')[0]} {row['env'] or '-'} {row['backend']} {row['method']} N={row['n']}: "
            f"{row['steps_per_s']:.3g} body-steps/s\n"
        )

    try:
        result = run(
            sizes=args.sizes,
            methods=[] if args.no_dynamics else args.methods,
            steps=args.steps,
            repeats=args.repeats,
            only=args.backends,
            progress=progress,
            envs=args.envs,
        )
    finally:
        bar.close()
    rep = report(result, out.stem)
    _show(rep)
    _wrote(write_report(rep, out.parent))
    return 0


def _integrators(args) -> int:
    from flatbody_env.bench.harness import redraw, write_docs, write_report
    from flatbody_env.bench.integrators import NAME, load, measure, report

    out = Path(args.out)
    if args.plot_only:
        from analysis.integrator_plots import plot_bench

        print(f"wrote {redraw(out, NAME, plot_bench, where='out')}")
        if args.docs:
            write_docs(report(load(out / f"{NAME}.json")), args.docs)
            print(f"regenerated the tables in {args.docs}")
        return 0
    rep = report(
        measure(quick=args.quick, repeats=args.repeats, max_run_s=args.max_run_s, with_compile=not args.no_compile)
    )
    _show(rep)
    _wrote(write_report(rep, out, docs=args.docs or None), args.docs or None)
    return 0


def _recording(args) -> int:
    from flatbody_env.bench.harness import write_report
    from flatbody_env.bench.recording import measure, report

    result = measure(
        scene=args.scene,
        steps=args.steps,
        sizes=args.sizes,
        repeats=args.repeats,
        block=args.block,
        frames=args.frames,
        episode_repeats=args.episode_repeats,
    )
    rep = report(result)
    _show(rep)
    _wrote(write_report(rep, args.out_dir, docs=args.docs), args.docs)
    return 0


def _service(args) -> int:
    from flatbody_env.bench.harness import redraw, write_report
    from flatbody_env.bench.service import NAME, measure, plot, report

    out = Path(args.out_dir)
    if args.plot_only:
        print(f"wrote {redraw(out, NAME, plot)}")
        return 0
    result = measure(clients=tuple(args.clients), requests=args.requests, seconds=args.seconds, workers=args.workers)
    rep = report(result)
    _show(rep)
    _wrote(write_report(rep, out))
    return 0 if result.errors == 0 else 1


def _sweep(args) -> int:
    from flatbody_env.bench.harness import redraw, write_report
    from flatbody_env.bench.sweep import NAME, measure, plot, report

    out = Path(args.out)
    if args.plot_only:
        print(f"wrote {redraw(out, NAME, plot, where='out')}")
        return 0
    rep = report(
        measure(
            grid=args.grid,
            workers=tuple(args.workers),
            sim_workers=args.sim_workers,
            chunk=args.chunk,
            noop_tasks=args.noop_tasks,
            extrapolate=(8, 32, 128),
        )
    )
    _show(rep)
    _wrote(write_report(rep, out))
    return 0


def _train(args) -> int:
    if args.to_goal:
        from flatbody_env.bench.time_to_goal import report, run

        bench = run(
            seed=args.seed,
            max_timesteps=args.max_timesteps,
            eval_every=args.eval_every,
            episodes=args.episodes,
            out_dir=args.out_dir,
            docs=args.docs or None,
        )
        name = "time_to_goal"
    else:
        from flatbody_env.bench.train import report, run

        bench = run(
            timesteps=args.timesteps,
            repeats=args.repeats,
            seed=args.seed,
            out_dir=args.out_dir,
            overrides=args.hyperparams or [],
            docs=args.docs or None,
        )
        name = "train_benchmark"
    _show(report(bench))
    _wrote([Path(args.out_dir) / f"{name}.{ext}" for ext in ("json", "csv", "png")], args.docs or None)
    return 0


def _compare(args) -> int:
    from flatbody_env.bench.compare import report, run
    from flatbody_env.bench.harness import write_report

    result = run(args.rev, figures=args.figures, rounds=args.rounds, progress=True, env_id=args.env)
    rep = report(result)
    _show(rep)
    _wrote(write_report(rep, args.out_dir))
    return 0


# --------------------------------------------------------------------------------------------- parsers
def _gpu_methods():
    from flatbody_env.integrators.specs import GPU_METHODS

    return GPU_METHODS


def _v1_ids():
    from flatbody_env.env.registration import V1_IDS

    return V1_IDS


def _gpu_backends():
    from flatbody_env.bench.gpu import BACKENDS

    return BACKENDS


def _compare_figures():
    from flatbody_env.bench.compare import FIGURES

    return tuple(FIGURES)


def _docs(p, block: str) -> None:
    p.add_argument(
        "--docs",
        default="",
        metavar="FILE.md",
        help=f"also regenerate the tables between <!-- bench:{block} --> markers in FILE.md",
    )


def register(sub) -> None:
    bench = sub.add_parser("bench", help="benchmarks: print figures and write JSON/CSV and PNG (not timed tests)")
    bsub = bench.add_subparsers(dest="target", metavar="TARGET", parser_class=type(bench))
    bench.set_defaults(handler=lambda args: (bench.print_help(), 2)[1])

    p = bsub.add_parser("env", help="FlatBody-v1 step rates vs Pendulum/Acrobot; batched vs CartPoleVectorEnv")
    p.add_argument(
        "--steps",
        type=int_at_least("steps", 1, validation.MAX_EPISODE_STEPS),
        default=2000,
        help="steps per timed block (single envs)",
    )
    p.add_argument(
        "--batch",
        type=int_at_least("batch", 1, validation.MAX_BATCH),
        default=1024,
        help="N for the batched comparison",
    )
    p.add_argument(
        "--batch-steps",
        type=int_at_least("batch_steps", 1, 10_000),
        default=50,
        help="steps per timed block (batched CartPole: x10)",
    )
    p.add_argument(
        "--episode-steps",
        type=int_at_least("episode_steps", 1, validation.MAX_EPISODE_STEPS),
        default=None,
        help="episode length of the batched FlatBody timing (default: the registered 400)",
    )
    p.add_argument(
        "--repeats",
        type=int_at_least("repeats", 1, validation.MAX_REPEATS),
        default=5,
        help="timed blocks; the best is kept",
    )
    p.add_argument(
        "--out-dir", type=output_dir("out_dir"), default="bench", help="where to write env_benchmark.json/.csv/.png"
    )
    _docs(p, "env")
    p.set_defaults(handler=_env)

    p = bsub.add_parser(
        "gpu",
        help="batched dynamics and the whole env step: body-steps/s against N on the CPU (serial, parallel) "
        "and a CUDA GPU when present",
    )
    p.add_argument(
        "--out",
        required=True,
        type=output_file("out", (".json",)),
        metavar="FILE.json",
        help="JSON of the rows; the table (FILE.csv) and the chart (FILE.png) go beside it",
    )
    p.add_argument(
        "--sizes",
        type=int_list("sizes", 1, 1 << 24),
        default=[256, 1024, 4096, 16384, 65536],
        metavar="N,N,...",
        help="numbers of bodies",
    )
    p.add_argument(
        "--methods",
        type=name_list("methods", _gpu_methods),
        default=["RK4", "DOP853-numba"],
        metavar="NAME,...",
        help="batch methods to time",
    )
    p.add_argument(
        "--backends",
        type=name_list("backends", _gpu_backends),
        default=None,
        metavar="NAME,...",
        help="time only these (cpu-serial, cpu-parallel, cuda; default: every one here), e.g. cuda alone at large N",
    )
    p.add_argument(
        "--envs",
        type=name_list("envs", _v1_ids),
        default=None,
        metavar="ID,...",
        help="the v1 ids of the whole-env-step rows (default: every one on cuda, FlatBody-v1 on the CPU)",
    )
    p.add_argument("--no-dynamics", action="store_true", help="the whole-env-step rows only (no dynamics-only rows)")
    p.add_argument("--steps", type=int_at_least("steps", 1, 100000), default=10, help="env steps per timed block")
    p.add_argument("--repeats", type=int_at_least("repeats", 1, 100), default=3, help="timed blocks; the best is kept")
    p.set_defaults(handler=_gpu)

    p = bsub.add_parser(
        "integrators", help="same-run ratios vs scipy DOP853, close approach, long horizon, per-step cost, compile time"
    )
    p.add_argument("--quick", action="store_true", help="shorter horizons, one close-approach case, 1 repeat")
    p.add_argument(
        "--repeats",
        type=int_at_least("repeats", 1, validation.MAX_REPEATS),
        default=3,
        help="timing repeats (minimum taken; default 3)",
    )
    p.add_argument(
        "--max-run-s",
        type=positive_float("max_run_s", validation.MAX_SECONDS),
        default=5.0,
        metavar="S",
        help="stop a sweep once one run takes longer",
    )
    p.add_argument("--no-compile", action="store_true", help="skip the compile-time measurement (two fresh processes)")
    p.add_argument(
        "--out",
        type=output_dir("out"),
        default=INTEGRATORS_OUT,
        metavar="DIR",
        help=f"output folder (default {INTEGRATORS_OUT})",
    )
    p.add_argument(
        "--plot-only", action="store_true", help="redraw the PNG (and with --docs the tables) from the saved JSON"
    )
    p.add_argument(
        "--docs",
        metavar="FILE.md",
        help="also regenerate the tables between <!-- bench:integrators-* --> markers in FILE.md",
    )
    p.set_defaults(handler=_integrators)

    p = bsub.add_parser(
        "recording",
        help="time to log an N-step trajectory to a finished .rrd (budget 1 s for 10 000) and to draw an rgb_array "
        "frame (budget 1 ms)",
    )
    p.add_argument(
        "--steps",
        type=int_at_least("steps", 2, validation.MAX_EPISODE_STEPS),
        default=10000,
        help="the size judged against the 1 s budget (default 10000)",
    )
    p.add_argument(
        "--sizes",
        type=int_list("sizes", 2, validation.MAX_EPISODE_STEPS),
        default=[1000, 3000, 30000],
        metavar="N1,N2,...",
        help="further sizes for the scaling chart",
    )
    p.add_argument(
        "--repeats",
        type=int_at_least("repeats", 1, validation.MAX_REPEATS),
        default=5,
        help="runs per size (median reported; default 5)",
    )
    p.add_argument(
        "--block",
        type=int_at_least("block", 1, validation.MAX_SAMPLES),
        default=256,
        help="block size of the live-recorder measurement",
    )
    p.add_argument(
        "--frames",
        type=int_at_least("frames", 2, validation.MAX_SAMPLES),
        default=2000,
        help="rgb_array frames timed (budget 1 ms each; default 2000)",
    )
    p.add_argument("--scene", default="default", help="built-in scene that supplies the trajectory")
    p.add_argument(
        "--out-dir",
        type=output_dir("out_dir"),
        default="bench",
        metavar="DIR",
        help="where recording.json, .csv and .png go (default bench)",
    )
    p.add_argument(
        "--episode-repeats",
        type=int_at_least("episode_repeats", 1, validation.MAX_REPEATS),
        default=3,
        help="recorded env episodes per path (compiled vs the former scipy path; median; default 3)",
    )
    p.add_argument(
        "--docs",
        metavar="FILE.md",
        help="also regenerate the table between <!-- bench:recording --> markers in FILE.md",
    )
    p.set_defaults(handler=_recording)

    from flatbody_env.cli.serve import default_workers

    p = bsub.add_parser(
        "service", help="latency and requests/s of the HTTP service at 1, 8, 32 clients while a long job runs"
    )
    p.add_argument(
        "--clients",
        type=int_list("clients", 1, 256),
        default=[1, 8, 32],
        metavar="N,N,...",
        help="concurrent clients (default 1,8,32)",
    )
    p.add_argument(
        "--requests",
        type=int_at_least("requests", 1, 1_000_000),
        default=200,
        help="requests per endpoint and client count, at most (default 200)",
    )
    p.add_argument(
        "--seconds",
        type=positive_float("seconds", validation.MAX_SECONDS),
        default=20.0,
        help="time per endpoint and client count, at most (default 20)",
    )
    p.add_argument(
        "--workers",
        type=int_at_least("workers", 1, validation.MAX_WORKERS),
        default=default_workers(),
        help="the service's worker processes",
    )
    p.add_argument(
        "--out-dir", type=output_dir("out_dir"), default="bench", help="where to write service_benchmark.json/.csv/.png"
    )
    p.add_argument(
        "--plot-only",
        action="store_true",
        help="redraw service_benchmark.png from the saved service_benchmark.json in --out-dir",
    )
    p.set_defaults(handler=_service)

    p = bsub.add_parser(
        "sweep",
        help="sweep scaling: speed-up over workers, scheduler overhead per task, extrapolation to 8/32/128 workers",
    )
    p.add_argument(
        "--grid",
        type=int_at_least("grid", 4, validation.SWEEP_GRID_RANGE[1]),
        default=48,
        metavar="N",
        help="stability-map grid per axis (default 48)",
    )
    p.add_argument(
        "--chunk",
        type=int_at_least("chunk", 1, validation.SWEEP_GRID_RANGE[1]),
        default=2,
        metavar="ROWS",
        help="lambda rows per task (default 2)",
    )
    p.add_argument(
        "--workers",
        type=int_at_least("workers", 1, validation.MAX_WORKERS),
        nargs="+",
        default=[1, 2],
        metavar="N",
        help="local worker counts (default 1 2)",
    )
    p.add_argument(
        "--sim-workers",
        type=int_at_least("sim_workers", 1, validation.MAX_WORKERS),
        default=4,
        metavar="N",
        help="worker processes of the simulated multi-node run (tasks sleep for the measured cost; default 4)",
    )
    p.add_argument(
        "--noop-tasks",
        type=int_at_least("noop_tasks", 10, 1_000_000),
        default=400,
        metavar="N",
        help="empty tasks timing the scheduler overhead (default 400)",
    )
    p.add_argument(
        "--out",
        type=output_dir("out"),
        default="runs/sweep-bench",
        metavar="DIR",
        help="output folder (default runs/sweep-bench)",
    )
    p.add_argument("--plot-only", action="store_true", help="redraw the PNG from the saved JSON")
    p.set_defaults(handler=_sweep)

    p = bsub.add_parser(
        "train",
        help="PPO wall time on FlatBody-v0 vs the same PPO on Pendulum-v1, share in env + LQR; "
        "--to-goal: wall time to a good agent, SB3 vs rsl_rl",
    )
    p.add_argument(
        "--timesteps",
        type=int_at_least("timesteps", 1, validation.MAX_TIMESTEPS),
        default=64_000,
        help="environment steps per run",
    )
    p.add_argument(
        "--repeats",
        type=int_at_least("repeats", 1, validation.MAX_REPEATS),
        default=1,
        help="runs per environment; the fastest is kept",
    )
    p.add_argument("--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=0, help="seed of both runs")
    p.add_argument(
        "--hyperparams", nargs="*", metavar="KEY=VALUE", help="overrides of the shipped PPO settings, for both runs"
    )
    p.add_argument(
        "--out-dir", type=output_dir("out_dir"), default="bench", help="where to write train_benchmark.json/.csv/.png"
    )
    _docs(p, "train")
    p.add_argument(
        "--to-goal",
        action="store_true",
        help="instead: wall time to a good residual agent, SB3's PPO vs rsl_rl's PPO (rsl-ppo) in the same "
        "run (time_to_goal.json/.csv/.png; with --docs the <!-- bench:time-to-goal --> table)",
    )
    p.add_argument(
        "--max-timesteps",
        type=int_at_least("max_timesteps", 1, validation.MAX_TIMESTEPS),
        default=3_000_000,
        help="--to-goal: stop a trainer here if it has not reached the goal",
    )
    p.add_argument(
        "--eval-every",
        type=int_at_least("eval_every", 1, validation.MAX_TIMESTEPS),
        default=50_000,
        help="--to-goal: environment steps between evaluations (rounded up to whole rollouts)",
    )
    p.add_argument(
        "--episodes",
        type=int_at_least("episodes", 1, 10_000),
        default=20,
        help="--to-goal: held-out episodes per evaluation (seeds 50000...)",
    )
    p.set_defaults(handler=_train)

    p = bsub.add_parser(
        "compare",
        help="the core figures (env step, vector step, compiled simulate, recording, PPO iteration) of this tree "
        "against a git revision checked out beside it, timed in alternation",
    )
    p.add_argument("rev", metavar="REV", help="a git revision of this checkout (a commit, branch or tag), e.g. main")
    p.add_argument(
        "--rounds",
        type=int_at_least("rounds", 1, 100),
        default=5,
        help="timed rounds; each figure is the best of them (default 5)",
    )
    p.add_argument(
        "--figures",
        type=name_list("figures", _compare_figures),
        default=None,
        metavar="NAME,...",
        help="only these figures (env-step, vector-step, simulate, recording, ppo, planner; default all)",
    )
    p.add_argument(
        "--env",
        metavar="ID",
        default=None,
        help="the task of the env figures (default: the newest FlatBody id both trees register, FlatBody-v1)",
    )
    p.add_argument(
        "--out-dir", type=output_dir("out_dir"), default="bench", help="where to write compare.json/.csv/.png"
    )
    p.set_defaults(handler=_compare)


__all__ = ["INTEGRATORS_OUT", "register"]
