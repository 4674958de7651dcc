"""Gymnasium wrappers of the flat-body environment: :class:`RerunRecorder`.

Env layer: gymnasium is imported here; rerun only through :mod:`flatbody_env.recording.writer`
(itself lazy), so importing this module does not import rerun.

The contract the wrapped environment meets (``env.unwrapped``)
--------------------------------------------------------------
* ``body`` — a :class:`flatbody_env.physics.body.Body`;
* ``state`` — a dict of the eleven :data:`flatbody_env.physics.state.STATE_NAMES`, floats;
* optional ``physics_state`` — the same state packed as an array (11,) in ``STATE_NAMES`` order,
  read instead of ``state`` at each step when present (``FlatBodyEnv`` has it);
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
  (from ``reset`` and ``step``) is plotted on ``/series/distance``; what ended the episode early (from
  ``info["status"]`` and ``info["domain_code"]``, in words by :func:`flatbody_env.env.core.end_reason`: an
  integrator failure, leaving the domain or the target's tolerance) is logged as a ``TextLog`` on ``/events``;
  ``info["is_success"]`` (else the distance within the tolerance) decides the outcome.

When an episode ends, its outcome — SUCCESS or MISSED, when the distance first and last came within the
tolerance, what ended it early — is written first in the recording's description and after its name
(:func:`outcome_text`), so that the viewer says at first sight how the episode went.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from flatbody_env.physics.state import STATE_NAMES
from flatbody_env.recording.writer import Recorder, _number


def _numeric(d: Any) -> dict[str, float]:
    """The entries of ``d`` that are numbers (:func:`~flatbody_env.recording.writer._number`), as floats."""
    if not isinstance(d, dict):
        return {}
    return {str(k): f for k, v in d.items() if (f := _number(v)) is not None}


def _state_vector(u) -> np.ndarray:
    """The unwrapped env's state (11,) in :data:`~flatbody_env.physics.state.STATE_NAMES` order: its
    ``physics_state`` when it has one (``FlatBodyEnv``: the packed state, a copy), else from ``state``."""
    y = getattr(u, "physics_state", None)
    if y is not None:
        return np.array(y, dtype=np.float64)
    st = u.state
    return np.array([float(st[k]) for k in STATE_NAMES])


def _check_contract(u) -> None:
    """A clear error when the unwrapped env lacks what the recorder reads (module docstring)."""
    for name in ("body", "state", "rotation", "time"):
        if not hasattr(u, name):
            raise ValueError(
                f"env.unwrapped.{name}: missing — RerunRecorder needs body, state, rotation, time (see flatbody_env.recording.wrapper)"
            )
    state = u.state
    if not isinstance(state, dict) or any(k not in state for k in STATE_NAMES):
        raise ValueError(f"env.unwrapped.state: expected a dict with the entries {', '.join(STATE_NAMES)}")
    packed = getattr(u, "physics_state", None)
    if packed is not None:
        from flatbody_env.physics.state import pack

        if np.shape(packed) != (len(STATE_NAMES),) or not np.array_equal(
            np.asarray(packed, dtype=np.float64), pack(state, validate=False), equal_nan=True
        ):
            raise ValueError(
                f"env.unwrapped.physics_state: expected the state packed in the order {', '.join(STATE_NAMES)}"
            )
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


def _controls(u, action) -> np.ndarray | None:
    """The physical controls u = (τ₁, τ₂, τ₃, f_ϱ) ``action`` applies, from the env's public
    ``controls(action)`` (``FlatBodyEnv``); None when the env has none or refuses the action."""
    fn = getattr(u, "controls", None)
    if not callable(fn):
        return None
    try:
        c = np.asarray(fn(action)[1], dtype=np.float64).ravel()
    except (ValueError, TypeError, IndexError):
        return None
    return c if c.size == 4 and np.all(np.isfinite(c)) else None


def _tolerance(u) -> float | None:
    """The task's success tolerance (``env.unwrapped.task.success_tolerance``), when it has one."""
    tol = _number(getattr(getattr(u, "task", None), "success_tolerance", None))
    return tol if tol is not None and math.isfinite(tol) and tol > 0 else None


