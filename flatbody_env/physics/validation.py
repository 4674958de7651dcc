"""The one set of field validators for data that enters the package (JSON, dicts, keywords, files).

Every check raises ``ValueError`` whose message starts with the field's dotted name
(``params.J``, ``state.lambda``, ``target.mu``) and states the allowed range, so a CLI prints it
as one line (exit 2) and an HTTP service returns it as a 422 naming the field. Numbers are checked
for type before use: ``bool`` is not a number, integers too large for a float are refused, and
NaN/inf are refused.

A refusal's "X: must be …" / "X: must lie in …" text is composed here and nowhere else
(a test of the suite holds it): a rule no validator below states goes through
:func:`requirement` (a condition and the rule) or :func:`refusal` (the exception to raise, also without
the value or as another class, e.g. argparse's ``ArgumentTypeError``).

Documented ranges
-----------------
The model is integrated in double precision; magnitudes outside these ranges make it stiff
beyond any step budget or overflow the kinetic energy (ω ~ s/(Jλ²) squared), so they are refused
up front with the range in the message:

==========================================  ==========================================
field                                       allowed
==========================================  ==========================================
J, J1, J2, J3, k, c, d, κ, a, b             :data:`PARAM_RANGE` = [1e-6, 1e6]
λ, μ, ϱ                                     :data:`STRETCH_RANGE` = [1e-6, 1e6]
s1, s2, s3, p_θ, p_λ, p_μ, p_ϱ, θ            within ± :data:`MOMENTUM_MAX` = ±1e6
t_end                                       (0, :data:`T_END_MAX`] = (0, 1e6]
output times (``times=``, ``--samples``)     at most :data:`MAX_SAMPLES` = 100 000 (an even grid: at least :data:`MIN_SAMPLES` = 2)
rtol, atol                                  :data:`TOL_RANGE` = [1e-16, 1]
fixed step h                                [:data:`STEP_MIN`, :data:`T_END_MAX`] = [1e-6, 1e6]
==========================================  ==========================================

Sizes, counts and budgets (env ``dt``, sub-steps, batch sizes, workers, episodes, seeds, grids,
wall-clock seconds) have the upper bounds of the constants below (``STEP_MIN`` … ``MAX_SECONDS``),
checked before any allocation or loop.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

_NUMBER_TYPES = (int, float, np.integer, np.floating)

PARAM_RANGE = (1e-6, 1e6)
"""Allowed range of the body's constants J1, J2, J3 (eq. (29)), k, c, d, κ (eqs. (37)–(39)), a, b (eq. (40))."""
STRETCH_RANGE = (1e-6, 1e6)
"""Allowed range of the stretches λ, μ and the thickness ϱ."""
MOMENTUM_MAX = 1e6
"""Largest |s_i|, |p_θ|, |p_λ|, |p_μ|, |p_ϱ| (and |θ|) accepted in a state."""
T_END_MAX = 1e6
"""Largest final time t_end (and fixed step h)."""
MAX_SAMPLES = 100_000
"""Most output times one integration may return (``times=``, ``--samples``, grids)."""
MIN_SAMPLES = 2
"""Fewest points of an even grid of output times (``samples``, ``--samples``): t = 0 and t_end."""
TOL_RANGE = (1e-16, 1.0)
"""Allowed range of rtol and atol."""
MAX_JSON_BYTES = 256 * 1024 * 1024
"""Largest JSON file :func:`read_json` reads (a trajectory of :data:`MAX_SAMPLES` rows is ~40 MB); also the default
cap of :func:`read_bytes` and :func:`read_npz`."""
MAX_TEXT_BYTES = 16 * 1024 * 1024
"""Largest text file :func:`read_text` reads by default (a Markdown page, a CSV table, the trusted-runs list)."""
MAX_YAML_BYTES = 1024 * 1024
"""Largest YAML file :func:`read_yaml` reads (hyperparameters, search spaces, a run's ``config.yml``)."""
YAML_MAX_NODES = 100_000
"""Most YAML nodes of one document, counted with its aliases expanded (:func:`parse_yaml`)."""
MAX_ARRAY_BYTES = 256 * 1024 * 1024
"""Most bytes the arrays of one ``.npz`` file may declare (:func:`read_npz`), checked before any is read."""

