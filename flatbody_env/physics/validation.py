"""The one set of field validators for data that enters the package (JSON, dicts, keywords).

Every check raises ``ValueError`` whose message starts with the field's dotted name
(``params.J``, ``state.lambda``, ``target.mu``) and states the allowed range, so a CLI prints it
as one line (exit 2) and an HTTP service returns it as a 422 naming the field. Numbers are checked
for type before use: ``bool`` is not a number, integers too large for a float are refused, and
NaN/inf are refused.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

_NUMBER_TYPES = (int, float, np.integer, np.floating)


def number(where: str, value: Any, *, positive: bool = False, low: float | None = None, high: float | None = None) -> float:
    """``value`` as a finite float, optionally > 0 and within [low, high].

    Raises
    ------
    ValueError
        Naming ``where`` and the allowed range.
    """
    rng = _range_text(positive, low, high)
    if isinstance(value, bool) or not isinstance(value, _NUMBER_TYPES):
        raise ValueError(f"{where}: must be a finite number{rng}, got {_short(value)}")
    try:
        x = float(value)
    except OverflowError:
        raise ValueError(f"{where}: must be a finite number{rng}, got an integer too large for a float") from None
    if not math.isfinite(x):
        raise ValueError(f"{where}: must be a finite number{rng}, got {_short(value)}")
    if positive and x <= 0.0:
        raise ValueError(f"{where}: must be > 0{rng}, got {x!r}")
    if (low is not None and x < low) or (high is not None and x > high):
        raise ValueError(f"{where}: must lie in{rng}, got {x!r}")
    return x


def mapping(where: str, value: Any) -> Mapping[str, Any]:
    """``value`` if it is a JSON object (a mapping), else a ``ValueError`` naming ``where``."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{where}: expected an object, got {type(value).__name__}")
    return value


def string(where: str, value: Any, *, choices: Iterable[str] | None = None) -> str:
    """``value`` if it is a string (one of ``choices`` when given)."""
    if not isinstance(value, str):
        raise ValueError(f"{where}: must be a string, got {_short(value)}")
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


def _range_text(positive: bool, low: float | None, high: float | None) -> str:
    if low is not None or high is not None:
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        return f" (allowed range [{lo}, {hi}])"
    return " (allowed range (0, inf))" if positive else ""


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


__all__ = ["keys", "mapping", "number", "string"]