def _end_reason(info: dict) -> str:
    """What ended the episode at this step, in words ("" when nothing did): :func:`flatbody_env.env.core.end_reason`
    of ``info["status"]`` and ``info["domain_code"]`` (an env without them ends nothing early)."""
    from flatbody_env.env.core import end_reason

    try:
        status, code = int(info.get("status", 0) or 0), int(info.get("domain_code", 0) or 0)
    except (TypeError, ValueError):
        return ""
    method = info.get("integrator", {}).get("method", "") if isinstance(info.get("integrator"), dict) else ""
    return end_reason(status, code, method) if status or code else ""


def outcome_text(
    t: list[float], distance: list[float], tolerance: float | None, *, success: bool | None, ended: str, finished: bool
) -> tuple[str, str]:
    """(outcome in a sentence, one word) of an episode from its times, distances to the target, the task's tolerance,
    ``success`` (``info["is_success"]`` at the end, None if the env has none), what ended it early and whether it
    finished (terminated or truncated) rather than being cut off by a reset or close."""
    d = np.asarray(distance, dtype=float)
    tt = np.asarray(t, dtype=float)
    ok = np.isfinite(d)
    d, tt = d[ok], tt[ok]
    if not d.size:
        return (f"recorded to t = {t[-1]:.2f}" if t else "no step recorded"), "recorded"
    inside = d <= tolerance if tolerance is not None else np.zeros(d.size, bool)
    if success is None:
        success = bool(inside[-1]) if tolerance is not None else False
    dist = f"distance {d[0]:.3g} → {d[-1]:.3g}"
    if tolerance is not None:
        if inside.any():
            last_out = np.flatnonzero(~inside)
            since = tt[last_out[-1] + 1] if last_out.size and last_out[-1] + 1 < d.size else tt[0]
            first = f"within the tolerance {tolerance:g} from t = {tt[np.argmax(inside)]:.2f}"
            if inside[-1]:
                first += f" (and since t = {since:.2f} to the end)" if since > tt[np.argmax(inside)] else " to the end"
            else:
                first += ", not at the end"
        else:
            first = f"never within the tolerance {tolerance:g}"
    else:
        first = "no tolerance to reach"
    word = "SUCCESS" if success else "MISSED"
    text = f"{word} — {'on the target' if success else 'not on the target'} at t = {tt[-1]:.2f}: {first}; {dist}"
    if ended:
        text += f"; the episode ended early at t = {tt[-1]:.2f}: {ended}"
        word += ", ended early"
    elif not finished:
        text += " (the recording stopped before the episode ended)"
    return text, word


def episode_file(path: str | Path, episode: int) -> Path:
    """The file :class:`RerunRecorder` writes episode ``episode`` to when given ``path``: ``path``
    formatted with ``episode`` if it holds ``{episode}``, else ``path`` itself for the first episode and
    ``STEM-K.rrd`` for episode K."""
    path = str(path)
    if "{episode" in path:
        return Path(path.format(episode=episode))
    if episode == 0:
        return Path(path)
    p = Path(path)
    return p.with_name(f"{p.stem}-{episode}{p.suffix}")


