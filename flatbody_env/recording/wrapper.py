"""Gymnasium wrappers of the flat-body environment: :class:`RerunRecorder`.

Env layer: gymnasium is imported here; rerun only through :mod:`flatbody_env.recording.writer`
(itself lazy), so importing this module does not import rerun.

The contract the wrapped environment meets (``env.unwrapped``)
--------------------------------------------------------------
* ``body`` — a :class:`flatbody_env.physics.body.Body`;
* ``state`` — a dict of the eleven :data:`flatbody_env.physics.state.STATE_NAMES`, floats;
* ``rotation`` — R, a 3×3 float64 rotation: ``FlatBodyEnv`` integrates R only when made with
  ``track_rotation=True`` (``gym.make("FlatBody-v0", track_rotation=True)``), else it is None and
  the wrapper stops with a ``ValueError`` saying so;
* ``time`` — the simulated time (float);
* ``target`` — a dict with at least ``lambda``, ``mu``, ``rho``, ``s3``: λ*, μ*, ϱ*, s₃*, p_θ*, H*
  are plotted beside their variables (``/series/target/NAME``), every numeric entry is printed in
  the description, and the target ellipse is outlined in the top view;
* optional ``action_names`` — names of the action components; else derived from ``control``
  (:data:`flatbody_env.env.task.CONTROLS`: the driven ones of τ1, τ2, τ3, f_ϱ);
* ``step`` returns ``info["reward_terms"]`` — a dict name → float (plotted on
  ``/series/reward/NAME``, with the step's reward as ``total``); an optional ``info["distance"]``
  (from ``reset`` and ``step``) is plotted on ``/series/distance``; a truthy
  ``info["integrator_failure"]`` or ``info["left_domain"]`` is logged as a ``TextLog`` on ``/events``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np


def _numeric(d: Any) -> dict[str, float]:
    out: dict[str, float] = {}
    if not isinstance(d, dict):
        return out
    for k, v in d.items():
        if isinstance(v, bool):
            continue
        try:
            f = float(v)
        except (TypeError, ValueError):
            continue
        out[str(k)] = f
    return out


def _check_contract(u) -> None:
    """A clear error when the unwrapped env lacks what the recorder reads (module docstring)."""
    from flatbody_env.physics.state import STATE_NAMES

    for name in ("body", "state", "rotation", "time"):
        if not hasattr(u, name):
            raise ValueError(f"env.unwrapped.{name}: missing — RerunRecorder needs body, state, rotation, time (see flatbody_env.recording.wrapper)")
    state = u.state
    if not isinstance(state, dict) or any(k not in state for k in STATE_NAMES):
        raise ValueError(f"env.unwrapped.state: expected a dict with the entries {', '.join(STATE_NAMES)}")
    R = u.rotation
    if R is None or np.shape(R) != (3, 3):
        raise ValueError(
            "env.unwrapped.rotation: expected a 3×3 rotation R, got "
            f"{None if R is None else np.shape(R)} — make the env with track_rotation=True "
            '(gym.make("FlatBody-v0", track_rotation=True)) so that it integrates R'
        )


def _action_names(u) -> tuple[str, ...] | None:
    """Names of the action entries: ``u.action_names`` if given, else from ``u.control``."""
    names = getattr(u, "action_names", None)
    if names is not None:
        return tuple(str(n) for n in names)
    control = getattr(u, "control", None)
    if isinstance(control, str):
        from flatbody_env.recording.layout import ACTION_NAMES
        from flatbody_env.env.task import CONTROLS, control_mask

        if control in CONTROLS:
            picked = tuple(n for n, m in zip(ACTION_NAMES, control_mask(control)) if m)
            return picked or ("ignored",)
    return None


class RerunRecorder(gym.Wrapper):
    """Record episodes of a flat-body environment to rerun ``.rrd`` files.

    Each recorded episode is one recording: the state after ``reset`` is step 0, and every
    ``step`` adds the new state with the action that led to it, the reward terms and the
    target. Steps are buffered and sent in ``send_columns`` blocks of ``block`` steps; the file
    is finished (footer written) when the episode terminates or is truncated, on the next
    ``reset``, or on ``close``.

    Parameters
    ----------
    env : gymnasium.Env
        An environment meeting the contract in the module docstring.
    path : str or Path
        ``.rrd`` file. With an ``{episode}`` field (``"runs/ep{episode:03d}.rrd"``) every
        episode gets its own formatted name; without one, episode 0 is written to ``path`` and
        episode k ≥ 1 to ``STEM-k.rrd`` beside it.
    episode_trigger : callable(int) -> bool, optional
        Which episodes (0-based) to record; default all.
    block : int
        Steps per ``send_columns`` block.
    tensor_every : int
        ``Tensor`` views of G and C every k-th step.
    title : str, optional
        Recording name (default ``"flatbody episode K"``).

    Attributes
    ----------
    recorded_paths : list of Path
        Files finished so far.
    """

    def __init__(
        self,
        env: gym.Env,
        path: str | Path,
        *,
        episode_trigger: Callable[[int], bool] | None = None,
        block: int = 256,
        tensor_every: int = 1,
        title: str | None = None,
    ) -> None:
        super().__init__(env)
        path = str(path)
        if not path.endswith(".rrd"):
            raise ValueError(f"path: a rerun recording file must end in .rrd, got {path!r}")
        if isinstance(block, bool) or not isinstance(block, int) or block < 1:
            raise ValueError(f"block: must be an integer ≥ 1, got {block!r}")
        if isinstance(tensor_every, bool) or not isinstance(tensor_every, int) or tensor_every < 1:
            raise ValueError(f"tensor_every: must be an integer ≥ 1, got {tensor_every!r}")
        self._path = path
        self._trigger = episode_trigger or (lambda k: True)
        self._block = block
        self._tensor_every = tensor_every
        self._title = title
        self._episode = -1
        self._step = 0
        self._rec = None
        self.recorded_paths: list[Path] = []

    # ------------------------------------------------------------------------------------------
    def episode_path(self, episode: int) -> Path:
        """The file episode ``episode`` is written to."""
        if "{episode" in self._path:
            return Path(self._path.format(episode=episode))
        if episode == 0:
            return Path(self._path)
        p = Path(self._path)
        return p.with_name(f"{p.stem}-{episode}{p.suffix}")

    @property
    def recording(self) -> bool:
        """Whether the current episode is being recorded."""
        return self._rec is not None

    def _finish(self) -> None:
        if self._rec is not None:
            rec, self._rec = self._rec, None
            self.recorded_paths.append(rec.close())

    def _append(self, *, action=None, reward: float | None = None, info: dict | None = None, reset_info: dict | None = None) -> None:
        u = self.env.unwrapped
        state = {k: float(v) for k, v in u.state.items()}
        R = np.asarray(u.rotation, dtype=np.float64)
        t = float(u.time)
        if not (all(math.isfinite(v) for v in state.values()) and np.all(np.isfinite(R))):
            self._rec.note("non-finite state (integration failure): step not drawn", step=self._step, t=t if math.isfinite(t) else 0.0)
            return
        terms = None
        if info is not None:
            terms = _numeric(info.get("reward_terms", {}))
            if reward is not None:
                terms.setdefault("total", float(reward))
            terms = {k: v for k, v in terms.items() if math.isfinite(v)}
        act = None
        if action is not None:
            act = np.asarray(action, dtype=np.float64).ravel()
            if not np.all(np.isfinite(act)):
                act = None
        if info is not None:
            for key in ("integrator_failure", "left_domain"):
                if info.get(key):
                    self._rec.note(f"{key.replace('_', ' ')}: {info[key]} (the env keeps the last valid state)", step=self._step, t=t)
        distance = None
        src = info if info is not None else reset_info
        if isinstance(src, dict) and "distance" in src:
            d = _numeric({"distance": src["distance"]}).get("distance")
            distance = d if d is not None and math.isfinite(d) else None
        self._rec.append(
            t,
            state,
            R,
            step=self._step,
            action=act,
            reward_terms=terms or None,
            target=_numeric(getattr(u, "target", None)) or None,
            distance=distance,
        )

    # ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._finish()
        obs, info = self.env.reset(seed=seed, options=options)
        self._episode += 1
        self._step = 0
        if self._trigger(self._episode):
            from flatbody_env.recording.layout import display_name
            from flatbody_env.recording.writer import Recorder

            u = self.env.unwrapped
            _check_contract(u)
            target = _numeric(getattr(u, "target", None))
            state = u.state
            extent = max([float(state[k]) for k in ("lambda", "mu", "rho")] + [target[k] for k in ("lambda", "mu", "rho") if k in target])
            self._rec = Recorder(
                self.episode_path(self._episode),
                u.body,
                title=self._title or f"flatbody episode {self._episode}",
                description=f"Environment `{getattr(getattr(u, 'spec', None), 'id', None) or type(u).__name__}`, episode {self._episode}"
                + (f", seed {seed}" if seed is not None else "")
                + ". Actions and rewards are drawn at the step they lead to."
                + (("\n\n**Target**: " + ", ".join(f"{display_name(k)}* = {v:.4g}" for k, v in target.items())) if target else ""),
                block=self._block,
                tensor_every=self._tensor_every,
                action_names=_action_names(u),
                episode=True,
                extent=extent if math.isfinite(extent) and extent > 0 else 2.0,
            )
            self._append(info=None, reset_info=info)
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._rec is not None:
            self._step += 1
            self._append(action=action, reward=reward, info=info)
            if terminated or truncated:
                self._finish()
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        try:
            self._finish()
        finally:
            super().close()


__all__ = ["RerunRecorder"]
