"""``flatbody bench env``: the environment's step rates (the measurement lives in :mod:`flatbody_env.env.benchmark`)."""

from __future__ import annotations

from pathlib import Path

from flatbody_env.cli.args import int_at_least


def _cmd(args) -> int:
    from flatbody_env.env.benchmark import run

    bench = run(steps=args.steps, batch=args.batch, batch_steps=args.batch_steps, repeats=args.repeats, out_dir=args.out_dir)
    print(f"integrator: {bench.integrator}")
    for r in bench.single:
        print(f"{r.name:<28} {r.us_per_env_step:10.2f} µs/step  {r.env_steps_per_s:14,.0f} steps/s  (reset {r.ms_per_reset:.3f} ms)")
    for r in bench.batched:
        print(f"{r.name:<28} {r.us_per_env_step:10.4f} µs/env-step {r.env_steps_per_s:14,.0f} env-steps/s")
    print(f"ratio FlatBody-v0 vs Pendulum-v1 step rate: {bench.ratio_vs_pendulum:.2f} (target >= 1.0)")
    print(f"ratio FlatBody-v0 vs Acrobot-v1 step rate:  {bench.ratio_vs_acrobot:.2f}")
    print(f"ratio batched FlatBody vs CartPoleVectorEnv: {bench.ratio_batched_vs_cartpole:.2f} (target >= 0.5)")
    print(f"batched episode error vs tight reference:   {bench.episode_error:.2e} (target <= 1e-6)")
    print(f"wrote {Path(args.out_dir) / 'env_benchmark.json'}, .csv, .png")
    return 0


def register_bench(bench_sub) -> None:
    p = bench_sub.add_parser("env", help="FlatBody-v0 step rates vs Pendulum/Acrobot; batched vs CartPoleVectorEnv")
    p.add_argument("--steps", type=int_at_least("steps", 1), default=2000, help="steps per timed block (single envs)")
    p.add_argument("--batch", type=int_at_least("batch", 1), default=1024, help="N for the batched comparison")
    p.add_argument("--batch-steps", type=int_at_least("batch_steps", 1), default=50, help="steps per timed block (batched)")
    p.add_argument("--repeats", type=int_at_least("repeats", 1), default=5, help="timed blocks; the best is kept")
    p.add_argument("--out-dir", default="bench", help="where to write env_benchmark.json/.csv/.png")
    p.set_defaults(handler=_cmd)
