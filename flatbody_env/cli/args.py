"""The one set of argparse types and shared arguments of the ``flatbody`` command.

Each type raises ``argparse.ArgumentTypeError`` (exit 2, one line) naming the field and its range;
the ranges are those of :mod:`flatbody_env.physics.validation` (the same checks as JSON input).
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from flatbody_env.output import check_output_path
from flatbody_env.physics import validation


def _float(name: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name}: expected a number, got {text[:60]!r}") from None


def number(name: str, *, low: float | None = None, high: float | None = None, positive: bool = False):
    """argparse type: a finite number (> 0 with ``positive``) within [low, high]."""

    def parse(text: str) -> float:
        try:
            return validation.number(name, _float(name, text), low=low, high=high, positive=positive)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse


def positive_float(name: str, high: float | None = validation.MAX_COUNT):
    """argparse type: a finite number > 0 (at most ``high``, by default
    :data:`~flatbody_env.physics.validation.MAX_COUNT`); the error names ``name`` and the range."""

    return number(name, positive=True, high=high)


def int_at_least(name: str, low: int = 1, high: int | None = validation.MAX_COUNT):
    """argparse type: an integer in [``low``, ``high``] (every count has an upper bound: by default
    :data:`~flatbody_env.physics.validation.MAX_COUNT`); the error names ``name`` and the allowed range."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: expected an integer, got {text[:60]!r}") from None
        if value < low or (high is not None and value > high):
            rng = f">= {low}" if high is None else f"in [{low}, {high}]"
            raise validation.refusal(name, f"be an integer {rng}", value, error=argparse.ArgumentTypeError)
        return value

    return parse


def seed(name: str = "seed"):
    """argparse type: a seed in [0, :data:`~flatbody_env.physics.validation.MAX_SEED`]."""
    return int_at_least(name, 0, validation.MAX_SEED)


def seconds(name: str):
    """argparse type: a wall-clock budget in (0, :data:`~flatbody_env.physics.validation.MAX_SECONDS`] seconds."""
    return positive_float(name, validation.MAX_SECONDS)


def fixed_step(name: str = "step"):
    """argparse type: a fixed step in [:data:`~flatbody_env.physics.validation.STEP_MIN`, 1e6] (never replaced)."""
    return number(name, low=validation.STEP_MIN, high=validation.T_END_MAX)


def body_constant(name: str):
    """argparse type: a body constant (J, J3, k, c, d, κ, a, b) in :data:`~flatbody_env.physics.validation.PARAM_RANGE`."""
    return number(name, low=validation.PARAM_RANGE[0], high=validation.PARAM_RANGE[1])


def momentum(name: str):
    """argparse type: a momentum or spin component within ± :data:`~flatbody_env.physics.validation.MOMENTUM_MAX`."""
    return number(name, low=-validation.MOMENTUM_MAX, high=validation.MOMENTUM_MAX)


def float_range(name: str, *, low: float = 0.0, high: float = validation.STRETCH_RANGE[1]):
    """argparse type: ``LO,HI`` with low < LO < HI ≤ high (finite)."""

    def parse(text: str) -> tuple[float, float]:
        parts = text.split(",")
        if len(parts) != 2:
            raise argparse.ArgumentTypeError(
                f"{name}: expected LO,HI (two numbers, {low:g} < LO < HI <= {high:g}), got {text[:60]!r}"
            )
        lo, hi = (_float(name, x) for x in parts)
        if not (math.isfinite(lo) and math.isfinite(hi) and low < lo < hi <= high):
            raise argparse.ArgumentTypeError(f"{name}: need {low:g} < LO < HI <= {high:g} (finite), got {text[:60]!r}")
        return lo, hi

    return parse


def number_list(name: str, *, low: float, high: float, max_items: int = 1000):
    """argparse type: comma-separated finite numbers in [low, high], at least one and at most ``max_items``."""
    spec = validation.Field(kind="numbers", low=low, high=high, max_items=max_items)

    def parse(text: str) -> list[float]:
        parts = [x.strip() for x in text.split(",")]
        try:
            return validation.field(name, [_float(name, x) if x else x for x in parts], spec)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse


def seed_range(name: str = "seeds", most: int = 100_000):
    """argparse type: ``LO:HI``, the seeds LO … HI − 1 (0 ≤ LO < HI ≤ :data:`~flatbody_env.physics.validation.MAX_SEED`,
    at most ``most`` of them), as ``(LO, HI)``."""

    def parse(text: str) -> tuple[int, int]:
        try:
            lo, hi = (int(v) for v in text.split(":"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}: expected LO:HI (integers), got {text[:60]!r}") from None
        if not 0 <= lo < hi <= validation.MAX_SEED or hi - lo > most:
            raise validation.refusal(
                name,
                f"be LO:HI with 0 <= LO < HI <= {validation.MAX_SEED}, at most {most} seeds",
                text[:60],
                error=argparse.ArgumentTypeError,
            )
        return lo, hi

    return parse


def int_list(name: str, low: int = 1, high: int = validation.MAX_COUNT, *, max_items: int = 32):
    """argparse type: 1 to ``max_items`` comma-separated integers, each in [``low``, ``high``]."""
    one = int_at_least(name, low, high)

    def parse(text: str) -> list[int]:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        if not 1 <= len(parts) <= max_items:
            raise argparse.ArgumentTypeError(
                f"{name}: expected 1 to {max_items} comma-separated integers, got {text[:60]!r}"
            )
        return [one(p) for p in parts]

    return parse


def name_list(name: str, allowed):
    """argparse type: comma-separated names, each one of ``allowed`` (a sequence, or a function giving it, read when
    the argument is parsed so that heavy modules load only then)."""

    def parse(text: str) -> list[str]:
        names = [p.strip() for p in text.split(",") if p.strip()]
        choices = tuple(allowed() if callable(allowed) else allowed)
        if not names or any(n not in choices for n in names):
            raise argparse.ArgumentTypeError(f"{name}: expected names from {', '.join(choices)}, got {text[:60]!r}")
        return names

    return parse


def times_list(text: str) -> list[float]:
    """argparse type of ``--times``: comma-separated finite numbers, at most
    :data:`~flatbody_env.physics.validation.MAX_SAMPLES` of them (range and order are checked by ``simulate``)."""
    parts = [x for x in text.split(",") if x.strip()]
    if not parts:
        raise argparse.ArgumentTypeError("times: expected comma-separated numbers, got nothing")
    if len(parts) > validation.MAX_SAMPLES:
        raise argparse.ArgumentTypeError(f"times: at most {validation.MAX_SAMPLES} times, got {len(parts)}")
    values = []
    for x in parts:
        try:
            v = float(x)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"times: expected comma-separated numbers, got {x.strip()[:40]!r}"
            ) from None
        if not math.isfinite(v):
            raise validation.refusal("times", "be finite numbers", x.strip()[:40], error=argparse.ArgumentTypeError)
        values.append(v)
    return values