# --- bounded work: every size, count and step a user can give (docs/reliability.md, "Bounded work") ---
STEP_MIN = 1e-6
"""Smallest fixed step h (``step=``, ``--step``): a smaller step is refused, never replaced."""
ENV_DT_RANGE = (1e-4, 1.0)
"""Allowed env step ``dt`` of ``FlatBody-v0`` (default 0.05)."""
ENV_MAX_SUBSTEPS = 100_000
"""Most fixed sub-steps ⌈dt/step⌉ in one env step."""
ENV_STEP_MAX_SECONDS = 10.0
"""Per-env-step wall-clock budget (``max_wall_time`` of the env's integrator)."""
ENV_STEP_MAX_NFEV = 1_000_000
"""Per-env-step budget of right-hand-side evaluations (``max_nfev`` of the env's integrator)."""
MAX_EPISODE_STEPS = 1_000_000
"""Largest ``max_episode_steps`` (vector env, ``--max-steps``, ``--episode-steps``)."""
RESET_MAX_STEPS = 200_000
"""Most env steps one body's reset may simulate (a witnessed start: ``witness_steps`` × ``max_witness_attempts``),
checked before the first reset; each of those steps has the per-step budget :data:`ENV_STEP_MAX_NFEV`."""
WITNESS_MAX_STEPS = 10_000
"""Largest ``witness_steps`` (the reversed run of a witnessed start; the registered episodes have 400)."""
MAX_BATCH = 65_536
"""Most bodies in one batch or vector env (``num_envs``, ``--batch``, ``--n-envs``)."""
MAX_WORKERS = 256
"""Most worker processes or threads a command starts (``--workers``, ``--threads``)."""
MAX_EPISODES = 100_000
"""Most episodes one command runs (``--episodes``, ``--eval-episodes``)."""
MAX_TIMESTEPS = 1_000_000_000
"""Most environment steps of one training run or benchmark (``--n-timesteps``, ``--timesteps``, ``--steps``)."""
MAX_REPEATS = 1_000
"""Most timing repeats or trials (``--repeats``, ``--trials``, ``--evaluations``)."""
MAX_SEED = 2**32 - 1
"""Largest seed (numpy's)."""
MAX_COUNT = 10**9
"""Upper bound of any other count a user can give (the default of :func:`count`)."""
MAX_SECONDS = 86_400.0
"""Largest wall-clock budget in seconds (``max_wall_time``, ``--max-seconds``, ``--max-run-s``)."""
SEARCH_GRID_RANGE = (8, 2001)
"""Grid points per axis of the root search for stationary ellipses (``SearchBox.n`` of :mod:`analysis.stationary`, ``--grid``)."""
FAMILY_SEEDS_RANGE = (2, 200)
"""Parameter values at which a family's solutions are all sought (``seeds`` of :func:`analysis.families.follow_family`, ``--seeds``)."""
SWEEP_GRID_RANGE = (4, 20_000)
"""Grid points per axis of ``flatbody sweep stability-map`` (:data:`flatbody_env.sweep.tasks.MAX_GRID`; rows are stored in chunks)."""
MAP_GRID_RANGE = (SWEEP_GRID_RANGE[0], 400)
"""Grid points per axis of the serial ``flatbody stability-map`` (one process; larger maps: ``flatbody sweep stability-map``)."""
MAX_TRAINER_BYTES = 2 * 1024**3
"""Most memory a training run's own buffers may be predicted to take (a rollout or replay buffer, the networks with
their gradients, target copies and optimiser state), checked from its hyperparameters before any is allocated
(:func:`memory`)."""


def count(where: str, value: Any, *, low: int = 1, high: int = MAX_COUNT) -> int:
    """``value`` as an ``int`` in [low, high] — every size and count a user can give has an upper
    bound, checked before any allocation or loop (``ValueError`` naming ``where`` and the range)."""
    return integer(where, value, low=low, high=high)


def fixed_step(where: str, value: Any, *, high: float = T_END_MAX) -> float:
    """A fixed step h in [:data:`STEP_MIN`, ``high``]; a smaller step is an error, never replaced."""
    return number(where, value, low=STEP_MIN, high=high)


def finite_result(where: str, values: Mapping[str, Any]) -> None:
    """Refuse a result holding NaN or ±inf: ``ValueError`` naming ``where``, the first quantity and why
    (no silent non-finite numbers in an output)."""
    for name, value in values.items():
        if value is None:
            continue
        arr = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise ValueError(
                f"{where}.{name}: not finite on this input (NaN or infinity; e.g. at a singular state such as "
                "lambda = mu or lambda = 0), so it is not reported"
            )


def number(
    where: str, value: Any, *, positive: bool = False, low: float | None = None, high: float | None = None
) -> float:
    """``value`` as a finite float, optionally > 0 and within [low, high].

    Raises
    ------
    ValueError
        Naming ``where`` and the allowed range.
    """
    # a plain float inside its range returns at once (this check runs on every value of every call); the range's
    # text is composed only for a refusal
    if (
        type(value) is float
        and -math.inf < value < math.inf
        and (not positive or value > 0.0)
        and (low is None or value >= low)
        and (high is None or value <= high)
    ):
        return value
    if isinstance(value, bool) or not isinstance(value, _NUMBER_TYPES):
        raise ValueError(f"{where}: must be a finite number{_range_text(positive, low, high)}, got {shown(value)}")
    try:
        x = float(value)
    except OverflowError:
        rng = _range_text(positive, low, high)
        raise ValueError(f"{where}: must be a finite number{rng}, got an integer too large for a float") from None
    if not math.isfinite(x):
        raise ValueError(f"{where}: must be a finite number{_range_text(positive, low, high)}, got {shown(value)}")
    if positive and x <= 0.0:
        raise ValueError(f"{where}: must be > 0{_range_text(positive, low, high)}, got {x!r}")
    if (low is not None and x < low) or (high is not None and x > high):
        raise ValueError(f"{where}: must lie in {_range_bounds(positive, low, high)}, got {x!r}")
    return x


