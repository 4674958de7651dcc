"""``flatbody bench env``: the environment's step rates (the measurement lives in :mod:`flatbody_env.bench.env`);
``flatbody targets-table``: regenerate the task's settling-rate table (:mod:`flatbody_env.env.targets`)."""

from __future__ import annotations

from pathlib import Path

from flatbody_env.cli.args import int_at_least, output_dir
from flatbody_env.physics import validation


def _cmd(args) -> int:
    from flatbody_env.bench.env import report, run
    from flatbody_env.bench.harness import write_report

    bench = run(
        steps=args.steps,
        batch=args.batch,
        batch_steps=args.batch_steps,
        repeats=args.repeats,
        episode_steps=args.episode_steps,
    )
    print(f"integrator: {bench.integrator}")
    for r in bench.single:
        print(
            f"{r.name:<28} {r.us_per_env_step:10.2f} µs/step  {r.env_steps_per_s:14,.0f} steps/s  (reset {r.ms_per_reset:.3f} ms)"
        )
    for r in bench.batched:
        print(f"{r.name:<38} {r.us_per_env_step:10.4f} µs/env-step {r.env_steps_per_s:14,.0f} env-steps/s")
    print(f"ratio FlatBody-v1 vs Pendulum-v1 step rate: {bench.ratio_vs_pendulum:.2f} (target >= 1.0)")
    print(f"ratio FlatBody-v1 vs Acrobot-v1 step rate:  {bench.ratio_vs_acrobot:.2f}")
    print(f"ratio FlatBody-v1 vs Pendulum-v1 reset time: {bench.reset_ratio_vs_pendulum:.2f} (target <= 5)")
    print(
        f"ratio batched FlatBody vs CartPoleVectorEnv: {bench.ratio_batched_vs_cartpole:.2f} (target >= 0.5; resets included; "
        f"with num_threads=None, {bench.threads} thread{'s' if bench.threads > 1 else ''}: {bench.ratio_batched_threads_vs_cartpole:.2f})"
    )
    print(f"batched episode error vs tight reference:   {bench.episode_error:.2e} (target <= 1e-8)")
    write_report(report(bench), args.out_dir, docs=args.docs or None)
    print(f"wrote {Path(args.out_dir) / 'env_benchmark.json'}, .csv, .png")
    if args.docs:
        print(f"updated the tables in {args.docs}")
    return 0


def register_bench(bench_sub) -> None:
    p = bench_sub.add_parser("env", help="FlatBody-v1 step rates vs Pendulum/Acrobot; batched vs CartPoleVectorEnv")
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
    p.add_argument(
        "--docs",
        default="",
        metavar="FILE.md",
        help="also regenerate the tables between <!-- bench:env --> markers in FILE.md",
    )
    p.set_defaults(handler=_cmd)


def _targets_table(args) -> int:
    import numpy as np

    from flatbody_env.env.targets import TABLE_PATH, build_table

    from flatbody_env.env.targets import GRID_ASPECT, GRID_LAMBDA

    table = build_table(
        grid_lambda=(*GRID_LAMBDA[:2], args.n_lambda),
        grid_aspect=(*GRID_ASPECT[:2], args.n_aspect),
        workers=args.workers,
        progress=not args.no_progress,
    )
    out = Path(args.out) if args.out else TABLE_PATH
    table.save(out)
    edge = int(np.isfinite(table.edge_lo).sum())
    print(
        f"wrote {out}: {table.rate.shape[1]} x {table.rate.shape[0]} shapes (lambda x aspect), {edge} edge cells, "
        f"largest interpolation margin {float(np.max(table.margin[np.isfinite(table.margin)])):.2e} 1/s"
    )
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "targets-table", help="regenerate the task's settling-rate table (default body, limits and controls)"
    )
    p.add_argument("--out", default="", help="where to write it (default: the package's own table file)")
    p.add_argument(
        "--n-lambda", type=int_at_least("n_lambda", 2, 2001), default=71, help="grid nodes in lambda* (shipped: 71)"
    )
    p.add_argument(
        "--n-aspect", type=int_at_least("n_aspect", 2, 2001), default=81, help="grid nodes in lambda*/mu* (shipped: 81)"
    )
    p.add_argument("--workers", type=int_at_least("workers", 1, validation.MAX_WORKERS), default=2, help="processes")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(handler=_targets_table)