def output_file(name: str, suffixes: tuple[str, ...] = ()):
    """argparse type: a path a command may write (its folder exists and is writable; it is not a
    directory or a special file; it ends with one of ``suffixes`` when given). Files are then
    written atomically (:func:`flatbody_env.output.atomic_write`)."""

    def parse(text: str) -> str:
        try:
            check_output_path(name, text, suffixes)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text

    return parse


def output_dir(name: str):
    """argparse type: a folder a command writes into (created if missing; must not be a file; the nearest existing
    folder must be writable): checked before a long measurement starts, not after it."""

    def parse(text: str) -> str:
        p = Path(text)
        if not text or "\0" in text:
            raise argparse.ArgumentTypeError(f"{name}: expected a folder path, got {text[:60]!r}")
        try:
            if p.exists() and not p.is_dir():
                raise argparse.ArgumentTypeError(f"{name}: {text[:60]!r} exists and is not a directory")
            anchor = p.absolute()
            while not anchor.exists():
                anchor = anchor.parent
        except OSError as exc:  # a name too long for the file system, a component that is a file, ...
            raise argparse.ArgumentTypeError(
                f"{name}: {text[:60]!r} is not a usable folder path ({exc.strerror})"
            ) from None
        if not anchor.is_dir() or not os.access(anchor, os.W_OK | os.X_OK):
            raise argparse.ArgumentTypeError(f"{name}: {str(anchor)[:60]!r} is not a writable directory")
        return text

    return parse


def load_scene_arg(args):
    """The scene a command asked for: a scene file, ``--scene NAME`` or the default scene."""
    from flatbody_env.scene import load_scene

    if args.scene_file and args.scene:
        raise ValueError("scene: give a scene file or --scene NAME, not both")
    return load_scene(args.scene_file or args.scene or "default")


def add_scene_arguments(p) -> None:
    """The scene selection shared by commands that integrate a scene."""
    p.add_argument("scene_file", nargs="?", metavar="SCENE.json", help="scene file (JSON)")
    p.add_argument("--scene", metavar="NAME", help="built-in scene (see 'flatbody scenes'); default: default")


def add_integration_arguments(p) -> None:
    """Method, tolerance and budget flags shared by commands that integrate."""
    from flatbody_env.integrators.base import DEFAULT_MAX_NFEV, DEFAULT_MAX_WALL_TIME

    p.add_argument(
        "--t-end",
        type=positive_float("t_end", validation.T_END_MAX),
        metavar="T",
        help="final time in (0, 1e6] (default: the scene's t_end)",
    )
    p.add_argument(
        "--method",
        default="auto",
        help="integrator (see 'flatbody methods') or auto (default): the fastest that meets --rtol/--atol in the chosen model",
    )
    p.add_argument(
        "--rtol",
        type=number("rtol", low=validation.TOL_RANGE[0], high=validation.TOL_RANGE[1]),
        default=1e-10,
        help="relative tolerance (adaptive methods), in [1e-16, 1]",
    )
    p.add_argument(
        "--atol",
        type=number("atol", low=validation.TOL_RANGE[0], high=validation.TOL_RANGE[1]),
        default=1e-10,
        help="absolute tolerance (adaptive methods), in [1e-16, 1]",
    )
    p.add_argument(
        "--step",
        type=fixed_step("step"),
        default=None,
        metavar="H",
        help="step size (fixed-step methods), in [1e-6, 1e6]",
    )
    p.add_argument(
        "--model",
        default="auto",
        choices=("auto", "stationary", "planar-V1", "planar", "two-polar", "regular"),
        help="rung of the model ladder (default auto: the lowest the scene allows)",
    )
    p.add_argument(
        "--max-nfev",
        type=int_at_least("max_nfev", 1, 10**12),
        default=DEFAULT_MAX_NFEV,
        metavar="N",
        help=f"work budget: right-hand-side evaluations (default {DEFAULT_MAX_NFEV:.0e})",
    )
    p.add_argument(
        "--max-seconds",
        type=seconds("max_seconds"),
        default=DEFAULT_MAX_WALL_TIME,
        metavar="S",
        help=f"work budget: wall-clock seconds of the integration, at most 86400 (default {DEFAULT_MAX_WALL_TIME:g})",
    )
