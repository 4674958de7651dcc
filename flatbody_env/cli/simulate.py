"""Sub-commands of the physics layer: ``simulate``, ``scenes``, ``methods`` (``demo`` lives in :mod:`flatbody_env.cli.agents`)."""

from __future__ import annotations

import json
import math
import sys

from flatbody_env.answers import methods_answer, scenes_answer, simulate_trajectory
from flatbody_env.cli.args import (
    add_integration_arguments,
    add_scene_arguments,
    int_at_least,
    load_scene_arg,
    output_file,
    times_list,
)
from flatbody_env.physics.validation import MAX_SAMPLES, MIN_SAMPLES
from flatbody_env.simulation import DEFAULT_SAMPLES


def _simulate(args) -> int:
    from flatbody_env.output import atomic_write

    scene = load_scene_arg(args)
    traj = simulate_trajectory(
        scene,
        t_end=args.t_end,
        times=args.times,
        samples=args.samples,
        method=args.method,
        rtol=args.rtol,
        atol=args.atol,
        step=args.step,
        model=args.model,
        with_rotation=args.with_rotation,
        max_nfev=args.max_nfev,
        max_wall_time=args.max_seconds,
    )
    if args.summary:
        print(format_summary(scene, traj))
        if not args.out:
            return 0
    text = json.dumps(traj.to_dict())
    if args.out:
        atomic_write(args.out, text + "\n")
        if not args.summary:
            print(f"wrote {args.out} ({traj.t.size} samples, {traj.method}, {traj.model} model)", file=sys.stderr)
            for line in _rung_lines(traj):
                print(line, file=sys.stderr)
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
        *_rung_lines(traj),
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
    lines.append(
        f"closest approach to lambda = mu: |lambda - mu| = {gap:.3g}; rho in [{st['rho'].min():.4g}, {st['rho'].max():.4g}]"
    )
    drift = traj.drift()
    lines.append("invariant drift (max |q(t) - q(0)|): " + ", ".join(f"{k} {v:.2e}" for k, v in drift.items()))
    return "\n".join(lines)


def _rung_lines(traj) -> list[str]:
    """The rung of the model ladder and why it was chosen (the invariant and its measured size)."""
    rung = traj.extra.get("rung")
    if rung is None:
        return []
    measured = ", ".join(f"{k} = {v:.3g}" for k, v in traj.extra.get("rung_measured", {}).items())
    return [f"rung: {rung} -- {traj.extra.get('rung_invariant', '')}" + (f" [{measured}]" if measured else "")]


def _scenes(args) -> int:
    from flatbody_env.scene import builtin_scenes

    scenes = builtin_scenes()
    if args.json:
        print(json.dumps(scenes_answer(), indent=2))
        return 0
    width = max(len(n) for n in scenes)
    for name, sc in scenes.items():
        print(f"{name:<{width}}  t_end={sc.t_end:<8g} {sc.body.describe()}")
        print(f"{'':<{width}}  {sc.description}")
    return 0


def _methods(args) -> int:
    from flatbody_env.integrators import available_methods

    infos = available_methods()
    if args.json:
        print(json.dumps(methods_answer(), indent=2))
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
    p.add_argument(
        "--times",
        type=times_list,
        metavar="t1,t2,...",
        help="output times in [0, t_end], increasing: exactly these rows are returned (add 0 for the initial state; "
        "it is also in the JSON's 'initial_state'); default: an even grid",
    )
    p.add_argument(
        "--samples",
        type=int_at_least("samples", MIN_SAMPLES, MAX_SAMPLES),
        default=None,
        metavar="N",
        help=f"number of evenly spaced output times in [0, t_end] (default {DEFAULT_SAMPLES}, at most {MAX_SAMPLES})",
    )
    p.add_argument("--with-rotation", action="store_true", help="also integrate R and output 'rotation'")
    p.add_argument(
        "--out",
        type=output_file("--out"),
        metavar="FILE",
        help="write the JSON here instead of stdout (replaced atomically)",
    )
    p.add_argument("--summary", action="store_true", help="print a readable summary instead of JSON")
    p.set_defaults(handler=_simulate)

    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.add_argument("--json", action="store_true", help="print the scenes as JSON")
    p.set_defaults(handler=_scenes)

    p = sub.add_parser("methods", help="list the integrators")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=_methods)