def workers(where: str, value: Any, *, low: int = 1) -> int:
    """A number of worker processes or threads: an ``int`` in [``low``, :data:`MAX_WORKERS`] (``low`` = 0 where 0
    means "none, in this process"); ``ValueError`` naming ``where`` and the range."""
    return integer(where, value, low=low, high=MAX_WORKERS)


def mapping(where: str, value: Any) -> Mapping[str, Any]:
    """``value`` if it is a JSON object (a mapping), else a ``ValueError`` naming ``where``."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{where}: expected an object, got {type(value).__name__}")
    return value


def string(where: str, value: Any, *, choices: Iterable[str] | None = None) -> str:
    """``value`` if it is a string (one of ``choices`` when given)."""
    if not isinstance(value, str):
        raise ValueError(f"{where}: must be a string, got {shown(value)}")
    if choices is not None:
        allowed = tuple(choices)
        if value not in allowed:
            raise ValueError(f"{where}: must be one of {', '.join(allowed)}, got {value!r}")
    return value


def keys(where: str, obj: Mapping[str, Any], allowed: Iterable[str], required: Iterable[str] = ()) -> None:
    """No field outside ``allowed`` and every field of ``required`` present."""
    allowed = set(allowed)
    unknown = sorted(str(k) for k in set(obj) - allowed)
    if unknown:
        raise ValueError(f"{where}.{unknown[0]}: unknown field (allowed: {', '.join(sorted(allowed))})")
    for key in required:
        if key not in obj:
            raise ValueError(f"{where}.{key}: missing field")


def integer(where: str, value: Any, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an ``int`` (not a bool, not a float) within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{where}: must be an integer{_range_text(False, low, high)}, got {shown(value)}")
    x = int(value)
    if (low is not None and x < low) or (high is not None and x > high):
        raise ValueError(f"{where}: must be an integer{_range_text(False, low, high)}, got {shown(x)}")
    return x


def interval(where: str, value: Any, *, low: float, high: float, strict: bool = True) -> tuple[float, float]:
    """``value`` as a range (lo, hi) of two finite numbers within [low, high], lo < hi (lo <= hi unless ``strict``)."""
    order = "<" if strict else "<="
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError(f"{where}: must be (lo, hi) with {low:g} <= lo {order} hi <= {high:g}, got {shown(value)}")
    lo, hi = (number(f"{where}[{i}]", x, low=low, high=high) for i, x in enumerate(value))
    if not (lo < hi if strict else lo <= hi):
        raise ValueError(f"{where}: must be (lo, hi) with lo {order} hi, got {(lo, hi)!r}")
    return lo, hi


def boolean(where: str, value: Any) -> bool:
    """``value`` if it is ``True`` or ``False`` (a numpy bool too), else a ``ValueError`` naming ``where``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{where}: must be true or false, got {shown(value)}")
    return bool(value)


FIELD_KINDS = (
    "integer",
    "number",
    "boolean",
    "choice",
    "string",
    "integers",
    "numbers",
    "layers",
    "list",
    "mapping",
    "switch",
    "frequency",
)
"""What a :class:`Field` accepts (:func:`field`)."""


@dataclass(frozen=True, kw_only=True)
class Field:
    """How one field of a mapping is checked (:func:`field`, :func:`fields`): the one description of a
    hyperparameter, read the same way from a YAML file, a ``--hyperparams KEY=VALUE`` flag or a run's ``config.yml``.

    Attributes
    ----------
    kind : str
        :data:`FIELD_KINDS`: ``integer`` (an int; an integral float or a numeric string such as YAML 1.1's ``1e5``
        too), ``number`` (a finite number; a numeric string such as ``3e-4`` too), ``boolean`` (true or false only),
        ``choice`` (one of ``choices``), ``string``, ``integers`` (a non-empty list of integers), ``numbers`` (a
        non-empty list of finite numbers), ``layers`` (a non-empty list of integers, or a mapping of ``choices`` to
        such lists), ``list`` (a list of at most ``max_items`` of anything: information, never used), ``mapping`` (checked by ``fields``
        when given), ``switch`` (true, false or a mapping checked by ``fields``), ``frequency`` (an integer, or
        ``[integer, unit]`` with the unit one of ``choices``).
    low, high : float, optional
        The allowed range of a number or integer (of each item of a list).
    positive : bool
        A number must be > 0.
    choices : tuple
        ``choice``: the allowed values; ``number``: strings allowed beside a number (e.g. ``"auto"``, and
        ``"auto_0.1"``: the choice with a number in range after an underscore); ``layers``:
        the allowed keys of a mapping; ``frequency``: the units.
    nullable : bool
        ``null`` (None) is allowed too.
    max_items : int
        Most items of a list.
    fields : Mapping[str, Field], optional
        The fields of a ``mapping`` or ``switch``.
    flag : str
        Not a field of the mapping but a command-line flag (``--seed``): refused naming the flag.
    """

    kind: str
    low: float | None = None
    high: float | None = None
    positive: bool = False
    choices: tuple = ()
    nullable: bool = False
    max_items: int = 64
    fields: Mapping[str, Field] | None = None
    flag: str = ""

    def __post_init__(self) -> None:
        if self.kind not in FIELD_KINDS:
            raise ValueError(f"kind: must be one of {', '.join(FIELD_KINDS)}, got {self.kind!r}")


