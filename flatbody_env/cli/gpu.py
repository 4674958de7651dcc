"""``flatbody bench gpu``: body-steps/s of the batched dynamics, then of the whole env step, against N on every backend
here (the measurement lives in :mod:`flatbody_env.bench.gpu`)."""

from __future__ import annotations

from pathlib import Path

from flatbody_env.cli.args import int_at_least, output_file

_SIZE = int_at_least("sizes", 1, 1 << 24)


def _sizes(text: str) -> list[int]:
    import argparse

    parts = [p for p in text.split(",") if p.strip()]
    if not 1 <= len(parts) <= 32:
        raise argparse.ArgumentTypeError(f"sizes: expected 1 to 32 comma-separated integers, got {text[:60]!r}")
    return [_SIZE(p.strip()) for p in parts]


def _methods(text: str) -> list[str]:
    import argparse

    from flatbody_env.integrators.specs import GPU_METHODS as allowed

    names = [p.strip() for p in text.split(",") if p.strip()]
    bad = [m for m in names if m not in allowed]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"methods: expected names from {', '.join(allowed)}, got {text[:60]!r}")
    return names


def _backends(text: str) -> list[str]:
    import argparse

    from flatbody_env.bench.gpu import BACKENDS as allowed

    names = [p.strip() for p in text.split(",") if p.strip()]
    if not names or any(n not in allowed for n in names):
        raise argparse.ArgumentTypeError(f"backends: expected names from {', '.join(allowed)}, got {text[:60]!r}")
    return names


def _cmd(args) -> int:
    from flatbody_env.bench.gpu import WHAT, report, run
    from flatbody_env.bench.harness import write_report

    def show(row):
        what = "dynamics" if row["what"] == WHAT else "whole env"
        print(
            f"{what:<9} {row['backend']:<13} {row['method']:<13} N = {row['n']:>8}  {row['steps_per_s']:14.4g} body-steps/s  "
            f"({row['device_name']})",
            flush=True,
        )

    result = run(
        sizes=args.sizes,
        methods=args.methods,
        steps=args.steps,
        repeats=args.repeats,
        only=args.backends,
        progress=show,
    )
    for note in result["left_out"]:
        print(f"left out: {note}")
    out = Path(args.out)
    paths = write_report(report(result, out.stem), out.parent)
    print(f"wrote {', '.join(str(p) for p in paths)}")
    return 0


def register_bench(bench_sub) -> None:
    p = bench_sub.add_parser(
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
        "--sizes", type=_sizes, default=[256, 1024, 4096, 16384, 65536], metavar="N,N,...", help="numbers of bodies"
    )
    p.add_argument(
        "--methods", type=_methods, default=["RK4", "DOP853-numba"], metavar="NAME,...", help="batch methods to time"
    )
    p.add_argument(
        "--backends",
        type=_backends,
        default=None,
        metavar="NAME,...",
        help="time only these (cpu-serial, cpu-parallel, cuda; default: every one here), e.g. cuda alone at large N",
    )
    p.add_argument("--steps", type=int_at_least("steps", 1, 100000), default=10, help="env steps per timed block")
    p.add_argument("--repeats", type=int_at_least("repeats", 1, 100), default=3, help="timed blocks; the best is kept")
    p.set_defaults(handler=_cmd)
