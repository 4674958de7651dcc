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

from flatbody_env.physics.state import STATE_NAMES
from flatbody_env.recording.layout import TARGET_SERIES


def _number(v: Any) -> float | None:
    """``v`` as a float; None for a bool or what is not a number (the one rule for what is drawn)."""
    if type(v) is float:
        return v
    if isinstance(v, bool):
        return None
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _numeric(d: Any) -> dict[str, float]:
    """The entries of ``d`` that are numbers (:func:`_number`), as floats."""
    if not isinstance(d, dict):
        return {}
    return {str(k): f for k, v in d.items() if (f := _number(v)) is not None}


class _Columns:
    """Float columns by name, one row per step, NaN where a step lacks a name.

    Only floats go into the columns (no per-step dict or tuple is kept), so buffering an episode
    leaves nothing for the garbage collector to scan."""

    __slots__ = ("cols", "rows", "_last")

    def __init__(self) -> None:
        self.cols: dict[str, list[float]] = {}
        self.rows = 0
        self._last: Any = None  # the row added last, when it was a dict (an episode's target repeats)

    def add(self, d: Any, names: tuple[str, ...] | None = None, total: float | None = None) -> None:
        """Add one row: the entries of ``d`` that are numbers (:func:`_number`; only ``names`` when given),
        and ``total`` under ``"total"`` unless ``d`` has that entry."""
        r = self.rows
        cols = self.cols
        if total is None and r and d is not None and self._last is not None and _same(d, self._last):  # the same row again: repeat it
            for col in cols.values():
                col.append(col[-1])
            self.rows = r + 1
            return
        self._last = dict(d) if isinstance(d, dict) and total is None else None  # a copy: an env may change its dict in place
        added = 0
        if isinstance(d, dict):
            for k, v in d.items():
                if type(k) is not str:
                    k = str(k)
                if names is not None and k not in names:
                    continue
                v = _number(v)
                if v is None:
                    continue
                col = cols.get(k)
                if col is None:
                    col = cols[k] = [math.nan] * r
                if len(col) == r:  # the first of two keys that read the same wins
                    col.append(v)
                    added += 1
        if total is not None:
            col = cols.get("total")
            if col is None:
                col = cols["total"] = [math.nan] * r
            if len(col) == r:
                col.append(float(total))
                added += 1
        if added != len(cols):
            for col in cols.values():
                if len(col) == r:
                    col.append(math.nan)
        self.rows = r + 1

    def arrays(self, keep: np.ndarray) -> dict[str, np.ndarray]:
        """name → the rows ``keep`` as a float array."""
        return {k: np.array(v, dtype=np.float64)[keep] for k, v in self.cols.items()}


def _same(a: Any, b: dict) -> bool:
    """``a == b``, False where the comparison has no single answer (e.g. array entries)."""
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


class _Steps:
    """The steps of an episode not yet sent: what each read from the env, in columns."""

    __slots__ = ("step", "t", "y", "R", "actions", "terms", "target", "distance", "events")

    def __init__(self) -> None:
        self.step: list[int] = []
        self.t: list[float] = []
        self.y: list[np.ndarray] = []
        self.R: list[np.ndarray] = []
        self.actions: list[np.ndarray | None] = []
        self.terms = _Columns()
        self.target = _Columns()
        self.distance: list[float] = []
        self.events: list[tuple[int, str, Any]] = []  # (row, info key, its value): failures and leaving the domain


def _state_vector(u) -> np.ndarray:
    """The unwrapped env's state (11,) in :data:`~flatbody_env.physics.state.STATE_NAMES` order: its
    ``physics_state`` when it has one (``FlatBodyEnv``: the packed state, a copy), else from ``state``."""
    y = getattr(u, "physics_state", None)
    if y is not None:
        return np.array(y, dtype=np.float64)
    st = u.state
    return np.array([float(st[k]) for k in STATE_NAMES])


def _distance(info: dict | None) -> float:
    """``info["distance"]`` as a float; NaN where absent or not finite (not drawn)."""
    d = _number(info.get("distance")) if isinstance(info, dict) else None
    return d if d is not None and math.isfinite(d) else math.nan


