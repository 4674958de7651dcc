"""The one set of argparse types and shared arguments of the ``flatbody`` command.

Each type raises ``argparse.ArgumentTypeError`` (exit 2, one line) naming the field and its range.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def float_list(text: str) -> list[float]:
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


def load_scene_arg(args):
    """The scene a command asked for: a scene file, ``--scene NAME`` or the default scene."""
    from flatbody_env.scene import load_scene

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
    p.add_argument("--model", default="auto", choices=("auto", "stationary", "planar-V1", "planar", "two-polar", "regular"),
                   help="rung of the model ladder (default auto: the lowest the scene allows)")