class RerunRecorder(gym.Wrapper):
    """Record episodes of a flat-body environment to rerun ``.rrd`` files.

    Each recorded episode is one recording: the state after ``reset`` is step 0, and every
    ``step`` adds the new state with the action that led to it, the reward terms and the
    target. A step only keeps what it read from the env, in the recorder's one per-step buffer
    (:meth:`~flatbody_env.recording.writer.Recorder.append`); the steps are converted together and
    sent column-wise when ``block`` of them are buffered and when the episode ends — a registered
    400-step episode in one block. A step whose state or R is not finite is noted on ``/events``
    and not drawn. The file is finished (footer written) when the episode terminates or is truncated, on the next
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
        Steps buffered before they are sent as one block (and at the end of the episode).
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
        block: int = 1024,
        tensor_every: int = 1,
        title: str | None = None,
    ) -> None:
        super().__init__(env)
        path = str(path)
        if not path.endswith(".rrd"):
            raise ValueError(f"path: a rerun recording file must end in .rrd, got {path!r}")
        from flatbody_env.physics import validation

        validation.integer("block", block, low=1)
        validation.integer("tensor_every", tensor_every, low=1)
        self._path = path
        self._trigger = episode_trigger or (lambda k: True)
        self._block = block
        self._tensor_every = tensor_every
        self._title = title
        self._episode = -1
        self._step = 0
        self._rec: Recorder | None = None
        self.recorded_paths: list[Path] = []
        self.outcomes: list[str] = []
        """The outcome of each recorded episode in words (:func:`outcome_text`), beside :attr:`recorded_paths`."""
        self._track: dict[str, Any] = {}

    # ------------------------------------------------------------------------------------------
    def episode_path(self, episode: int) -> Path:
        """The file episode ``episode`` is written to (:func:`episode_file`)."""
        return episode_file(self._path, episode)

    @property
    def recording(self) -> bool:
        """Whether the current episode is being recorded."""
        return self._rec is not None

    def _finish(self, *, finished: bool = False) -> None:
        if self._rec is not None:
            rec, self._rec = self._rec, None
            k = self._track
            if k.get("t"):
                text, word = outcome_text(
                    k["t"], k["d"], k["tol"], success=k.get("success"), ended=k.get("ended", ""), finished=finished
                )
                rec.set_outcome(text, short=word)
                self.outcomes.append(text)
            else:
                self.outcomes.append("")
            self.recorded_paths.append(rec.close())

    def _append(self, *, action=None, control=None, reward: float | None = None, info: dict | None = None) -> None:
        """Pass what this step read from the env to the recorder's buffer (which notes and skips a
        step whose state is not finite); note integrator failures and leaving the domain."""
        u = self.env.unwrapped
        stepped = self._step > 0 and isinstance(info, dict)  # the reset has no reward
        t = float(u.time)
        self._rec.append(
            t,
            _state_vector(u),
            u.rotation,
            step=self._step,
            action=action,
            reward_terms=info.get("reward_terms") if stepped else None,
            reward=reward if stepped else None,
            target=getattr(u, "target", None),
            distance=info.get("distance") if isinstance(info, dict) else None,
            control=control,
        )
        k = self._track
        d = _number(info.get("distance")) if isinstance(info, dict) else None
        k.setdefault("t", []).append(t)
        k.setdefault("d", []).append(math.nan if d is None else d)
        if isinstance(info, dict) and "is_success" in info:
            k["success"] = bool(info["is_success"])
        if stepped:
            reason = _end_reason(info)
            if reason:
                k["ended"] = reason
                self._rec.note(
                    f"the episode ended: {reason} (the env keeps the last valid state)", step=self._step, t=t
                )

    # ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._finish()
        obs, info = self.env.reset(seed=seed, options=options)
        self._episode += 1
        self._step = 0
        if self._trigger(self._episode):
            from flatbody_env.recording.layout import display_name

            u = self.env.unwrapped
            _check_contract(u)
            target = _numeric(getattr(u, "target", None))
            state = u.state
            extent = max(
                [float(state[k]) for k in ("lambda", "mu", "rho")]
                + [target[k] for k in ("lambda", "mu", "rho") if k in target]
            )
            steps = getattr(getattr(u, "spec", None), "max_episode_steps", None) or getattr(
                getattr(self.env, "spec", None), "max_episode_steps", None
            )
            dt = _number(getattr(u, "dt", None))
            t_end = float(steps) * dt if steps and dt else None
            self._track = {"tol": _tolerance(u)}
            self._rec = Recorder(
                self.episode_path(self._episode),
                u.body,
                title=self._title or f"flatbody episode {self._episode}",
                description=f"Environment `{getattr(getattr(u, 'spec', None), 'id', None) or type(u).__name__}`, episode {self._episode}"
                + (f", seed {seed}" if seed is not None else "")
                + ". Actions and rewards are drawn at the step they lead to."
                + (
                    ("\n\n**Target**: " + ", ".join(f"{display_name(k)}* = {v:.4g}" for k, v in target.items()))
                    if target
                    else ""
                ),
                block=self._block,
                tensor_every=self._tensor_every,
                action_names=_action_names(u),
                episode=True,
                extent=extent if math.isfinite(extent) and extent > 0 else 2.0,
                success_tolerance=_tolerance(u),
                t_end=t_end,
            )
            self._append(info=info)
        return obs, info

    def step(self, action):
        control = None
        if self._rec is not None:
            control = _controls(self.env.unwrapped, action)
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._rec is not None:
            self._step += 1
            self._append(action=action, control=control, reward=reward, info=info)
            if terminated or truncated:
                self._finish(finished=True)
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        try:
            self._finish()
        finally:
            super().close()


__all__ = ["RerunRecorder", "episode_file", "outcome_text"]
