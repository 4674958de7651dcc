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
(``params.J``, ``state.lambda``, …) and the allowed range (the ranges are those of
:mod:`flatbody_env.physics.validation`: constants in [1e-6, 1e6], λ, μ, ϱ in [1e-6, 1e6],
momenta and θ within ±1e6, t_end in (0, 1e6]).

Built-in scenes ship in ``flatbody_env/scenes/*.json`` (:func:`builtin_scenes`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from flatbody_env.physics import validation
from flatbody_env.physics.body import Body
from flatbody_env.physics.state import STATE_NAMES, validate_state

_TOP_KEYS = {"name", "description", "params", "potential", "thickness", "state", "spin_convention", "t_end"}


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

    def with_state(self, **changes: float) -> Scene:
        """A copy with some state entries replaced (validated)."""
        state = dict(self.state)
        state.update({k: float(v) for k, v in changes.items()})
        try:
            validate_state(state)
        except ValueError as exc:
            raise SceneError(str(exc)) from None
        return Scene(
            name=self.name,
            body=self.body,
            state=state,
            description=self.description,
            t_end=self.t_end,
            source=self.source,
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (round-trips through :func:`load_scene`)."""
        out = dict(self.source)
        out["name"] = self.name
        out["state"] = dict(self.state)
        return out


def scene_from_dict(data: Mapping[str, Any], *, default_name: str = "scene") -> Scene:
    """Validate a scene dict (module docstring) and build a :class:`Scene`."""
    try:
        data = validation.mapping("scene", data)
        validation.keys("scene", data, _TOP_KEYS, ("params", "potential", "thickness", "state"))
        body = Body.from_dict(
            {k: data[k] for k in ("params", "potential", "thickness", "spin_convention") if k in data}
        )
        state = validation.mapping("state", data["state"])
        validate_state(state)
        t_end = (
            validation.number("t_end", data["t_end"], positive=True, high=validation.T_END_MAX)
            if "t_end" in data
            else 20.0
        )
        name = validation.string("name", data.get("name", default_name))
        description = validation.string("description", data.get("description", ""))
    except SceneError:
        raise
    except ValueError as exc:
        raise SceneError(str(exc)) from None
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
    if isinstance(path_or_dict, Scene):
        return path_or_dict
    if isinstance(path_or_dict, Mapping):
        return scene_from_dict(path_or_dict)
    if not isinstance(path_or_dict, (str, Path)):
        raise SceneError(
            f"scene: expected a scene dict, a JSON path or a built-in name, got {type(path_or_dict).__name__}"
        )
    path = Path(path_or_dict)
    try:
        exists = path.exists()
    except (OSError, ValueError) as exc:  # a name too long, a NUL byte
        raise SceneError(f"scene: cannot use {str(path_or_dict)[:60]!r} as a path ({exc})") from None
    if not exists:
        scenes = builtin_scenes()
        if str(path_or_dict) in scenes:
            return scenes[str(path_or_dict)]
        raise SceneError(
            f"scene: no file {str(path)!r} and no built-in scene of that name (built-in: {', '.join(scenes)})"
        )
    try:
        data = validation.read_json("scene", path)
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    return scene_from_dict(data, default_name=path.stem)