def _numeric_text(value: Any) -> Any:
    """A string that spells a number (YAML 1.1 reads ``3e-4`` and ``1e5`` as strings) as that number; else unchanged."""
    if isinstance(value, str) and len(value) <= 40:
        try:
            return float(value)
        except ValueError:
            return value
    return value


def field(where: str, value: Any, spec: Field) -> Any:
    """``value`` checked against ``spec`` (:class:`Field`) and returned in its plain type (int, float, bool, str,
    list, dict); ``ValueError`` naming ``where`` and what is allowed."""
    if value is None:
        if spec.nullable or spec.flag:
            return None
        raise ValueError(f"{where}: must not be null ({_kind_text(spec)})")
    kind = spec.kind
    if kind == "integer":
        v = _numeric_text(value)
        if isinstance(v, (float, np.floating)) and math.isfinite(v) and float(v).is_integer() and abs(v) < 2**63:
            v = int(v)
        return integer(where, v, low=spec.low, high=spec.high)
    if kind == "number":
        if isinstance(value, str) and value in spec.choices:
            return value
        if isinstance(value, str) and value.partition("_")[0] in spec.choices and "_" in value:
            head, _, tail = value.partition("_")  # "auto_0.1": the choice, starting from a number (SB3's ent_coef)
            number(where, _numeric_text(tail), positive=spec.positive, low=spec.low, high=spec.high)
            return value
        v = _numeric_text(value)
        if isinstance(v, str) and spec.choices:
            raise ValueError(f"{where}: must be one of {', '.join(map(str, spec.choices))} or a number, got {shown(v)}")
        return number(where, v, positive=spec.positive, low=spec.low, high=spec.high)
    if kind == "boolean":
        return boolean(where, value)
    if kind == "choice":
        if isinstance(value, (list, dict)) or value not in spec.choices:
            allowed = ", ".join("null" if c is None else str(c) for c in spec.choices)
            raise ValueError(f"{where}: must be one of {allowed}, got {shown(value)}")
        return value
    if kind == "string":
        return string(where, value)
    if kind == "integers":
        return _integers(where, value, spec)
    if kind == "numbers":
        if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (list, tuple)) or not value:
            raise ValueError(f"{where}: must be {_kind_text(spec)}, got {shown(value)}")
        if len(value) > spec.max_items:
            raise ValueError(f"{where}: must hold at most {spec.max_items} numbers, got {len(value)}")
        item = Field(kind="number", low=spec.low, high=spec.high)
        return [field(f"{where}[{i}]", v, item) for i, v in enumerate(value)]
    if kind == "list":
        if not isinstance(value, (list, tuple)) or len(value) > spec.max_items:
            raise ValueError(f"{where}: must be {_kind_text(spec)}, got {shown(value)}")
        return list(value)
    if kind == "layers":
        if isinstance(value, Mapping):
            keys(where, value, spec.choices)
            return {str(k): _integers(f"{where}.{k}", v, spec) for k, v in value.items()}
        return _integers(where, value, spec)
    if kind == "frequency":
        if isinstance(value, (list, tuple)):
            if len(value) != 2 or value[1] not in spec.choices:
                raise ValueError(
                    f"{where}: must be an integer or [integer, unit] with the unit one of "
                    f"{', '.join(spec.choices)}, got {shown(value)}"
                )
            return [field(f"{where}[0]", value[0], Field(kind="integer", low=spec.low, high=spec.high)), value[1]]
        return field(where, value, Field(kind="integer", low=spec.low, high=spec.high))
    if kind == "switch" and isinstance(value, (bool, np.bool_)):
        return bool(value)
    if not isinstance(value, Mapping):
        raise ValueError(f"{where}: must be {_kind_text(spec)}, got {shown(value)}")
    return fields(where, value, spec.fields) if spec.fields is not None else dict(value)


def fields(where: str, values: Mapping[str, Any], specs: Mapping[str, Field]) -> dict[str, Any]:
    """Every entry of ``values`` checked by its :class:`Field` in ``specs`` (:func:`field`), in order; a key without
    a field is refused naming it and the allowed keys, a key that is a command-line flag (``Field.flag``) naming the
    flag. Returns the checked values (``{}`` for an empty mapping)."""
    mapping(where, values)
    out: dict[str, Any] = {}
    for key, value in values.items():
        name = f"{where}.{str(key)[:60]}"
        spec = specs.get(key) if isinstance(key, str) else None
        if spec is None:
            allowed = sorted(k for k, s in specs.items() if not s.flag)
            raise ValueError(f"{name}: unknown field (allowed: {', '.join(allowed)})")
        if spec.flag:
            raise ValueError(f"{name}: not a hyperparameter; give {spec.flag} on the command line")
        out[key] = field(name, value, spec)
    return out


def requirement(where: str, value: Any, ok: bool, rule: str) -> None:
    """A check that combines fields (``n_steps × n_envs`` divisible by ``batch_size``, ``batch_size`` ≤ ``buffer_size``):
    when ``ok`` is false, ``ValueError`` naming ``where`` with ``rule``, what the value must do (e.g. ``"divide
    n_steps x n_envs = 4096"``)."""
    if not ok:
        raise refusal(where, rule, value)


