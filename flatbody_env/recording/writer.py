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

Data are sent column-wise in blocks, one chunk per entity and block: a whole trajectory at once
from :func:`record_arrays`, an env episode (up to ``block`` steps at a time) from
:class:`~flatbody_env.recording.wrapper.RerunRecorder` through :meth:`Recorder.extend`, blocks of
``block`` steps from :meth:`Recorder.append`. The columns are built in Arrow directly, and the
blueprint and the static parts are converted to Arrow once per process and sent again to each file
(rerun's archetype conversions cost more than the rest of a short recording); the Arrow arrays are
the archetypes' own, so a file holds the same data either way.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import functools
import math
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
    camera,
    camera_kind,
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
    """Validated arrays for one block of n steps."""

    step: np.ndarray
    t: np.ndarray
    states: np.ndarray
    rotations: np.ndarray
    energy: np.ndarray
    index: dict
    """The block's timelines (``step``, ``sim_time``) as Arrow arrays, shared by its entities."""


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
    return _Block(step=step_arr, t=t, states=states, rotations=rotations, energy=energy, index=_timelines(step_arr, t))


def _optional_column(name: str, values, n: int, width: int | None = None) -> np.ndarray:
    """An optional per-step column of :meth:`Recorder.extend`: NaN marks a step without a value,
    ±inf is refused (a value that cannot be drawn is not silently dropped)."""
    a = np.asarray(values, dtype=np.float64)
    shape = (n,) if width is None else (n, width)
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    if np.any(np.isinf(a)):
        raise ValueError(f"{name}: must be finite or NaN (NaN marks a step without a value)")
    return a


def _safe_name(name: str) -> str:
    out = "".join(c if (c.isalnum() or c in "_-") else "_" for c in str(name))
    return out or "_"


def _ns(t) -> np.ndarray:
    return np.round(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64).astype("timedelta64[ns]")


# -- Arrow, once per process ---------------------------------------------------------------------------
def _components(*archetypes) -> dict:
    """Component descriptor → Arrow array of rerun archetypes (what ``RecordingStream.log`` sends)."""
    out = {}
    for arch in archetypes:
        batches = arch.as_component_batches() if hasattr(arch, "as_component_batches") else arch
        for b in batches:
            array = b.as_arrow_array()
            if array is not None:
                out.setdefault(b.component_descriptor(), array)
    return out


_STATIC: dict[tuple, dict] = {}


def _static(key: tuple, build) -> dict:
    """The components of a static archetype that does not change between files, converted once per process."""
    comps = _STATIC.get(key)
    if comps is None:
        comps = _STATIC[key] = _components(build())
    return comps


class _Capture:
    """Stands in for a blueprint stream: keeps what a blueprint logs, as (path, components, static)."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, dict, bool]] = []

    def log(self, entity_path, entity, *extra, static: bool = False) -> None:
        self.calls.append((str(entity_path), _components(entity, *extra), bool(static)))


def _views(container):
    import rerun.blueprint as rrb

    if isinstance(container, rrb.View):
        yield container
        return
    for item in container.contents:
        yield from _views(item)


@functools.lru_cache(maxsize=8)
def _blueprint_template(episode: bool, drift_range: float | None) -> tuple[tuple[tuple[str, dict, bool], ...], dict[str, str]]:
    """What :func:`~flatbody_env.recording.layout.blueprint` logs, converted once per (episode, drift
    axis); and the camera property of each 3-D view (path → ``"top"``/``"oblique"``), the only part
    that depends on the body's extent."""
    import rerun.blueprint as rrb

    bp = blueprint(episode=episode, extent=1.0, drift_range=drift_range)
    cap = _Capture()
    bp._log_to_stream(cap)
    cameras = {f"{v.blueprint_path()}/EyeControls3D": camera_kind(v.name) for v in _views(bp.root_container) if isinstance(v, rrb.Spatial3DView)}
    logged = {path for path, _, _ in cap.calls}
    if not set(cameras) <= logged:  # pragma: no cover - a rerun version that logs view properties elsewhere
        raise RuntimeError("rerun blueprint: the 3-D views' EyeControls3D were not logged where expected")
    return tuple(cap.calls), cameras


def _blueprint_storage(*, episode: bool, extent: float, drift_range: float | None):
    """The default blueprint of one file as rerun's in-memory blueprint storage (what ``save`` takes):
    the cached template with the cameras placed for ``extent``."""
    import rerun_bindings as bindings

    calls, cameras = _blueprint_template(bool(episode), drift_range)
    eyes = {kind: _components(camera(kind, extent)) for kind in set(cameras.values())}
    stream = bindings.new_blueprint(application_id=APP_ID, make_default=False, make_thread_default=False, default_enabled=True)
    bindings.set_time_sequence("blueprint", 0, recording=stream)
    for path, comps, static in calls:
        kind = cameras.get(path)
        bindings.log_arrow_msg(path, components=eyes[kind] if kind is not None else comps, static_=static, recording=stream)
    return bindings.memory_recording(recording=stream)


@functools.lru_cache(maxsize=1)
def _column_types() -> dict[str, tuple]:
    """(descriptor, Arrow list type) of every temporal component column, taken from rerun's own
    ``columns()`` once; the columns are then built in Arrow directly."""
    import rerun as rr

    one = np.zeros((1, 3))
    cols = [
        *rr.Scalars.columns(scalars=[0.0]),
        *rr.Ellipsoids3D.columns(half_sizes=one, quaternions=[[0.0, 0.0, 0.0, 1.0]]),
        *rr.Transform3D.columns(mat3x3=np.eye(3)[None]),
        *rr.Arrows3D.columns(vectors=one, labels=["x"]),
        *rr.TextDocument.columns(text=["x"]),
    ]
    out = {}
    for c in cols:
        d = c.component_descriptor()
        out[str(d.component)] = (d, c.as_arrow_array().type)
    return out


_SHARED_OFFSETS = 4096
"""Blocks of at most this many steps share their Arrow offsets (an episode's block; a few kB each)."""


def _build_offsets(n: int, per: int):
    import pyarrow as pa

    return pa.array(np.arange(0, per * n + 1, per, dtype=np.int32))


_shared_offsets = functools.lru_cache(maxsize=32)(_build_offsets)


def _offsets(n: int, per: int):
    """Arrow offsets of n list rows of ``per`` entries each; immutable, so a block's columns share
    them (cached up to :data:`_SHARED_OFFSETS` rows, so that the cache stays small)."""
    return _shared_offsets(n, per) if n <= _SHARED_OFFSETS else _build_offsets(n, per)


def _fixed(values: np.ndarray, n: int, per: int, key: str):
    """A list column of n rows, ``per`` fixed-size float32 vectors each (``values`` (n·per, width))."""
    import pyarrow as pa

    descriptor, typ = _column_types()[key]
    inner = typ.value_type
    flat = pa.array(np.ascontiguousarray(values, dtype=np.float32).ravel())
    vectors = pa.FixedSizeListArray.from_arrays(flat, type=inner)
    return descriptor, pa.ListArray.from_arrays(_offsets(n, per), vectors, type=typ)


def _scalars(values: np.ndarray):
    import pyarrow as pa

    descriptor, typ = _column_types()["Scalars:scalars"]
    values = np.ascontiguousarray(values, dtype=np.float64).ravel()
    return descriptor, pa.ListArray.from_arrays(_offsets(values.size, 1), pa.array(values), type=typ)


def _scalar_rows(values: np.ndarray, per: int):
    """A ``Scalars`` column of rows of ``per`` values each (``values`` (n, per))."""
    import pyarrow as pa

    descriptor, typ = _column_types()["Scalars:scalars"]
    values = np.ascontiguousarray(values, dtype=np.float64)
    n = values.shape[0]
    return descriptor, pa.ListArray.from_arrays(_offsets(n, per), pa.array(values.ravel()), type=typ)


def _strings(texts: list[str], per: int, key: str):
    import pyarrow as pa

    descriptor, typ = _column_types()[key]
    n = len(texts) // per
    return descriptor, pa.ListArray.from_arrays(_offsets(n, per), pa.array(texts, type=typ.value_type), type=typ)


def _mat3x3(M: np.ndarray):
    """``Transform3D:mat3x3`` of n matrices (rerun stores them column-major, float32)."""
    M = np.asarray(M, dtype=np.float64)
    return _fixed(np.swapaxes(M, 1, 2).reshape(-1, 9), M.shape[0], 1, "Transform3D:mat3x3")


def _timelines(step: np.ndarray, t: np.ndarray) -> dict:
    import pyarrow as pa

    return {"step": pa.array(np.asarray(step, dtype=np.int64), pa.int64()), "sim_time": pa.array(_ns(t), pa.duration("ns"))}


class Recorder:
    """A live recording to an ``.rrd`` file, sent column-wise in blocks.

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
        Steps buffered by :meth:`append` before they are sent as one block (≥ 1).
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
        import rerun_bindings as bindings

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
        self._buf: dict[str, list] = self._empty_buffer()
        self._closed = False
        self._steps = 0
        self._styled: dict[str, int] = {}
        self._members: dict[str, list[str]] = {"action": [], "reward": []}
        self._q0: dict[str, float] | None = None
        self._range = 0.0
        self._rr = rr
        self._bindings = bindings
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id or str(uuid.uuid4()), send_properties=True)
        if not self.rec.is_enabled():
            raise ValueError("RERUN: rerun logging is disabled by the environment variable RERUN (e.g. RERUN=off); unset it to record")
        self._native = self.rec.to_native()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        storage = _blueprint_storage(episode=self.episode, extent=float(extent), drift_range=drift_range)
        bindings.save(path=str(self.path), default_blueprint=storage, recording=self._native, write_footer=True)
        self.rec.send_recording_name(title)
        self._log_static(title, description, int(spokes))

    # -- static parts ------------------------------------------------------------------------------
    def _static_log(self, path: str, comps: dict) -> None:
        self._bindings.log_arrow_msg(path, components=comps, static_=True, recording=self._native)

    def _log_static(self, title: str, description: str, spokes: int) -> None:
        rr = self._rr
        text = description_markdown(title, self.body, description, episode=self.episode)
        self._static_log("/description", _components(rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN)))
        self._static_log("/tensors/numbers", _static(("numbers",), lambda: rr.TextDocument.from_fields(media_type=rr.MediaType.MARKDOWN)))
        coords = _static(("coords",), lambda: rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        self._static_log("/world", coords)
        self._static_log("/material", coords)
        lines = _static(("lines", spokes), lambda: rr.LineStrips3D(material_lines(spokes), colors=material_line_colors(spokes), radii=0.008))
        self._static_log("/world/material/lines", lines)
        self._static_log("/material/reference", lines)
        ellipsoid = _static(
            ("ellipsoid",),
            lambda: rr.Ellipsoids3D.from_fields(colors=[rgba((90, 140, 255))], fill_mode=rr.components.FillMode.MajorWireframe, line_radii=0.006),
        )
        self._static_log("/world/body", ellipsoid)
        self._static_log("/material/G_ellipsoid", ellipsoid)
        arrows = _static(("arrows",), lambda: rr.Arrows3D.from_fields(colors=AXIS_COLORS, radii=0.02, show_labels=True))
        for ent in ("/world/axes_C", "/material/axes_G"):
            self._static_log(ent, arrows)
        for name in BODY_SERIES:
            self._style(f"/series/{name}")
        for name, _ in DRIFT_SERIES:
            self._style(f"/series/drift/{name}")
        for sym in ("G", "C"):
            self._static_log(
                f"/series/{sym}",
                _static(("entries", sym), lambda: rr.SeriesLines(names=[f"{sym}{ij}" for ij in ("11", "22", "33", "12", "13", "23")], colors=TENSOR_ENTRY_COLORS)),
            )
        if self.episode:
            from flatbody_env.env.rendering import COLORS

            self._static_log(
                "/world/target/outline", _static(("outline",), lambda: rr.LineStrips3D([unit_circle()], colors=[rgba(COLORS["target"])], radii=0.012))
            )
            self._style("/series/distance")
            for name in TARGET_SERIES:
                self._style(f"/series/target/{name}")

    def _style(self, path: str, index: int = 0) -> None:
        if path not in self._styled:
            rr = self._rr

            def build():
                name, color, width = series_style(path, index)
                return rr.SeriesLines(names=name, colors=[color], widths=width)

            self._static_log(path, _static(("style", path, index), build))
            self._styled[path] = index

    # -- appending ---------------------------------------------------------------------------------
    @staticmethod
    def _empty_buffer() -> dict[str, list]:
        return {k: [] for k in ("t", "y", "R", "energy", "step", "action", "reward_terms", "target", "distance")}

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
        """Buffer one step; a full buffer (``block`` steps) is sent as one block.

        ``state`` is a dict of the eleven names or an array in :data:`STATE_NAMES` order;
        ``energy`` defaults to H(state) (eq. (41) of [1]); ``step`` to the running count.
        ``action``, ``reward_terms``, ``target`` (its :data:`~flatbody_env.recording.layout.TARGET_SERIES`
        entries) and ``distance`` are an env episode's (``episode=True``); they must be finite.
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
        act = None if action is None else np.array(action, dtype=np.float64).ravel()
        terms = {str(k): float(v) for k, v in reward_terms.items()} if reward_terms else None
        tgt = {k: float(target[k]) for k in TARGET_SERIES if k in target} if target else None
        dist = None if distance is None else float(distance)
        checks = (("action", [] if act is None else act.tolist()), ("reward_terms", list((terms or {}).values())),
                  ("target", list((tgt or {}).values())), ("distance", [] if dist is None else [dist]))
        for name, values in checks:
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"{name}: must be finite, got {values!r}")
        buf = self._buf
        buf["t"].append(float(t))
        buf["y"].append(y)
        buf["R"].append(np.array(rotation, dtype=np.float64))
        buf["energy"].append(None if energy is None else float(energy))
        buf["step"].append(self._steps if step is None else int(step))
        buf["action"].append(act)
        buf["reward_terms"].append(terms)
        buf["target"].append(tgt)
        buf["distance"].append(np.nan if dist is None else dist)
        self._steps += 1
        if len(buf["t"]) >= self.block:
            self.flush()

    def flush(self) -> None:
        """Send the steps buffered by :meth:`append` as one block (no-op when empty)."""
        buf = self._buf
        if not buf["t"]:
            return
        self._buf = self._empty_buffer()
        n = len(buf["t"])
        Y = np.stack(buf["y"], axis=1)
        missing = np.array([e is None for e in buf["energy"]])
        energy = np.array([np.nan if e is None else e for e in buf["energy"]])
        if missing.any():
            from flatbody_env.physics.hamiltonian import hamiltonian_series

            _check_finite("states", Y.T)
            energy[missing] = hamiltonian_series(Y[:, missing], self.body)
        actions = terms = target = None
        with_action = [a for a in buf["action"] if a is not None]
        if with_action:
            sizes = {a.size for a in with_action}
            if len(sizes) != 1:
                raise ValueError(f"action: sizes differ within an episode ({sorted(sizes)})")
            actions = np.full((n, sizes.pop()), np.nan)
            for i, a in enumerate(buf["action"]):
                if a is not None:
                    actions[i] = a
        names = {k for d in buf["reward_terms"] if d for k in d}
        if names:
            terms = {name: np.array([d.get(name, np.nan) if d else np.nan for d in buf["reward_terms"]]) for name in names}
        names = {k for d in buf["target"] if d for k in d}
        if names:
            target = {name: np.array([d.get(name, np.nan) if d else np.nan for d in buf["target"]]) for name in names}
        self._extend(buf["t"], Y, np.stack(buf["R"]), step=np.array(buf["step"], dtype=np.int64), energy=energy, actions=actions,
                     reward_terms=terms, target=target, distance=np.array(buf["distance"]) if self.episode else None)

    def extend(
        self,
        t,
        states,
        rotations,
        *,
        step=None,
        energy=None,
        actions=None,
        reward_terms: Mapping[str, np.ndarray] | None = None,
        target: Mapping[str, np.ndarray] | None = None,
        distance=None,
    ) -> None:
        """Send n steps at once, column-wise (what :meth:`append` buffers, given as columns).

        Steps appended and not yet flushed are sent first, so the order of the steps is kept.

        Parameters
        ----------
        t : array (n,)
            Simulated times (non-decreasing).
        states : array (11, n)
            States in :data:`STATE_NAMES` order.
        rotations : array (n, 3, 3)
            R at each step.
        step : int array (n,), optional
            The ``step`` timeline (default: the running count).
        energy : array (n,), optional
            H at each step (default: H of the states, eq. (41) of [1]).
        actions : array (n, k), optional
            Episodes: the action that led to each step; a row of NaN for a step without one (the reset).
        reward_terms, target : mapping name → array (n,), optional
            Episodes: the reward terms (``total`` among them) and the target's
            :data:`~flatbody_env.recording.layout.TARGET_SERIES` entries; NaN where a step has none.
        distance : array (n,), optional
            Episodes: the distance to the target; NaN where a step has none.

        Raises
        ------
        ValueError
            Shapes, non-finite states or rotations, ±inf in an optional column, episode columns
            given to a recording that is not an episode.
        """
        if self._closed:
            raise ValueError("recorder: already closed")
        self.flush()
        t = np.asarray(t, dtype=np.float64).ravel()
        n = t.size
        if step is None:
            step = np.arange(self._steps, self._steps + n, dtype=np.int64)
        self._steps += n
        self._extend(t, states, rotations, step=step, energy=energy, actions=actions, reward_terms=reward_terms, target=target, distance=distance)

    def _extend(self, t, states, rotations, *, step, energy, actions, reward_terms, target, distance) -> None:
        if (actions is not None or reward_terms or target or distance is not None) and not self.episode:
            raise ValueError("recorder: actions, reward terms, target and distance belong to an episode (Recorder(..., episode=True))")
        if energy is None:
            from flatbody_env.physics.hamiltonian import hamiltonian_series

            Y = np.asarray(states, dtype=np.float64)
            if Y.ndim != 2 or Y.shape[0] != len(STATE_NAMES):
                raise ValueError(f"states: expected shape ({len(STATE_NAMES)}, n), got {Y.shape}")
            _check_finite("states", Y.T)
            energy = hamiltonian_series(Y, self.body)
        block = _as_block(t, states, rotations, energy=energy, step=step)
        n = block.t.size
        episode = None
        if self.episode:
            episode = {
                "actions": None if actions is None else _optional_column("actions", actions, n, np.shape(actions)[-1]),
                "reward_terms": {str(k): _optional_column(f"reward_terms[{k!r}]", v, n) for k, v in (reward_terms or {}).items()},
                "target": {k: _optional_column(f"target[{k!r}]", target[k], n) for k in TARGET_SERIES if target and k in target},
                "distance": None if distance is None else _optional_column("distance", distance, n),
            }
        self._send_block(block)
        if episode is not None:
            self._send_episode(block, **episode)

    def note(self, text: str, *, step: int, t: float, level: str = "WARN") -> None:
        """Log one event (e.g. an integrator failure) as a ``TextLog`` on ``/events``."""
        rr = self._rr
        self.rec.set_time("step", sequence=int(step))
        self.rec.set_time("sim_time", duration=np.timedelta64(int(round(float(t) * 1e9)), "ns"))
        self.rec.log("/events", rr.TextLog(str(text), level=level))

    def _send(self, path: str, timelines: dict, *columns) -> None:
        self._bindings.send_arrow_chunk(path, timelines=timelines, components=dict(columns), recording=self._native)

    def _send_block(self, block: _Block) -> None:
        """Log a whole block of steps column-wise (one chunk per entity)."""
        n = block.t.size
        y = block.states
        lam, mu, rho, theta = (y[_IDX[k]] for k in ("lambda", "mu", "rho", "theta"))
        R = block.rotations
        U = material_rotation(theta)
        half = np.stack([lam, mu, rho], axis=1)
        G = green_tensor(lam, mu, rho, theta)
        C = cauchy_tensor(lam, mu, rho, R)
        Phi = configuration(lam, mu, rho, theta, R)
        idx = block.index
        self._send("/world/body", idx, _fixed(half, n, 1, "Ellipsoids3D:half_sizes"), _fixed(quaternions_xyzw(R), n, 1, "Ellipsoids3D:quaternions"))
        self._send("/material/G_ellipsoid", idx, _fixed(half, n, 1, "Ellipsoids3D:half_sizes"), _fixed(quaternions_xyzw(U), n, 1, "Ellipsoids3D:quaternions"))
        self._send("/world/material", idx, _mat3x3(Phi))
        labels = _strings(axis_labels(half), 3, "Arrows3D:labels")
        for ent, frames in (("/world/axes_C", R), ("/material/axes_G", U)):
            self._send(ent, idx, _fixed(principal_axes(frames, half).reshape(3 * n, 3), n, 3, "Arrows3D:vectors"), labels)
        self._send("/series/G", idx, _scalar_rows(symmetric_entries(G), 6))
        self._send("/series/C", idx, _scalar_rows(symmetric_entries(C), 6))
        casimir = y[_IDX["s1"]] ** 2 + y[_IDX["s2"]] ** 2 + y[_IDX["s3"]] ** 2
        series = {"lambda": lam, "mu": mu, "rho": rho, "theta": theta, "s3": y[_IDX["s3"]], "p_theta": y[_IDX["p_theta"]], "energy": block.energy, "casimir": casimir}
        if self._q0 is None:
            self._q0 = {name: float(series[name][0]) for name, _ in DRIFT_SERIES}
        for name, values in series.items():
            self._send(f"/series/{name}", idx, _scalars(values))
        for name, _ in DRIFT_SERIES:
            self._send(f"/series/drift/{name}", idx, _scalars(relative_drift(series[name], self._q0[name])))
        sel = np.flatnonzero(block.step % self.tensor_every == 0)
        if sel.size:
            rr = self._rr
            m = float(max(np.abs(G[sel]).max(), np.abs(C[sel]).max()))
            if m > self._range:  # a fixed, symmetric colour range ±r for both views (widened, never narrowed)
                self._range = nice_range(1.05 * m)
                comps = _static(("range", self._range), lambda: rr.Tensor.from_fields(value_range=[-self._range, self._range]))
                for ent in ("/tensors/G", "/tensors/C"):
                    self._static_log(ent, comps)
            tidx = idx if sel.size == n else _timelines(block.step[sel], block.t[sel])
            self._send("/tensors/G", tidx, self._tensor_column(G[sel]))
            self._send("/tensors/C", tidx, self._tensor_column(C[sel]))
            self._send("/tensors/numbers", tidx, _strings(tensor_text(block.t[sel], G[sel], C[sel], half[sel], self._range), 1, "TextDocument:text"))

    def _send_episode(self, block: _Block, *, actions, reward_terms, target, distance) -> None:
        """Actions, reward terms, target (series and outline) and distance of a block; a NaN is a step without that value."""
        if actions is not None:
            has = ~np.isnan(actions).any(axis=1)
            if has.any():
                k = actions.shape[1]
                names = self.action_names or (ACTION_NAMES if k == len(ACTION_NAMES) else tuple(f"a{i}" for i in range(k)))
                if len(names) != k:
                    raise ValueError(f"action_names: {len(names)} names for actions of size {k}")
                idx = self._rows(block, has)
                for i, name in enumerate(names):
                    self._series(f"/series/action/{_safe_name(name)}", idx, actions[has, i], group="action")
        for name in sorted(reward_terms, key=lambda n: (n == "total", n)):
            values = reward_terms[name]
            has = ~np.isnan(values)
            if has.any():
                self._series(f"/series/reward/{_safe_name(name)}", self._rows(block, has), values[has], group="reward")
        for name in TARGET_SERIES:
            values = target.get(name)
            if values is not None:
                has = ~np.isnan(values)
                if has.any():
                    self._series(f"/series/target/{name}", self._rows(block, has), values[has])
        if all(k in target for k in ("lambda", "mu", "rho")):
            d = np.stack([target["lambda"], target["mu"], target["rho"]], axis=1)
            has = ~np.isnan(d).any(axis=1)
            if has.any():  # R·diag(λ*, μ*, ϱ*): the target ellipse along the body's axes
                self._send("/world/target", self._rows(block, has), _mat3x3(block.rotations[has] * d[has][:, None, :]))
        if distance is not None:
            has = ~np.isnan(distance)
            if has.any():
                self._series("/series/distance", self._rows(block, has), distance[has])

    @staticmethod
    def _rows(block: _Block, has: np.ndarray) -> dict:
        """The timelines of the steps ``has`` of ``block`` (the block's own when it is all of them)."""
        if has.all():
            return block.index
        return _timelines(block.step[has], block.t[has])

    def _series(self, path: str, idx: dict, values: np.ndarray, *, group: str | None = None) -> None:
        if path not in self._styled:
            index = 0
            if group is not None:
                members = self._members[group]
                members.append(path)
                index = len(members) - 1
            self._style(path, index)
        self._send(path, idx, _scalars(values))

    def _tensor_column(self, M: np.ndarray):
        """A ``Tensor:data`` column of n 3×3 float64 tensors, built directly in Arrow.

        ``rr.Tensor.columns()`` cannot express a time series of tensors (ECOSYSTEM.md), so the
        ``TensorData`` struct (shape, names, dense-union buffer with the F64 arm) is assembled
        with pyarrow from the type rerun itself reports.
        """
        import pyarrow as pa

        rr = self._rr
        descriptor, typ = _tensor_type()
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

        column = rr.ComponentColumn(descriptor, _Batch())
        return column.component_descriptor(), column.as_arrow_array()

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


@functools.lru_cache(maxsize=1)
def _tensor_type() -> tuple:
    """(descriptor, Arrow type of one ``TensorData``) of rerun's ``Tensor:data`` (read from rerun's
    own tables: building a template tensor would import ``pyarrow.compute``, 45 ms)."""
    import rerun as rr
    from rerun.encodings.tensor_data import TensorDataBatch

    return rr.Tensor.descriptor_data(), TensorDataBatch._ARROW_DATATYPE


def warm_up() -> None:
    """Import rerun and build now what an env episode's recording needs first (the episode blueprint
    template, the Arrow column types), so that it does not wait for them (a
    :class:`~flatbody_env.recording.process.RecorderProcess` calls it while its caller works)."""
    _blueprint_template(True, None)
    _column_types()
    _tensor_type()


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