def _check_contract(u) -> None:
    """A clear error when the unwrapped env lacks what the recorder reads (module docstring)."""
    for name in ("body", "state", "rotation", "time"):
        if not hasattr(u, name):
            raise ValueError(f"env.unwrapped.{name}: missing — RerunRecorder needs body, state, rotation, time (see flatbody_env.recording.wrapper)")
    state = u.state
    if not isinstance(state, dict) or any(k not in state for k in STATE_NAMES):
        raise ValueError(f"env.unwrapped.state: expected a dict with the entries {', '.join(STATE_NAMES)}")
    packed = getattr(u, "physics_state", None)
    if packed is not None:
        from flatbody_env.physics.state import pack

        if np.shape(packed) != (len(STATE_NAMES),) or not np.array_equal(np.asarray(packed, dtype=np.float64), pack(state, validate=False), equal_nan=True):
            raise ValueError(f"env.unwrapped.physics_state: expected the state packed in the order {', '.join(STATE_NAMES)}")
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
    target. A step only keeps what it read from the env; the steps are converted together and
    sent column-wise (:meth:`~flatbody_env.recording.writer.Recorder.extend`) when ``block`` of
    them are buffered and when the episode ends — a registered 400-step episode in one block. The
    file is finished (footer written) when the episode terminates or is truncated, on the next
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
    recorder : callable, optional
        Makes each episode's recorder, called as :class:`~flatbody_env.recording.writer.Recorder`
        (the default) is: e.g. a :class:`~flatbody_env.recording.process.RecorderProcess`, which
        writes the files from a helper process.

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
        recorder: Callable[..., Any] | None = None,
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
        self._recorder = recorder
        self._trigger = episode_trigger or (lambda k: True)
        self._block = block
        self._tensor_every = tensor_every
        self._title = title
        self._episode = -1
        self._step = 0
        self._rec = None
        self._buf = _Steps()
        self.recorded_paths: list[Path] = []

    # ------------------------------------------------------------------------------------------
    def episode_path(self, episode: int) -> Path:
        """The file episode ``episode`` is written to (:func:`episode_file`)."""
        return episode_file(self._path, episode)

    @property
    def recording(self) -> bool:
        """Whether the current episode is being recorded."""
        return self._rec is not None

    def _finish(self) -> None:
        if self._rec is not None:
            rec, self._rec = self._rec, None
            try:
                self._flush(rec)
            finally:
                self.recorded_paths.append(rec.close())

    def _append(self, *, action=None, reward: float | None = None, info: dict | None = None) -> None:
        """Keep what this step read from the env (numbers and array copies, in columns); :meth:`_flush`
        converts the steps together."""
        u = self.env.unwrapped
        b = self._buf
        row = len(b.t)
        b.step.append(self._step)
        b.t.append(float(u.time))
        b.y.append(_state_vector(u))
        b.R.append(np.array(u.rotation, dtype=np.float64))
        b.actions.append(None if action is None else np.array(action, dtype=np.float64).ravel())
        if self._step == 0 or not isinstance(info, dict):  # the reset: no reward
            b.terms.add(None)
        else:
            b.terms.add(info.get("reward_terms"), total=reward)
            for key in ("integrator_failure", "left_domain"):
                if info.get(key):
                    b.events.append((row, key, info[key]))
        b.target.add(getattr(u, "target", None), names=TARGET_SERIES)
        b.distance.append(_distance(info))
        if row + 1 >= self._block:
            self._flush(self._rec)

    def _flush(self, rec) -> None:
        """Send the buffered steps: a step whose state or R is not finite is noted and not drawn;
        integrator failures and leaving the domain are noted; the rest goes out column-wise."""
        b, self._buf = self._buf, _Steps()
        n = len(b.t)
        if not n:
            return
        t = np.array(b.t)
        Y = np.stack(b.y, axis=1)
        R = np.stack(b.R)
        ok = np.isfinite(Y).all(axis=0) & np.isfinite(R.reshape(n, 9)).all(axis=1)
        events = iter(b.events)
        event = next(events, None)
        for i in range(n):
            if not ok[i]:
                rec.note("non-finite state (integration failure): step not drawn", step=b.step[i], t=t[i] if math.isfinite(t[i]) else 0.0)
            while event is not None and event[0] == i:
                if ok[i]:
                    rec.note(f"{event[1].replace('_', ' ')}: {event[2]} (the env keeps the last valid state)", step=b.step[i], t=t[i])
                event = next(events, None)
        keep = np.flatnonzero(ok)
        if keep.size == 0:
            return
        act = None
        given = [b.actions[i] for i in keep if b.actions[i] is not None]
        if given:
            sizes = {a.size for a in given}
            if len(sizes) != 1:
                raise ValueError(f"action: sizes differ within an episode ({sorted(sizes)})")
            act = np.full((keep.size, sizes.pop()), np.nan)
            for row, i in enumerate(keep):
                a = b.actions[i]
                if a is not None and np.all(np.isfinite(a)):
                    act[row] = a
        reward_terms = {k: np.where(np.isfinite(v), v, np.nan) for k, v in b.terms.arrays(keep).items()}
        target = b.target.arrays(keep)
        for name, values in target.items():
            if not np.all(np.isfinite(values[~np.isnan(values)])):
                raise ValueError(f"target[{name!r}]: must be finite")
        rec.extend(
            t[keep],
            Y[:, keep],
            R[keep],
            step=np.array(b.step, dtype=np.int64)[keep],
            actions=act,
            reward_terms=reward_terms or None,
            target=target or None,
            distance=np.array(b.distance)[keep],
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
            self._rec = (self._recorder or Recorder)(
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
            self._append(info=info)
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


__all__ = ["RerunRecorder", "episode_file"]