_UNSHOWN = object()


def refusal(where: str, rule: str, value: Any = _UNSHOWN, *, error: type[Exception] = ValueError) -> Exception:
    """The exception, to be raised by the caller, for a value that breaks ``rule``: the one spelling of a refusal,
    ``"{where}: must {rule}, got {value}"`` (the value bounded by its short repr), for the checks no other validator
    here states — a rule on many values at once, a message that cannot show the value (an array too large to print,
    a check that already ran elsewhere), an exception other than ``ValueError``.

    Parameters
    ----------
    where : str
        The field's dotted name (``times``, ``options.reset_mask``, ``--grid``).
    rule : str
        What the value must do, after "must" (``"be strictly increasing"``, ``"lie in [0, 1]"``).
    value : Any, optional
        The refused value, shown after ", got"; left out, the message ends with the rule.
    error : type of Exception
        The exception's class: ``ValueError`` (the package's), or e.g. ``argparse.ArgumentTypeError`` for an argument
        type of a command line.

    Returns
    -------
    Exception
        ``error(message)``; raise it (``from None`` inside an ``except`` block, to hide the library's error).
    """
    text = f"{where}: must {rule}" if value is _UNSHOWN else f"{where}: must {rule}, got {shown(value)}"
    return error(text)


def memory(where: str, nbytes: int, what: str, *, limit: int = MAX_TRAINER_BYTES) -> int:
    """Refuse a predicted allocation of ``nbytes`` above ``limit`` (:data:`MAX_TRAINER_BYTES`): ``ValueError`` naming
    ``where``, ``what`` would be allocated and both sizes, before anything is allocated. Returns ``nbytes``."""
    if nbytes > limit:
        raise ValueError(
            f"{where}: must keep {what} within {_size_text(limit)}; these settings predict {_size_text(int(nbytes))}"
        )
    return int(nbytes)


def _integers(where: str, value: Any, spec: Field) -> list[int]:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (list, tuple)) or not value:
        raise ValueError(
            f"{where}: must be a non-empty list of integers{_range_text(False, spec.low, spec.high)}, got {shown(value)}"
        )
    if len(value) > spec.max_items:
        raise ValueError(f"{where}: must hold at most {spec.max_items} integers, got {len(value)}")
    return [field(f"{where}[{i}]", v, Field(kind="integer", low=spec.low, high=spec.high)) for i, v in enumerate(value)]


def _kind_text(spec: Field) -> str:
    return {
        "integer": f"an integer{_range_text(False, spec.low, spec.high)}",
        "number": f"a finite number{_range_text(spec.positive, spec.low, spec.high)}",
        "boolean": "true or false",
        "choice": "one of " + ", ".join("null" if c is None else str(c) for c in spec.choices),
        "string": "a string",
        "integers": "a non-empty list of integers",
        "numbers": f"a non-empty list of finite numbers{_range_text(False, spec.low, spec.high)}",
        "layers": "a non-empty list of integers",
        "list": f"a list of at most {spec.max_items} items",
        "mapping": "a mapping",
        "switch": "true, false or a mapping",
        "frequency": "an integer",
    }[spec.kind]


def float_array(where: str, value: Any, *, shape: tuple[int | None, ...], finite: bool = True) -> np.ndarray:
    """``value`` (nested JSON lists or an array) as a float64 array of ``shape`` (None: any length).

    Elements must be numbers (no bools, strings or nulls; integers too large for a float are
    refused); with ``finite`` NaN/inf are refused.
    """
    dims = "x".join("n" if d is None else str(d) for d in shape)
    if isinstance(value, (str, bytes, Mapping)) or value is None or isinstance(value, (bool, int, float)):
        raise ValueError(f"{where}: expected an array of shape ({dims}), got {shown(value)}")
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError, OverflowError, RecursionError):
        raise ValueError(f"{where}: expected an array of shape ({dims}) of numbers") from None
    if arr.dtype.kind not in "iuf":
        raise ValueError(
            f"{where}: expected an array of shape ({dims}) of numbers, got elements of type {arr.dtype.kind!r}"
            if arr.dtype.kind != "O"
            else f"{where}: expected an array of shape ({dims}) of numbers (ragged, nested "
            "too deep, or holding non-numbers / integers too large for a float)"
        )
    if arr.ndim != len(shape) or any(d is not None and d != n for d, n in zip(shape, arr.shape)):
        raise ValueError(f"{where}: expected an array of shape ({dims}), got shape {arr.shape}")
    if isinstance(value, (list, tuple)) and _has_bool(value, len(shape)):
        raise ValueError(f"{where}: expected numbers, got true/false")
    try:
        arr = arr.astype(np.float64)
    except OverflowError:
        raise ValueError(f"{where}: holds an integer too large for a float") from None
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{where}: must hold finite numbers")
    return arr


def _has_bool(value: Any, depth: int) -> bool:
    if depth == 0:
        return isinstance(value, (bool, np.bool_))
    return isinstance(value, (list, tuple)) and any(_has_bool(x, depth - 1) for x in value)


