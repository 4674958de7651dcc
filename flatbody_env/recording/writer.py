"""The live writer of rerun recordings (``.rrd``): :class:`Recorder`, and the one-call
:func:`record_trajectory` / :func:`record_arrays` for a whole trajectory of a free scene.

rerun is imported lazily, inside functions. Every recording goes to an explicit
:class:`rerun.RecordingStream` saved to a file (no viewer, no network); the file is complete —
footer written — when :func:`record_arrays` / :func:`record_trajectory` return or
:meth:`Recorder.close` does. Env episodes (the demo, ``record --agent``, ``record-env``) are
recorded by :class:`flatbody_env.recording.wrapper.RerunRecorder`, which feeds a :class:`Recorder`.

What is logged (entity paths; ``step`` and ``sim_time`` timelines on everything temporal)
-----------------------------------------------------------------------------------------
=====================================  =====================================================
entity                                 content
=====================================  =====================================================
``/description``                       markdown: the model, the body, what each view shows
``/world/body``                        ``Ellipsoids3D``: half-sizes (λ, μ, ϱ), orientation R
                                       — the body R·D·(unit ball), eqs. (23)–(24) of [1]
``/world/material``                    ``Transform3D(mat3x3=Φ)``, Φ = R D U(θ)⁻¹ (eq. (23))
``/world/material/lines``              static material lines (rim, spokes, normal) drawn under
                                       Φ: the spokes turn inside the ellipse with U(θ)
``/world/axes_C``                      ``Arrows3D``: principal axes of C = R D⁻² Rᵀ (columns of
                                       R), length (λ, μ, ϱ), labelled with those lengths
``/material/reference``                static undeformed material lines (reference frame)
``/material/G_ellipsoid``              ``Ellipsoids3D``: U D (unit ball) = G^{1/2}(unit ball)
``/material/axes_G``                   ``Arrows3D``: principal axes of G = U D² Uᵀ (columns of
                                       U(θ)), length (λ, μ, ϱ), labelled with those lengths
``/tensors/G``, ``/tensors/C``         ``Tensor`` 3×3 (float64), every ``tensor_every`` steps,
                                       with a fixed symmetric ``value_range`` ±r (static)
``/tensors/numbers``                   markdown: G and C as numbers with their eigenvalues
``/series/G``, ``/series/C``           the 6 independent entries (11, 22, 33, 12, 13, 23)
``/series/{lambda,mu,rho,theta}``      the shape and the material angle
``/series/{s3,p_theta}``               the body's s₃ and p_θ
``/series/{energy,casimir}``           H (eq. (41)) and the Casimir |s|²
``/series/drift/{energy,casimir,       relative drift (Q − Q₀)/|Q₀| of the conserved
p_theta}``                             quantities
``/series/action/NAME``                env episodes: the actions (u = τ₁, τ₂, τ₃, f_ϱ)
``/series/reward/NAME``                env episodes: the reward terms (and ``total``)
``/series/target/NAME``                env episodes: λ*, μ*, ϱ*, s₃*, p_θ*, H* of the target
``/series/distance``                   env episodes: the distance to the target (``info``)
``/world/target``, ``…/outline``       env episodes: the target ellipse R·diag(λ*, μ*, ϱ*)·circle
``/events``                            env episodes: integrator failures, leaving the domain
=====================================  =====================================================

G = ΦᵀΦ = U D² U⁻¹ (eq. (33) of [1]); C = Φ⁻ᵀΦ⁻¹ = R D⁻² R⁻¹ (the corrected remark after eq. (51),
see ``docs/physics.md``); both come from :mod:`flatbody_env.physics.kinematics`. Names, colours and
views: :mod:`flatbody_env.recording.layout`.

Data are sent column-wise (``send_columns``) in blocks: a whole trajectory at once from
:func:`record_arrays`, blocks of ``block`` steps from a live :class:`Recorder`.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flatbody_env.physics.kinematics import cauchy_tensor, configuration, green_tensor, material_rotation
from flatbody_env.physics.state import STATE_NAMES
from flatbody_env.recording.geometry import material_lines, principal_axes, quaternions_xyzw, relative_drift, symmetric_entries, unit_circle
from flatbody_env.recording.layout import (
    ACTION_NAMES,
    AXIS_COLORS,
    DRIFT_SERIES,
    TARGET_SERIES,
    TENSOR_ENTRY_COLORS,
    axis_labels,
    blueprint,
    description_markdown,
    drift_axis,
    material_line_colors,
    nice_range,
    rgba,
    series_style,
    tensor_text,
)

APP_ID = "flatbody"
"""rerun application id of every flatbody recording."""

TIMELINES = ("step", "sim_time")
"""The two timelines: ``step`` (sequence) and ``sim_time`` (duration, integer nanoseconds)."""

BODY_SERIES = ("lambda", "mu", "rho", "theta", "s3", "p_theta", "energy", "casimir")
"""One-scalar series logged at every step of every recording (``/series/NAME``)."""

BODY_ENTITIES = (
    "/description",
    "/world/body",
    "/world/material",
    "/world/material/lines",
    "/world/axes_C",
    "/material/reference",
    "/material/G_ellipsoid",
    "/material/axes_G",
    "/tensors/G",
    "/tensors/C",
    "/tensors/numbers",
    "/series/G",
    "/series/C",
    *(f"/series/{name}" for name in BODY_SERIES),
    *(f"/series/drift/{name}" for name, _ in DRIFT_SERIES),
)
"""Entity paths present in every recording."""

EPISODE_ENTITIES = ("/series/distance", "/world/target", "/world/target/outline", *(f"/series/target/{n}" for n in TARGET_SERIES))
"""Entity paths an env episode adds (besides ``/series/action/…``, ``/series/reward/…`` and ``/events``)."""

_IDX = {name: i for i, name in enumerate(STATE_NAMES)}


@dataclass(frozen=True, kw_only=True)
class _Block:
    """Validated arrays for one ``send_columns`` block of n steps."""

    step: np.ndarray
    t: np.ndarray
    states: np.ndarray
    rotations: np.ndarray
    energy: np.ndarray


def _check_finite(name: str, a: np.ndarray) -> None:
    if not np.all(np.isfinite(a)):
        bad = int(np.argmax(~np.isfinite(a).reshape(a.shape[0], -1).all(axis=1))) if a.ndim else 0
        raise ValueError(f"{name}: must be finite (first non-finite entry at step index {bad})")


def _as_block(t, states, rotations, *, energy, step) -> _Block:
    t = np.asarray(t, dtype=np.float64).ravel()
    n = t.size
    if n == 0:
        raise ValueError("t: must hold at least one time")
    _check_finite("t", t)
    if np.any(np.diff(t) < 0):
        raise ValueError("t: must be non-decreasing")
    states = np.asarray(states, dtype=np.float64)
    if states.shape != (len(STATE_NAMES), n):
        raise ValueError(f"states: expected shape ({len(STATE_NAMES)}, {n}) (state × step), got {states.shape}")
    _check_finite("states", states.T)
    for name in ("lambda", "mu", "rho"):
        if np.any(states[_IDX[name]] <= 0):
            raise ValueError(f"states: {name} must be > 0 (allowed range (0, inf))")
    rotations = np.asarray(rotations, dtype=np.float64)
    if rotations.shape != (n, 3, 3):
        raise ValueError(f"rotations: expected shape ({n}, 3, 3), got {rotations.shape}")
    _check_finite("rotations", rotations)
    ortho = np.max(np.abs(rotations @ np.swapaxes(rotations, 1, 2) - np.eye(3)))
    if ortho > 1e-6 or np.any(np.linalg.det(rotations) <= 0):
        raise ValueError(f"rotations: must be rotation matrices (RRᵀ = I to 1e-6, det > 0); |RRᵀ − I| = {ortho:.2g}")
    if step is None:
        step_arr = np.arange(n, dtype=np.int64)
    else:
        step_arr = np.asarray(step)
        if step_arr.shape != (n,) or not np.issubdtype(step_arr.dtype, np.integer):
            raise ValueError(f"step: expected {n} integers, got shape {step_arr.shape} dtype {step_arr.dtype}")
        step_arr = step_arr.astype(np.int64)
    energy = np.asarray(energy, dtype=np.float64).ravel()
    if energy.shape != (n,):
        raise ValueError(f"energy: expected shape ({n},), got {energy.shape}")
    _check_finite("energy", energy)
    return _Block(step=step_arr, t=t, states=states, rotations=rotations, energy=energy)


def _safe_name(name: str) -> str:
    out = "".join(c if (c.isalnum() or c in "_-") else "_" for c in str(name))
    return out or "_"


def _ns(t) -> np.ndarray:
    return np.round(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64).astype("timedelta64[ns]")


class Recorder:
    """A live recording to an ``.rrd`` file, sent in blocks with ``send_columns``.

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file (parent folders are created).
    body : flatbody_env.physics.body.Body
        The body (its parameters go into the description).
    title : str
        Recording name shown in the viewer.
    description : str, optional
        Extra markdown appended to the standard description.
    block : int
        Steps buffered by :meth:`append` before a ``send_columns`` block is flushed (≥ 1).
    tensor_every : int
        Log the ``Tensor`` views of G and C and their numbers every k-th step (k ≥ 1; the
        6-entry series are logged at every step regardless).
    action_names : sequence of str, optional
        Entity names of the action components (default ``tau1, tau2, tau3, f_rho`` for four).
    recording_id : str, optional
        rerun recording id (default: a fresh UUID).
    spokes : int
        Material spokes drawn under Φ.
    episode : bool
        An env episode: the layout adds the target, reward, distance and action views.
    extent : float
        The body's expected size (largest semi-axis), which places the cameras (> 0).
    drift_range : float, optional
        A fixed axis ±``drift_range`` for the relative-drift plot (default: it follows the data).

    Use as a context manager or call :meth:`close`; the file is complete only after that.
    """

    def __init__(
        self,
        path: str | Path,
        body,
        *,
        title: str = "flatbody",
        description: str = "",
        block: int = 256,
        tensor_every: int = 1,
        action_names: Sequence[str] | None = None,
        recording_id: str | None = None,
        spokes: int = 12,
        episode: bool = False,
        extent: float = 2.0,
        drift_range: float | None = None,
    ) -> None:
        import rerun as rr

        for name, value in (("block", block), ("tensor_every", tensor_every), ("spokes", spokes)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name}: must be an integer ≥ 1, got {value!r}")
        if not (isinstance(extent, (int, float, np.floating)) and np.isfinite(extent) and extent > 0):
            raise ValueError(f"extent: must be a finite number > 0, got {extent!r}")
        self.path = Path(path)
        if self.path.suffix != ".rrd":
            raise ValueError(f"path: a rerun recording file must end in .rrd, got {str(path)!r}")
        self.body = body
        self.block = int(block)
        self.tensor_every = int(tensor_every)
        self.action_names = tuple(action_names) if action_names is not None else None
        self.episode = bool(episode)
        self._buf: list[dict] = []
        self._closed = False
        self._steps = 0
        self._styled: dict[str, int] = {}
        self._members: dict[str, list[str]] = {"action": [], "reward": []}
        self._q0: dict[str, float] | None = None
        self._range = 0.0
        self._tensor_batch_type = None
        self._rr = rr
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id or str(uuid.uuid4()), send_properties=True)
        if not self.rec.is_enabled():
            raise ValueError("RERUN: rerun logging is disabled by the environment variable RERUN (e.g. RERUN=off); unset it to record")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec.save(str(self.path), default_blueprint=blueprint(episode=self.episode, extent=float(extent), drift_range=drift_range))
        self.rec.send_recording_name(title)
        self._log_static(title, description, int(spokes))

    # -- static parts ------------------------------------------------------------------------------
    def _log_static(self, title: str, description: str, spokes: int) -> None:
        rr = self._rr
        rec = self.rec
        text = description_markdown(title, self.body, description, episode=self.episode)
        rec.log("/description", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
        rec.log("/tensors/numbers", rr.TextDocument.from_fields(media_type=rr.MediaType.MARKDOWN), static=True)
        rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log("/material", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        lines = material_lines(spokes)
        colors = material_line_colors(spokes)
        rec.log("/world/material/lines", rr.LineStrips3D(lines, colors=colors, radii=0.008), static=True)
        rec.log("/material/reference", rr.LineStrips3D(lines, colors=colors, radii=0.008), static=True)
        body_color = [rgba((90, 140, 255))]
        rec.log("/world/body", rr.Ellipsoids3D.from_fields(colors=body_color, fill_mode=rr.components.FillMode.MajorWireframe, line_radii=0.006), static=True)
        rec.log("/material/G_ellipsoid", rr.Ellipsoids3D.from_fields(colors=body_color, fill_mode=rr.components.FillMode.MajorWireframe, line_radii=0.006), static=True)
        for ent in ("/world/axes_C", "/material/axes_G"):
            rec.log(ent, rr.Arrows3D.from_fields(colors=AXIS_COLORS, radii=0.02, show_labels=True), static=True)
        for name in BODY_SERIES:
            self._style(f"/series/{name}")
        for name, _ in DRIFT_SERIES:
            self._style(f"/series/drift/{name}")
        for sym in ("G", "C"):
            rec.log(f"/series/{sym}", rr.SeriesLines(names=[f"{sym}{ij}" for ij in ("11", "22", "33", "12", "13", "23")], colors=TENSOR_ENTRY_COLORS), static=True)
        if self.episode:
            from flatbody_env.env.rendering import COLORS

            rec.log("/world/target/outline", rr.LineStrips3D([unit_circle()], colors=[rgba(COLORS["target"])], radii=0.012), static=True)
            self._style("/series/distance")
            for name in TARGET_SERIES:
                self._style(f"/series/target/{name}")

    def _style(self, path: str, index: int = 0) -> None:
        if path not in self._styled:
            name, color, width = series_style(path, index)
            self.rec.log(path, self._rr.SeriesLines(names=name, colors=[color], widths=width), static=True)
            self._styled[path] = index

    # -- appending ---------------------------------------------------------------------------------
    def append(
        self,
        t: float,
        state: Mapping[str, float] | np.ndarray,
        rotation: np.ndarray,
        *,
        energy: float | None = None,
        step: int | None = None,
        action: np.ndarray | Sequence[float] | None = None,
        reward_terms: Mapping[str, float] | None = None,
        target: Mapping[str, float] | None = None,
        distance: float | None = None,
    ) -> None:
        """Buffer one step; a full buffer is flushed as one ``send_columns`` block.

        ``state`` is a dict of the eleven names or an array in :data:`STATE_NAMES` order;
        ``energy`` defaults to H(state) (eq. (41) of [1]); ``step`` to the running count.
        ``action``, ``reward_terms``, ``target`` (its :data:`~flatbody_env.recording.layout.TARGET_SERIES`
        entries) and ``distance`` are an env episode's (``episode=True``).
        """
        if self._closed:
            raise ValueError("recorder: already closed")
        if isinstance(state, Mapping):
            missing = [k for k in STATE_NAMES if k not in state]
            if missing:
                raise ValueError(f"state: missing entries {', '.join(missing)}")
            y = np.array([float(state[k]) for k in STATE_NAMES])
        else:
            y = np.asarray(state, dtype=np.float64).ravel()
            if y.shape != (len(STATE_NAMES),):
                raise ValueError(f"state: expected {len(STATE_NAMES)} entries, got shape {y.shape}")
        if (action is not None or reward_terms or target or distance is not None) and not self.episode:
            raise ValueError("recorder: actions, reward terms, target and distance belong to an episode (Recorder(..., episode=True))")
        if energy is None:
            from flatbody_env.physics.hamiltonian import hamiltonian

            energy = hamiltonian(y, self.body)
        self._buf.append(
            {
                "t": float(t),
                "y": y,
                "R": np.asarray(rotation, dtype=np.float64),
                "energy": float(energy),
                "step": self._steps if step is None else int(step),
                "action": None if action is None else np.asarray(action, dtype=np.float64).ravel(),
                "reward_terms": {str(k): float(v) for k, v in reward_terms.items()} if reward_terms else None,
                "target": {k: float(target[k]) for k in TARGET_SERIES if k in target} if target else None,
                "distance": None if distance is None else float(distance),
            }
        )
        self._steps += 1
        if len(self._buf) >= self.block:
            self.flush()

    def flush(self) -> None:
        """Send the buffered steps as one block (no-op when empty).

        The body, tensors and state series go out for every buffered step; actions, reward
        terms, target and distance for the steps that carry them (a reset has no action or reward).
        """
        if not self._buf:
            return
        buf, self._buf = self._buf, []
        block = _as_block(
            [b["t"] for b in buf],
            np.stack([b["y"] for b in buf], axis=1),
            np.stack([b["R"] for b in buf]),
            energy=[b["energy"] for b in buf],
            step=np.array([b["step"] for b in buf], dtype=np.int64),
        )
        self._send_block(block)
        if self.episode:
            self._send_episode(buf)

    def note(self, text: str, *, step: int, t: float, level: str = "WARN") -> None:
        """Log one event (e.g. an integrator failure) as a ``TextLog`` on ``/events``."""
        rr = self._rr
        self.rec.set_time("step", sequence=int(step))
        self.rec.set_time("sim_time", duration=np.timedelta64(int(round(float(t) * 1e9)), "ns"))
        self.rec.log("/events", rr.TextLog(str(text), level=level))

    def _send_block(self, block: _Block) -> None:
        """Log a whole block of steps column-wise (one ``send_columns`` per entity)."""
        rr = self._rr
        rec = self.rec
        n = block.t.size
        y = block.states
        lam, mu, rho, theta = (y[_IDX[k]] for k in ("lambda", "mu", "rho", "theta"))
        R = block.rotations
        U = material_rotation(theta)
        half = np.stack([lam, mu, rho], axis=1)
        G = green_tensor(lam, mu, rho, theta)
        C = cauchy_tensor(lam, mu, rho, R)
        Phi = configuration(lam, mu, rho, theta, R)
        idx = [rr.TimeColumn("step", sequence=block.step), rr.TimeColumn("sim_time", duration=_ns(block.t))]
        rec.send_columns("/world/body", indexes=idx, columns=rr.Ellipsoids3D.columns(half_sizes=half, quaternions=quaternions_xyzw(R)))
        rec.send_columns("/material/G_ellipsoid", indexes=idx, columns=rr.Ellipsoids3D.columns(half_sizes=half, quaternions=quaternions_xyzw(U)))
        rec.send_columns("/world/material", indexes=idx, columns=rr.Transform3D.columns(mat3x3=Phi))
        labels = axis_labels(half)
        three = np.full(n, 3, dtype=np.int32)
        for ent, frames in (("/world/axes_C", R), ("/material/axes_G", U)):
            vec = principal_axes(frames, half).reshape(3 * n, 3)
            rec.send_columns(ent, indexes=idx, columns=rr.Arrows3D.columns(vectors=vec, labels=labels).partition(three))
        six = np.full(n, 6, dtype=np.int32)
        rec.send_columns("/series/G", indexes=idx, columns=rr.Scalars.columns(scalars=symmetric_entries(G).ravel()).partition(six))
        rec.send_columns("/series/C", indexes=idx, columns=rr.Scalars.columns(scalars=symmetric_entries(C).ravel()).partition(six))
        casimir = y[_IDX["s1"]] ** 2 + y[_IDX["s2"]] ** 2 + y[_IDX["s3"]] ** 2
        series = {"lambda": lam, "mu": mu, "rho": rho, "theta": theta, "s3": y[_IDX["s3"]], "p_theta": y[_IDX["p_theta"]], "energy": block.energy, "casimir": casimir}
        if self._q0 is None:
            self._q0 = {name: float(series[name][0]) for name, _ in DRIFT_SERIES}
        for name, values in series.items():
            rec.send_columns(f"/series/{name}", indexes=idx, columns=rr.Scalars.columns(scalars=values))
        for name, _ in DRIFT_SERIES:
            rec.send_columns(f"/series/drift/{name}", indexes=idx, columns=rr.Scalars.columns(scalars=relative_drift(series[name], self._q0[name])))
        sel = np.flatnonzero(block.step % self.tensor_every == 0)
        if sel.size:
            m = float(max(np.abs(G[sel]).max(), np.abs(C[sel]).max()))
            if m > self._range:  # a fixed, symmetric colour range ±r for both views (widened, never narrowed)
                self._range = nice_range(1.05 * m)
                for ent in ("/tensors/G", "/tensors/C"):
                    rec.log(ent, rr.Tensor.from_fields(value_range=[-self._range, self._range]), static=True)
            tidx = [rr.TimeColumn("step", sequence=block.step[sel]), rr.TimeColumn("sim_time", duration=_ns(block.t[sel]))]
            rec.send_columns("/tensors/G", indexes=tidx, columns=[self._tensor_column(G[sel])])
            rec.send_columns("/tensors/C", indexes=tidx, columns=[self._tensor_column(C[sel])])
            text = tensor_text(block.t[sel], G[sel], C[sel], half[sel], self._range)
            rec.send_columns("/tensors/numbers", indexes=tidx, columns=rr.TextDocument.columns(text=text))

    def _send_episode(self, buf: list[dict]) -> None:
        """Actions, reward terms, target (series and outline) and distance of the buffered steps."""
        rr = self._rr
        with_action = [b for b in buf if b["action"] is not None]
        if with_action:
            sizes = {b["action"].size for b in with_action}
            if len(sizes) != 1:
                raise ValueError(f"action: sizes differ within an episode ({sorted(sizes)})")
            actions = np.stack([b["action"] for b in with_action])
            _check_finite("actions", actions)
            k = actions.shape[1]
            names = self.action_names or (ACTION_NAMES if k == len(ACTION_NAMES) else tuple(f"a{i}" for i in range(k)))
            if len(names) != k:
                raise ValueError(f"action_names: {len(names)} names for actions of size {k}")
            step = np.array([b["step"] for b in with_action], dtype=np.int64)
            t = np.array([b["t"] for b in with_action])
            for i, name in enumerate(names):
                self._series(f"/series/action/{_safe_name(name)}", step, t, actions[:, i], group="action")
        names = sorted({k for b in buf if b["reward_terms"] for k in b["reward_terms"]}, key=lambda n: (n == "total", n))
        for name in names:
            rows = [b for b in buf if b["reward_terms"] and name in b["reward_terms"]]
            values = np.array([b["reward_terms"][name] for b in rows])
            _check_finite(f"reward_terms[{name!r}]", values)
            self._series(f"/series/reward/{_safe_name(name)}", np.array([b["step"] for b in rows], dtype=np.int64), np.array([b["t"] for b in rows]), values, group="reward")
        for name in TARGET_SERIES:
            rows = [b for b in buf if b["target"] and name in b["target"]]
            if rows:
                values = np.array([b["target"][name] for b in rows])
                _check_finite(f"target[{name!r}]", values)
                self._series(f"/series/target/{name}", np.array([b["step"] for b in rows], dtype=np.int64), np.array([b["t"] for b in rows]), values)
        rows = [b for b in buf if b["target"] and all(k in b["target"] for k in ("lambda", "mu", "rho"))]
        if rows:
            D = np.zeros((len(rows), 3, 3))
            for i, b in enumerate(rows):
                D[i] = np.diag([b["target"]["lambda"], b["target"]["mu"], b["target"]["rho"]])
            M = np.stack([b["R"] for b in rows]) @ D  # R·diag(λ*, μ*, ϱ*): the target ellipse along the body's axes
            idx = [rr.TimeColumn("step", sequence=np.array([b["step"] for b in rows], dtype=np.int64)), rr.TimeColumn("sim_time", duration=_ns([b["t"] for b in rows]))]
            self.rec.send_columns("/world/target", indexes=idx, columns=rr.Transform3D.columns(mat3x3=M))
        rows = [b for b in buf if b["distance"] is not None]
        if rows:
            values = np.array([b["distance"] for b in rows])
            _check_finite("distance", values)
            self._series("/series/distance", np.array([b["step"] for b in rows], dtype=np.int64), np.array([b["t"] for b in rows]), values)

    def _series(self, path: str, step: np.ndarray, t: np.ndarray, values: np.ndarray, *, group: str | None = None) -> None:
        rr = self._rr
        if path not in self._styled:
            index = 0
            if group is not None:
                members = self._members[group]
                members.append(path)
                index = len(members) - 1
            self._style(path, index)
        idx = [rr.TimeColumn("step", sequence=step), rr.TimeColumn("sim_time", duration=_ns(t))]
        self.rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(scalars=values))

    def _tensor_column(self, M: np.ndarray):
        """A ``Tensor:data`` column of n 3×3 float64 tensors, built directly in Arrow.

        ``rr.Tensor.columns()`` cannot express a time series of tensors (ECOSYSTEM.md), so the
        ``TensorData`` struct (shape, names, dense-union buffer with the F64 arm) is assembled
        with pyarrow from the type rerun itself reports.
        """
        import pyarrow as pa

        rr = self._rr
        if self._tensor_batch_type is None:
            template = rr.Tensor(np.eye(3), dim_names=["row", "col"]).as_component_batches()[0]
            self._tensor_batch_type = (template.component_descriptor(), template.as_arrow_array().type)
        descriptor, typ = self._tensor_batch_type
        n = M.shape[0]
        pair = np.arange(0, 2 * n + 1, 2, dtype=np.int32)
        shape = pa.ListArray.from_arrays(pa.array(pair), pa.array(np.full(2 * n, 3, dtype=np.uint64)), type=typ.field("shape").type)
        names = pa.ListArray.from_arrays(pa.array(pair), pa.array(["row", "col"] * n, type=pa.string()), type=typ.field("names").type)
        union = typ.field("buffer").type
        children = []
        f64_code = None
        for i, f in enumerate(union):
            if f.name == "F64":
                f64_code = union.type_codes[i]
                offsets = pa.array(np.arange(0, 9 * n + 1, 9, dtype=np.int32))
                children.append(pa.ListArray.from_arrays(offsets, pa.array(np.ascontiguousarray(M, dtype=np.float64).ravel()), type=f.type))
            else:
                children.append(pa.array([], type=f.type))
        if f64_code is None:  # pragma: no cover - a rerun version without the F64 arm
            raise RuntimeError("rerun TensorData has no F64 buffer arm")
        buffer = pa.Array.from_buffers(
            union,
            n,
            [None, pa.py_buffer(np.full(n, f64_code, dtype=np.int8).tobytes()), pa.py_buffer(np.arange(n, dtype=np.int32).tobytes())],
            children=children,
        )
        data = pa.StructArray.from_arrays([shape, names, buffer], fields=list(typ))

        class _Batch:
            def as_arrow_array(self):
                return data

            def component_descriptor(self):
                return descriptor

        return rr.ComponentColumn(descriptor, _Batch())

    # -- finishing ---------------------------------------------------------------------------------
    @property
    def steps(self) -> int:
        """Steps appended so far."""
        return self._steps

    def close(self) -> Path:
        """Flush, write the footer and release the file; returns the path. Idempotent."""
        if not self._closed:
            try:
                self.flush()
            finally:
                self._closed = True
                self.rec.flush()
                self.rec.disconnect()
        return self.path

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def record_arrays(
    t,
    states,
    rotations,
    body,
    path: str | Path,
    *,
    energy=None,
    step=None,
    title: str = "flatbody",
    description: str = "",
    tensor_every: int = 1,
    recording_id: str | None = None,
) -> Path:
    """Record a whole trajectory of a free scene given as arrays to ``path`` (``.rrd``), column-wise.

    Env episodes (actions, reward terms, target) are recorded through
    :class:`flatbody_env.recording.wrapper.RerunRecorder` only.

    Parameters
    ----------
    t : array (n,)
        Simulated times (non-decreasing); logged on ``sim_time`` as integer nanoseconds.
    states : array (11, n)
        States in :data:`flatbody_env.physics.state.STATE_NAMES` order.
    rotations : array (n, 3, 3)
        R(t) ∈ SO(3).
    body : Body
    path : str or Path
    energy : array (n,), optional
        H along the trajectory; computed with :func:`flatbody_env.physics.hamiltonian.hamiltonian_series`
        when omitted.
    step : int array (n,), optional
        Values of the ``step`` timeline (default 0 … n−1).
    title, description : str
        Recording name and extra markdown.
    tensor_every : int
        Log the ``Tensor`` views and numbers every k-th step.
    recording_id : str, optional

    Returns
    -------
    Path
        ``path``; the file is complete (footer written).

    Raises
    ------
    ValueError
        Shapes, non-finite values, non-positive λ, μ, ϱ or non-rotations, naming the field.
    """
    Y = np.asarray(states, dtype=np.float64)
    if Y.ndim != 2 or Y.shape[0] != len(STATE_NAMES):
        raise ValueError(f"states: expected shape ({len(STATE_NAMES)}, n), got {Y.shape}")
    if energy is None:
        from flatbody_env.physics.hamiltonian import hamiltonian_series

        energy = hamiltonian_series(Y, body)
    block = _as_block(t, Y, rotations, energy=energy, step=step)
    extent = float(max(Y[_IDX["lambda"]].max(), Y[_IDX["mu"]].max(), Y[_IDX["rho"]].max()))
    casimir = Y[_IDX["s1"]] ** 2 + Y[_IDX["s2"]] ** 2 + Y[_IDX["s3"]] ** 2
    drift = max(float(np.abs(relative_drift(q, float(q[0]))).max()) for q in (block.energy, casimir, Y[_IDX["p_theta"]]))
    with Recorder(path, body, title=title, description=description, tensor_every=tensor_every, recording_id=recording_id, extent=extent, drift_range=drift_axis(drift)) as rec:
        rec._send_block(block)
    return Path(path)


def record_trajectory(traj, body, path: str | Path, *, title: str | None = None, description: str = "", tensor_every: int = 1, recording_id: str | None = None) -> Path:
    """Record a :class:`flatbody_env.simulation.Trajectory` (with rotation) to ``path``.

    ``traj`` must come from ``simulate(..., with_rotation=True)`` (or the regular model, which
    always returns R). Energy is taken from the trajectory.
    """
    if getattr(traj, "rotation", None) is None:
        raise ValueError("traj.rotation: the trajectory has no R(t); simulate it with with_rotation=True")
    meta = f"Scene `{traj.scene}`, integrated with {traj.method} ({traj.model} model), t ∈ [{traj.t[0]:g}, {traj.t[-1]:g}], {traj.t.size} samples."
    return record_arrays(
        traj.t,
        traj.y,
        traj.rotation,
        body,
        path,
        energy=traj.energy,
        title=title or f"flatbody: {traj.scene or 'trajectory'}",
        description=(meta + ("\n\n" + description if description else "")),
        tensor_every=tensor_every,
        recording_id=recording_id,
    )


