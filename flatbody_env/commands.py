"""Sub-commands of the physics layer: ``simulate``, ``scenes``, ``methods`` (``demo`` lives in :mod:`agents.commands`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def _float_list(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"times: expected comma-separated numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError("times: must be finite numbers")
    return values


def positive_float(name: str):
    """argparse type: a finite number > 0; the error names ``name`` and the allowed range."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: expected a number, got {text!r}") from None
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"{name}: must be a finite number > 0 (allowed range (0, inf)), got {text}")
        return value

    return parse


def int_at_least(name: str, low: int = 1):
    """argparse type: an integer ≥ ``low``; the error names ``name`` and the allowed range."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: expected an integer, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"{name}: must be an integer >= {low}, got {value}")
        return value

    return parse


def _load(args):
    from .scene import load_scene

    if args.scene_file and args.scene:
        raise ValueError("scene: give a scene file or --scene NAME, not both")
    if args.scene_file:
        path = Path(args.scene_file)
        if not path.exists():
            raise ValueError(f"scene: no file {args.scene_file!r}")
        return load_scene(path)
    return load_scene(args.scene or "default")


def add_scene_arguments(p) -> None:
    """The scene selection shared by commands that integrate a scene."""
    p.add_argument("scene_file", nargs="?", metavar="SCENE.json", help="scene file (JSON)")
    p.add_argument("--scene", metavar="NAME", help="built-in scene (see 'flatbody scenes'); default: default")


def add_integration_arguments(p) -> None:
    """Method and tolerance flags shared by commands that integrate."""
    p.add_argument("--t-end", type=positive_float("t_end"), metavar="T", help="final time (default: the scene's t_end)")
    p.add_argument("--method", default="DOP853", help="integrator (see 'flatbody methods'); default DOP853")
    p.add_argument("--rtol", type=positive_float("rtol"), default=1e-10, help="relative tolerance (adaptive methods)")
    p.add_argument("--atol", type=positive_float("atol"), default=1e-10, help="absolute tolerance (adaptive methods)")
    p.add_argument("--step", type=positive_float("step"), default=None, metavar="H", help="step size (fixed-step methods)")
    p.add_argument("--model", default="auto", choices=("auto", "two-polar", "regular"), help="formulation (default auto)")


def _simulate(args) -> int:
    from .simulation import simulate

    scene = _load(args)
    t_end = args.t_end if args.t_end is not None else scene.t_end
    times = None
    if args.times:
        times = _float_list(args.times)
    elif args.samples is not None:
        import numpy as np

        times = np.linspace(0.0, t_end, args.samples)
    traj = simulate(
        scene,
        t_end=t_end,
        times=times,
        method=args.method,
        rtol=args.rtol,
        atol=args.atol,
        step=args.step,
        model=args.model,
        with_rotation=args.with_rotation,
    )
    if args.summary:
        print(format_summary(scene, traj))
        if not args.out:
            return 0
    text = json.dumps(traj.to_dict())
    if args.out:
        Path(args.out).write_text(text + "\n", encoding="utf-8")
        if not args.summary:
            print(f"wrote {args.out} ({traj.t.size} samples, {traj.method}, {traj.model} model)", file=sys.stderr)
    else:
        sys.stdout.write(text + "\n")
    return 0


def format_summary(scene, traj, rows: int = 6) -> str:
    """A short human-readable table of a trajectory and its invariants."""
    import numpy as np

    lines = [
        f"scene {scene.name}: {scene.body.describe()}",
        f"integrated to t = {traj.t[-1]:g} with {traj.method} ({traj.model} model): "
        f"{traj.nfev} RHS evaluations, {traj.wall_time * 1e3:.1f} ms",
        "",
        f"{'t':>9} {'lambda':>10} {'mu':>10} {'rho':>10} {'theta':>10} {'|s|':>10} {'energy':>14}",
    ]
    idx = np.unique(np.linspace(0, traj.t.size - 1, rows).round().astype(int))
    st = traj.state
    for k in idx:
        s = math.sqrt(traj.casimir[k])
        lines.append(
            f"{traj.t[k]:9.3f} {st['lambda'][k]:10.5f} {st['mu'][k]:10.5f} {st['rho'][k]:10.5f} "
            f"{st['theta'][k]:10.4f} {s:10.6f} {traj.energy[k]:14.10f}"
        )
    lines.append("")
    gap = float(np.min(np.abs(st["lambda"] - st["mu"])))
    lines.append(f"closest approach to lambda = mu: |lambda - mu| = {gap:.3g}; rho in [{st['rho'].min():.4g}, {st['rho'].max():.4g}]")
    drift = traj.drift()
    lines.append("invariant drift (max |q(t) - q(0)|): " + ", ".join(f"{k} {v:.2e}" for k, v in drift.items()))
    return "\n".join(lines)


def _scenes(args) -> int:
    from .scene import builtin_scenes

    scenes = builtin_scenes()
    if args.json:
        print(json.dumps({name: sc.to_dict() for name, sc in scenes.items()}, indent=2))
        return 0
    width = max(len(n) for n in scenes)
    for name, sc in scenes.items():
        print(f"{name:<{width}}  t_end={sc.t_end:<8g} {sc.body.describe()}")
        print(f"{'':<{width}}  {sc.description}")
    return 0


def _methods(args) -> int:
    from .integrators import available_methods

    infos = available_methods()
    if args.json:
        print(json.dumps([m.as_dict() for m in infos], indent=2))
        return 0
    header = f"{'name':<22} {'adaptive':<8} {'order':>5} {'chart':<10} {'compiled':<8} preserves"
    print(header)
    print("-" * len(header))
    for m in infos:
        print(
            f"{m.name:<22} {'yes' if m.adaptive else 'no':<8} {m.order:>5} {m.chart:<10} "
            f"{'yes' if m.compiled else 'no':<8} {', '.join(m.preserves) or '-'}"
        )
    return 0


def register(sub) -> None:
    p = sub.add_parser("simulate", help="integrate a scene and print the trajectory as JSON")
    add_scene_arguments(p)
    add_integration_arguments(p)
    p.add_argument("--times", metavar="t1,t2,...", help="output times (default: an even grid)")
    p.add_argument("--samples", type=int_at_least("samples", 2), default=None, metavar="N", help="number of evenly spaced output times (default 101)")
    p.add_argument("--with-rotation", action="store_true", help="also integrate R and output 'rotation'")
    p.add_argument("--out", metavar="FILE", help="write the JSON here instead of stdout")
    p.add_argument("--summary", action="store_true", help="print a readable summary instead of JSON")
    p.set_defaults(handler=_simulate)

    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.add_argument("--json", action="store_true", help="print the scenes as JSON")
    p.set_defaults(handler=_scenes)

    p = sub.add_parser("methods", help="list the integrators")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_methods)