def parse_json(where: str, text: str | bytes) -> Any:
    """JSON text → Python value; malformed, too deeply nested or oversized-integer JSON → ``ValueError`` naming ``where``."""
    import json

    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise ValueError(f"{where}: not valid JSON (nested too deeply)") from None
    except (ValueError, UnicodeDecodeError) as exc:  # e.g. integers beyond Python's digit limit
        raise ValueError(f"{where}: not valid JSON ({shown(str(exc))})") from None


def _path_of(where: str, path: Any):
    import os
    from pathlib import Path

    if not isinstance(path, (str, os.PathLike)) or not str(path) or "\0" in str(path):
        raise ValueError(f"{where}: expected a file path, got {shown(path)}")
    return Path(path)


def _check_regular(where: str, p, info, max_bytes: int) -> None:
    import stat

    if stat.S_ISDIR(info.st_mode):
        raise ValueError(f"{where}: {shown(str(p))} is a directory, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"{where}: {shown(str(p))} is not a regular file (a FIFO, socket or device is never read)")
    if info.st_size > max_bytes:
        raise ValueError(f"{where}: {shown(str(p))} is larger than {_size_text(max_bytes)}")


def read_bytes(where: str, path: Any, *, max_bytes: int = MAX_JSON_BYTES) -> bytes:
    """The one door through which the package reads a file: its bytes, when it is a regular, readable file of
    at most ``max_bytes``.

    The file is looked at (``stat``) before it is opened, then opened without blocking and looked at
    again through the open descriptor (``fstat``), so a FIFO, socket or device — also one swapped in
    between — is refused without a read that could block or never end; at most ``max_bytes + 1`` bytes
    are read, so a file that grows meanwhile is refused too.

    Raises
    ------
    ValueError
        Naming ``where`` and the path: missing, a directory, not a regular file, unreadable, larger
        than ``max_bytes``.
    """
    import os

    p = _path_of(where, path)
    try:
        _check_regular(where, p, p.stat(), max_bytes)
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ValueError(f"{where}: no file {shown(str(p))}") from None
    except OSError as exc:
        raise ValueError(f"{where}: cannot read {shown(str(p))} ({exc.strerror or exc})") from None
    try:
        _check_regular(where, p, os.fstat(fd), max_bytes)
        chunks, left = [], max_bytes + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 24))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    except OSError as exc:
        raise ValueError(f"{where}: cannot read {shown(str(p))} ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) > max_bytes:
        raise ValueError(f"{where}: {shown(str(p))} is larger than {_size_text(max_bytes)}")
    return data


def read_text(where: str, path: Any, *, max_bytes: int = MAX_TEXT_BYTES) -> str:
    """A UTF-8 text file read through :func:`read_bytes` (at most ``max_bytes``); not UTF-8 is a ``ValueError`` naming ``where``."""
    data = read_bytes(where, path, max_bytes=max_bytes)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{where}: {shown(str(path))} is not UTF-8 text (byte {exc.start})") from None


def read_csv(where: str, path: Any, *, max_bytes: int = MAX_JSON_BYTES) -> list[dict[str, str]]:
    """The rows of a CSV table with a header row (as ``csv.DictReader`` gives them), read through :func:`read_text`."""
    import csv
    import io

    text = read_text(where, path, max_bytes=max_bytes)
    try:
        return list(csv.DictReader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise ValueError(f"{where}: {shown(str(path))} is not a CSV table ({_short_text(str(exc))})") from None


def read_json(where: str, path: Any) -> Any:
    """Read and parse a JSON file: a regular, readable file of at most :data:`MAX_JSON_BYTES` (:func:`read_bytes`).

    Missing files, directories, special files (FIFOs, devices), unreadable or oversized files and
    malformed JSON all raise ``ValueError`` naming ``where`` and the path.
    """
    data = read_bytes(where, path, max_bytes=MAX_JSON_BYTES)
    return parse_json(f"{where} ({path})", data)


def parse_yaml(where: str, text: str | bytes, *, max_nodes: int = YAML_MAX_NODES) -> Any:
    """YAML text → Python value with the safe loader (plain data only, no Python objects), within a node budget.

    Every node counts as often as aliases repeat it: the document's size *with its aliases expanded* must
    stay within ``max_nodes``. It is counted while the document is composed, before any Python object is
    built, in time linear in the text, so a few hundred bytes of nested aliases ("billion laughs") are
    refused at once instead of growing into gigabytes wherever the data are walked (printed, copied,
    validated). Recursive aliases, nesting beyond Python's recursion limit and malformed YAML are refused too.

    Raises
    ------
    ValueError
        Naming ``where``.
    """
    import yaml

    sizes: dict[int, int] = {}

    class _Loader(yaml.SafeLoader):
        def compose_node(self, parent, index):
            alias = self.check_event(yaml.AliasEvent)
            node = super().compose_node(parent, index)
            size = sizes.get(id(node))
            if size is None:
                if alias:  # an alias of a node still being composed: an ancestor of itself
                    raise ValueError(f"{where}: a recursive YAML alias (an alias inside the node it names)")
                if isinstance(node, yaml.MappingNode):
                    size = 1 + sum(sizes[id(k)] + sizes[id(v)] for k, v in node.value)
                elif isinstance(node, yaml.SequenceNode):
                    size = 1 + sum(sizes[id(v)] for v in node.value)
                else:
                    size = 1
                sizes[id(node)] = size
            if size > max_nodes:
                raise ValueError(
                    f"{where}: YAML larger than {max_nodes} nodes with its aliases expanded (nested aliases, "
                    "a 'billion laughs' document?)"
                )
            return node

    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise ValueError(f"{where}: not valid YAML ({_short_text(str(exc))})") from None
    except RecursionError:
        raise ValueError(f"{where}: not valid YAML (nested too deeply)") from None
    except ValueError as exc:  # ours above, or an integer beyond Python's digit limit
        if str(exc).startswith(f"{where}: "):
            raise
        raise ValueError(f"{where}: not valid YAML ({_short_text(str(exc))})") from None


def read_yaml(where: str, path: Any, *, max_bytes: int = MAX_YAML_BYTES, max_nodes: int = YAML_MAX_NODES) -> Any:
    """A YAML file read through :func:`read_bytes` (at most ``max_bytes``) and parsed by :func:`parse_yaml`."""
    text = read_text(where, path, max_bytes=max_bytes)
    return parse_yaml(f"{where} ({path})", text, max_nodes=max_nodes)


def read_npz(
    where: str, path: Any, *, max_bytes: int = MAX_JSON_BYTES, max_array_bytes: int = MAX_ARRAY_BYTES
) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file, its members checked before any of them is decompressed into an array.

    The file is read through :func:`read_bytes` (at most ``max_bytes``). Each member must be an ``.npy``
    array whose header (read alone, a few hundred bytes) declares a plain dtype (no pickled objects) and a
    shape whose data fill the member exactly as the archive declares it; the arrays together may declare at
    most ``max_array_bytes``. Only then are the arrays read — so a small file whose headers declare huge
    arrays (or a compressed member that would inflate beyond what it claims) is refused before anything of
    that size is allocated.

    Raises
    ------
    ValueError
        Naming ``where`` and the path: not an npz, a member that is not an array, a pickled (object) array,
        a header that does not match its member, or more than ``max_array_bytes`` declared.
    """
    import io
    import zipfile

    data = read_bytes(where, path, max_bytes=max_bytes)
    name = shown(str(path))
    declared = 0
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            infos = zf.infolist()
            if len(infos) > 4096:
                raise ValueError(f"{len(infos)} members (at most 4096)")
            for info in infos:
                if not info.filename.endswith(".npy"):
                    raise ValueError(f"member {info.filename[:40]!r} is not an .npy array")
                with zf.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    if version == (1, 0):
                        shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
                    elif version in ((2, 0), (3, 0)):
                        shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
                    else:
                        raise ValueError(f"member {info.filename[:40]!r} has npy format {version}")
                    header = fh.tell()
                if dtype.hasobject:
                    raise ValueError(f"member {info.filename[:40]!r} holds Python objects (pickles are never loaded)")
                nbytes = dtype.itemsize
                for n in shape:
                    nbytes *= int(n)
                if header + nbytes != info.file_size:
                    raise ValueError(
                        f"member {info.filename[:40]!r} declares {_size_text(nbytes)} of {dtype} {tuple(shape)}, "
                        f"its data hold {_size_text(max(info.file_size - header, 0))}"
                    )
                declared += nbytes
                if declared > max_array_bytes:
                    raise ValueError(f"its arrays declare more than {_size_text(max_array_bytes)}")
            with np.load(io.BytesIO(data), allow_pickle=False) as npz:
                return {k: npz[k] for k in npz.files}
    except ValueError as exc:
        raise ValueError(f"{where}: {name} is damaged or not an array file ({_short_text(str(exc), 200)})") from None
    except (OSError, EOFError, KeyError, zipfile.BadZipFile, RuntimeError, NotImplementedError) as exc:
        raise ValueError(
            f"{where}: {name} is damaged or not an array file ({type(exc).__name__}: {_short_text(str(exc))})"
        ) from None


def sqlite_file(where: str, path: Any, tables: Iterable[str]) -> None:
    """Check a SQLite database a command is about to open (and write): it is missing or empty (a
    new one will be made), or a regular file holding an intact SQLite database with ``tables``.
    A directory, a special file, a corrupt file or another program's (foreign) database raises
    ``ValueError`` naming ``where`` — nothing is written to it."""
    import os
    import sqlite3
    import stat
    from pathlib import Path

    p = Path(path)
    try:
        info = p.stat()
    except FileNotFoundError:
        return
    except OSError as exc:
        raise ValueError(f"{where}: cannot open {str(p)!r} ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise ValueError(f"{where}: {str(p)!r} is a directory, not a database file (move it away)")
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"{where}: {str(p)!r} is not a regular file")
    if info.st_size == 0:
        return
    try:
        with open(p, "rb") as fh:
            head = fh.read(16)
    except OSError as exc:
        raise ValueError(f"{where}: cannot read {str(p)!r} ({exc.strerror or exc})") from None
    if head != b"SQLite format 3\x00":
        raise ValueError(
            f"{where}: {str(p)!r} is not an SQLite database (corrupt or another kind of file; move it away)"
        )
    try:
        db = sqlite3.connect(f"file:{os.fspath(p.resolve())}?mode=ro", uri=True, timeout=30.0)
        try:
            have = {name for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            db.execute("PRAGMA quick_check(1)").fetchone()
        finally:
            db.close()
    except sqlite3.Error as exc:
        raise ValueError(
            f"{where}: {str(p)!r} is a damaged SQLite database ({shown(str(exc))}; move it away)"
        ) from None
    missing = sorted(set(tables) - have)
    if missing:
        raise ValueError(
            f"{where}: {str(p)!r} is another program's SQLite database (no table {missing[0]!r}); move it away or choose another folder"
        )


def _range_bounds(positive: bool, low: float | None, high: float | None) -> str:
    """The allowed range alone (``[1e-06, 1e+06]``, ``(0, 86400]``), the one spelling every message uses."""
    if positive and low is None:
        return "(0, inf)" if high is None else f"(0, {high:g}]"
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    return f"[{lo}, {hi}]"


def _range_text(positive: bool, low: float | None, high: float | None) -> str:
    """`` (allowed range [lo, hi])`` after what a value must be (empty when nothing bounds it)."""
    if positive or low is not None or high is not None:
        return f" (allowed range {_range_bounds(positive, low, high)})"
    return ""


_REPR = None


def shown(value: Any) -> str:
    """``value`` as an error message shows it after "got": its repr in at most 60 characters, its size bounded
    *before* it is built — containers to a few levels and items (:mod:`reprlib`), long strings cut first, an integer
    of 19 digits or more by its magnitude (``1e+99``) — never the whole repr of a huge or self-similar value (a YAML
    alias bomb, a list of a million items) cut afterwards. The one formatter of refused values (the service's too)."""
    global _REPR
    if _REPR is None:
        import reprlib

        _REPR = reprlib.Repr()
        _REPR.maxlevel, _REPR.maxstring, _REPR.maxlong, _REPR.maxother = 3, 60, 60, 60
        _REPR.maxlist = _REPR.maxtuple = _REPR.maxdict = _REPR.maxset = _REPR.maxfrozenset = _REPR.maxdeque = 6
        _REPR.maxarray = 6
    if isinstance(value, np.ndarray) and (value.ndim > 1 or value.size > 6):  # its shape says more than its repr
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**18:  # 1e+99, not digits cut
        try:
            return f"{value:.6g}"
        except OverflowError:  # beyond a float: its size (bit_length is cheap, str() of it may not be)
            sign = "a negative" if value < 0 else "an"
            return f"{sign} integer of about {value.bit_length() * math.log10(2):.0f} digits"
    try:
        text = _REPR.repr(value)
    except (ValueError, RecursionError):  # integers beyond the digit limit, self-referencing containers
        return f"a {type(value).__name__} too large to print"
    if "\n" in text:  # a multi-line repr (an object's; a string's repr has none) on the message's one line
        text = " ".join(line.strip() for line in text.splitlines())
    return text if len(text) <= 60 else text[:57] + "..."


def _short_text(text: str, limit: int = 120) -> str:
    """A message of a library's exception on one line of at most ``limit`` characters."""
    return " ".join(text[: 4 * limit].split())[:limit]


def _size_text(n: int) -> str:
    for unit, size in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


__all__ = [
    "shown",
    "RESET_MAX_STEPS",
    "WITNESS_MAX_STEPS",
    "FIELD_KINDS",
    "Field",
    "MAX_TRAINER_BYTES",
    "field",
    "fields",
    "memory",
    "requirement",
    "refusal",
    "boolean",
    "interval",
    "ENV_DT_RANGE",
    "ENV_MAX_SUBSTEPS",
    "ENV_STEP_MAX_NFEV",
    "ENV_STEP_MAX_SECONDS",
    "FAMILY_SEEDS_RANGE",
    "MAX_BATCH",
    "MAX_COUNT",
    "MAP_GRID_RANGE",
    "MAX_EPISODES",
    "MAX_EPISODE_STEPS",
    "MAX_REPEATS",
    "MAX_SECONDS",
    "MAX_SEED",
    "MAX_TIMESTEPS",
    "MAX_WORKERS",
    "MIN_SAMPLES",
    "SEARCH_GRID_RANGE",
    "STEP_MIN",
    "SWEEP_GRID_RANGE",
    "count",
    "workers",
    "finite_result",
    "fixed_step",
    "sqlite_file",
    "MAX_ARRAY_BYTES",
    "MAX_JSON_BYTES",
    "MAX_TEXT_BYTES",
    "MAX_YAML_BYTES",
    "YAML_MAX_NODES",
    "parse_yaml",
    "read_bytes",
    "read_csv",
    "read_npz",
    "read_text",
    "read_yaml",
    "MAX_SAMPLES",
    "MOMENTUM_MAX",
    "PARAM_RANGE",
    "STRETCH_RANGE",
    "TOL_RANGE",
    "T_END_MAX",
    "float_array",
    "integer",
    "keys",
    "mapping",
    "number",
    "parse_json",
    "read_json",
    "string",
]
