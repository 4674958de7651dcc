"""Scenes: a body, an initial state and a few defaults, read from JSON or a dict.

A scene file is JSON::

    {
      "name": "regular",                        (optional)
      "description": "...",                     (optional)
      "params": {"J": 1.0, "J3": 0.5},          or {"J1": ..., "J2": ..., "J3": ...}
      "potential": {"name": "V1", "k": 1.0},    V2: "c", "d";  V3: "kappa"
      "thickness": {"a": 1.0, "b": 1.0},        V_ϱ of eq. (40) of [1]; null for none
      "state": {"s1": ..., "s2": ..., "s3": ..., "p_theta": ..., "p_lambda": ..., "p_mu": ...,
                "p_rho": ..., "lambda": ..., "mu": ..., "rho": ..., "theta": ...},
      "spin_convention": "corrected",           (optional; or "paper")
      "t_end": 20.0                             (optional default horizon)
    }

Every error is a :class:`SceneError` (a ``ValueError``) whose message names the field
(``params.J``, ``state.lambda``, …) and the allowed range.

Built-in scenes ship in ``flatbody_env/scenes/*.json`` (:func:`builtin_scenes`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from flatbody_env.physics.body import SPIN_CONVENTIONS, Body, Inertia
from flatbody_env.physics.potentials import ThicknessPotential, V1, V2, V3
from flatbody_env.physics.state import STATE_NAMES, validate_state

_TOP_KEYS = {"name", "description", "params", "potential", "thickness", "state", "spin_convention", "t_end"}
_POTENTIAL_KEYS = {"V1": ("k",), "V2": ("c", "d"), "V3": ("kappa",)}


class SceneError(ValueError):
    """A scene that cannot be used; the message names the field and the allowed range."""


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A body and an initial state (paper's variables, :mod:`flatbody_env.physics.state`)."""

    name: str
    body: Body
    state: dict[str, float]
    description: str = ""
    t_end: float = 20.0
    source: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def with_state(self, **changes: float) -> "Scene":
        """A copy with some state entries replaced (validated)."""
        state = dict(self.state)
        state.update({k: float(v) for k, v in changes.items()})
        try:
            validate_state(state)
        except ValueError as exc:
            raise SceneError(str(exc)) from None
        return Scene(name=self.name, body=self.body, state=state, description=self.description, t_end=self.t_end, source=self.source)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (round-trips through :func:`load_scene`)."""
        out = dict(self.source)
        out["name"] = self.name
        out["state"] = dict(self.state)
        return out


def _number(where: str, value: Any, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}: must be a finite number{' > 0' if positive else ''}, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise SceneError(f"{where}: must be a finite number, got {value!r}")
    if positive and x <= 0.0:
        raise SceneError(f"{where}: must be > 0 (allowed range (0, inf)), got {value!r}")
    return x


def _mapping(where: str, value: Any) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise SceneError(f"{where}: expected an object, got {type(value).__name__}")
    return value


def _keys(where: str, obj: Mapping[str, Any], allowed: set[str] | tuple[str, ...], required: tuple[str, ...]) -> None:
    unknown = sorted(set(obj) - set(allowed))
    if unknown:
        raise SceneError(f"{where}.{unknown[0]}: unknown field (allowed: {', '.join(sorted(allowed))})")
    for key in required:
        if key not in obj:
            raise SceneError(f"{where}.{key}: missing field")


def _inertia(params: Mapping[str, Any]) -> Inertia:
    if "J" in params:
        _keys("params", params, {"J", "J3"}, ("J", "J3"))
        J = _number("params.J", params["J"], positive=True)
        return Inertia(J1=J, J2=J, J3=_number("params.J3", params["J3"], positive=True))
    if "J1" in params or "J2" in params:
        _keys("params", params, {"J1", "J2", "J3"}, ("J1", "J2", "J3"))
        return Inertia(
            J1=_number("params.J1", params["J1"], positive=True),
            J2=_number("params.J2", params["J2"], positive=True),
            J3=_number("params.J3", params["J3"], positive=True),
        )
    _keys("params", params, {"J", "J1", "J2", "J3"}, ())
    raise SceneError("params.J: missing field (give J and J3, or J1, J2 and J3; each > 0)")


def _potential(pot: Mapping[str, Any]):
    if "name" not in pot:
        raise SceneError("potential.name: missing field (allowed: V1, V2, V3)")
    name = pot["name"]
    if name not in _POTENTIAL_KEYS:
        raise SceneError(f"potential.name: unknown potential {name!r} (allowed: V1, V2, V3)")
    keys = _POTENTIAL_KEYS[name]
    _keys("potential", pot, {"name", *keys}, keys)
    values = {k: _number(f"potential.{k}", pot[k], positive=True) for k in keys}
    return {"V1": V1, "V2": V2, "V3": V3}[name](**values)


def scene_from_dict(data: Mapping[str, Any], *, default_name: str = "scene") -> Scene:
    """Validate a scene dict (module docstring) and build a :class:`Scene`."""
    data = _mapping("scene", data)
    _keys("scene", data, _TOP_KEYS, ("params", "potential", "thickness", "state"))
    inertia = _inertia(_mapping("params", data["params"]))
    potential = _potential(_mapping("potential", data["potential"]))
    thick = data["thickness"]
    thickness = None
    if thick is not None:
        thick = _mapping("thickness", thick)
        _keys("thickness", thick, {"a", "b"}, ("a", "b"))
        thickness = ThicknessPotential(a=_number("thickness.a", thick["a"], positive=True), b=_number("thickness.b", thick["b"], positive=True))
    convention = data.get("spin_convention", "corrected")
    if convention not in SPIN_CONVENTIONS:
        raise SceneError(f"spin_convention: must be one of {', '.join(SPIN_CONVENTIONS)}, got {convention!r}")
    state = _mapping("state", data["state"])
    try:
        validate_state(state)
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    t_end = _number("t_end", data["t_end"], positive=True) if "t_end" in data else 20.0
    name = data.get("name", default_name)
    if not isinstance(name, str):
        raise SceneError(f"name: must be a string, got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SceneError(f"description: must be a string, got {description!r}")
    body = Body(inertia=inertia, potential=potential, thickness=thickness, spin_convention=convention)
    return Scene(
        name=name,
        body=body,
        state={k: float(state[k]) for k in STATE_NAMES},
        description=description,
        t_end=t_end,
        source=json.loads(json.dumps(dict(data))),
    )


def builtin_scenes() -> dict[str, Scene]:
    """The scenes shipped with the package, by name."""
    out = {}
    for entry in sorted(resources.files("flatbody_env.scenes").iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".json"):
            data = json.loads(entry.read_text(encoding="utf-8"))
            scene = scene_from_dict(data, default_name=entry.name[:-5])
            out[scene.name] = scene
    return out


def load_scene(path_or_dict: str | Path | Mapping[str, Any]) -> Scene:
    """Load a scene from a JSON file, a dict, or the name of a built-in scene.

    Raises
    ------
    SceneError
        (a ``ValueError``) naming the field and the allowed range.
    """
    if isinstance(path_or_dict, Mapping):
        return scene_from_dict(path_or_dict)
    if isinstance(path_or_dict, Scene):
        return path_or_dict
    path = Path(path_or_dict)
    if not path.exists():
        scenes = builtin_scenes()
        if str(path_or_dict) in scenes:
            return scenes[str(path_or_dict)]
        raise SceneError(f"scene: no file {str(path)!r} and no built-in scene of that name (built-in: {', '.join(scenes)})")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SceneError(f"scene: {path} is not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except OSError as exc:
        raise SceneError(f"scene: cannot read {path} ({exc.strerror})") from None
    return scene_from_dict(data, default_name=path.stem)
