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

Everything goes through rerun's public API: a :class:`rerun.RecordingStream` saved to the file with
the default blueprint (``save``), static parts with ``log(..., static=True)``, and the data
column-wise with ``send_columns``, one chunk per entity and block — a whole trajectory at once from
:func:`record_arrays`, ``block`` steps at a time from :meth:`Recorder.append` (the one per-step buffer,
which :class:`~flatbody_env.recording.wrapper.RerunRecorder` fills) or :meth:`Recorder.extend`. One
escape hatch, :func:`_matrix_column`, builds the two columns of 3×3 matrices in Arrow (see there why).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flatbody_env.physics import validation
from flatbody_env.physics.kinematics import cauchy_tensor, configuration, green_tensor, material_rotation
from flatbody_env.physics.state import STATE_NAMES
from flatbody_env.recording.geometry import (
    material_lines,
    principal_axes,
    quaternions_xyzw,
    relative_drift,
    symmetric_entries,
    unit_circle,
)
from flatbody_env.recording.layout import (
    ACTION_NAMES,
    AXIS_COLORS,
    DRIFT_SERIES,
    TARGET_SERIES,
    TENSOR_ENTRY_COLORS,
    axis_labels,
    blueprint,
    description_markdown,
    grow_axes,
    material_line_colors,
    rgba,
    series_axes,
    series_style,
    tensor_text,
    time_note,
    time_unit,
)

LABEL_CHAR = 0.059
"""The width of one character of an arrow's label, a fraction of the body's size (``extent``), as the views show it
at 1600 × 1000 (rerun draws labels at a fixed size in pixels)."""
LABEL_HALF_HEIGHT = 0.085
"""Half the height of a label's box, the same way."""
LABEL_DROP = LABEL_HALF_HEIGHT + 0.025
"""rerun draws a point's label under the point: the box's centre lies this far below it on screen (a fraction of
``extent``; in the top view, −y)."""
LABEL_MARGIN = 0.06
"""Room between an arrow's tip and the nearest edge of its label's box."""


def label_points(vectors: np.ndarray, frames: np.ndarray, labels: np.ndarray, extent: float) -> np.ndarray:
    """Where each arrow's label is logged (n, 3 arrows, 3) so that its box clears the arrow, the spokes and the rim.

    rerun draws a label as a box of fixed pixel size centred under its point (:data:`LABEL_DROP`). Seen down the
    lab's z axis (the top view) the box of an in-plane arrow (columns 0, 1 of ``frames``) must reach past the tip
    by half its width or half its height, whichever the arrow's direction meets first, plus a margin: its centre
    goes there and the point :data:`LABEL_DROP` above it. The normal (column 2) is labelled in the 3-D views, seen
    from above the plate, where it points up the screen (foreshortened to about 0.8): its point goes beyond the
    tip by the box's whole height, so that the box hangs above the tip."""
    vectors = np.asarray(vectors, dtype=np.float64)
    frames = np.asarray(frames, dtype=np.float64)
    n = frames.shape[0]
    widths = np.vectorize(len)(np.asarray(labels, dtype=object).reshape(n, 3)).astype(float)
    half_w = (0.5 * widths * LABEL_CHAR + 0.05) * extent
    half_h = LABEL_HALF_HEIGHT * extent
    out = np.empty((n, 3, 3))
    for col in range(2):
        d = frames[:, :, col]  # the axis in the lab (unit); its picture in the top view is (x, y)
        flat = np.hypot(d[:, 0], d[:, 1])
        ux = np.abs(d[:, 0]) / np.maximum(flat, 1e-12)
        uy = np.abs(d[:, 1]) / np.maximum(flat, 1e-12)
        reach = np.minimum(half_w[:, col] / np.maximum(ux, 1e-12), half_h / np.maximum(uy, 1e-12))
        along = np.minimum((reach + LABEL_MARGIN * extent) / np.maximum(flat, 0.2), 1.5 * extent)
        out[:, col] = vectors[:, col] + along[:, None] * d
        out[:, col, 1] += LABEL_DROP * extent  # the box hangs under its point
    up = (2.0 * half_h + LABEL_MARGIN * extent) / 0.8
    out[:, 2] = vectors[:, 2] + up * frames[:, :, 2]
    return out


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
    "/world/labels/in_plane",
    "/world/labels/normal",
    "/material/reference",
    "/material/G_ellipsoid",
    "/material/axes_G",
    "/material/labels",
    "/tensors/numbers",
    "/series/G",
    "/series/C",
    *(f"/series/{name}" for name in BODY_SERIES),
)
"""Entity paths present in every recording."""

FREE_ENTITIES = tuple(f"/series/drift/{name}" for name, _ in DRIFT_SERIES)
"""Entity paths a free scene adds: the relative drift of its conserved quantities."""

EPISODE_ENTITIES = (
    "/series/distance",
    "/world/target",
    "/world/target/outline",
    "/series/balance/delta_energy",
    *(f"/series/target/{n}" for n in TARGET_SERIES),
)
"""Entity paths an env episode adds (besides ``/series/action/…``, ``/series/reward/…``, the control's
power and work ``/series/power``, ``/series/balance/work`` when the env tells its controls, the
success tolerance ``/series/distance_tolerance`` when it has one, and ``/events``)."""

_IDX = {name: i for i, name in enumerate(STATE_NAMES)}


@dataclass(frozen=True, kw_only=True)
class _Block:
    """Validated arrays for one block of n steps."""

    step: np.ndarray
    t: np.ndarray
    states: np.ndarray
    rotations: np.ndarray
    energy: np.ndarray
    index: list
    """The block's timelines (``step``, ``sim_time``) as ``rr.TimeColumn``, shared by its entities."""


def _check_finite(name: str, a: np.ndarray) -> None:
    if not np.all(np.isfinite(a)):
        bad = int(np.argmax(~np.isfinite(a).reshape(a.shape[0], -1).all(axis=1))) if a.ndim else 0
        raise validation.refusal(name, f"be finite (first non-finite entry at step index {bad})")


def _as_block(t, states, rotations, *, energy, step, scale: float = 1.0) -> _Block:
    t = np.asarray(t, dtype=np.float64).ravel()
    n = t.size
    if n == 0:
        raise ValueError("t: must hold at least one time")
    _check_finite("t", t)
    if np.any(np.diff(t) < 0):
        raise validation.refusal("t", "be non-decreasing")
    states = np.asarray(states, dtype=np.float64)
    if states.shape != (len(STATE_NAMES), n):
        raise ValueError(f"states: expected shape ({len(STATE_NAMES)}, {n}) (state × step), got {states.shape}")
    _check_finite("states", states.T)
    for name in ("lambda", "mu", "rho"):
        if np.any(states[_IDX[name]] <= 0):
            raise validation.refusal("states", f"have {name} > 0 (allowed range (0, inf))")
    rotations = np.asarray(rotations, dtype=np.float64)
    if rotations.shape != (n, 3, 3):
        raise ValueError(f"rotations: expected shape ({n}, 3, 3), got {rotations.shape}")
    _check_finite("rotations", rotations)
    ortho = np.max(np.abs(rotations @ np.swapaxes(rotations, 1, 2) - np.eye(3)))
    if ortho > 1e-6 or np.any(np.linalg.det(rotations) <= 0):
        raise validation.refusal(
            "rotations", f"be rotation matrices (RRᵀ = I to 1e-6, det > 0); |RRᵀ − I| = {ortho:.2g}"
        )
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
    return _Block(
        step=step_arr, t=t, states=states, rotations=rotations, energy=energy, index=_timelines(step_arr, t, scale)
    )


def _optional_column(name: str, values, n: int, width: int | None = None) -> np.ndarray:
    """An optional per-step column of :meth:`Recorder.extend`: NaN marks a step without a value,
    ±inf is refused (a value that cannot be drawn is not silently dropped)."""
    a = np.asarray(values, dtype=np.float64)
    shape = (n,) if width is None else (n, width)
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    if np.any(np.isinf(a)):
        raise validation.refusal(name, "be finite or NaN (NaN marks a step without a value)")
    return a


def _safe_name(name: str) -> str:
    out = "".join(c if (c.isalnum() or c in "_-") else "_" for c in str(name))
    return out or "_"


def _timelines(step: np.ndarray, t: np.ndarray, scale: float = 1.0) -> list:
    """The ``step`` and ``sim_time`` columns; ``sim_time`` is the model time ``t`` as a duration of ``scale`` seconds
    per unit (:func:`~flatbody_env.recording.layout.time_unit`), in integer nanoseconds."""
    import rerun as rr

    ns = np.round(np.asarray(t, dtype=np.float64) * (1e9 * scale)).astype(np.int64).astype("timedelta64[ns]")
    return [rr.TimeColumn("step", sequence=np.asarray(step, dtype=np.int64)), rr.TimeColumn("sim_time", duration=ns)]


# -- the one per-step buffer -----------------------------------------------------------------------------
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


def _same(a: Any, b: dict) -> bool:
    """``a == b``, False where the comparison has no single answer (e.g. array entries)."""
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


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
        if (
            total is None and r and d is not None and self._last is not None and _same(d, self._last)
        ):  # the same row again: repeat it
            for col in cols.values():
                col.append(col[-1])
            self.rows = r + 1
            return
        self._last = (
            dict(d) if isinstance(d, dict) and total is None else None
        )  # a copy: an env may change its dict in place
        added = 0
        items = list(d.items()) if isinstance(d, Mapping) else []
        if total is not None:
            items.append(("total", total))
        for k, v in items:
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
        if added != len(cols):
            for col in cols.values():
                if len(col) == r:
                    col.append(math.nan)
        self.rows = r + 1

    def arrays(self) -> dict[str, np.ndarray]:
        """name → the column as a float array."""
        return {k: np.array(v, dtype=np.float64) for k, v in self.cols.items()}


class _Steps:
    """The steps :meth:`Recorder.append` buffered and has not sent yet, in columns."""

    __slots__ = ("step", "t", "y", "R", "energy", "actions", "controls", "terms", "target", "distance")

    def __init__(self) -> None:
        self.step: list[int] = []
        self.t: list[float] = []
        self.y: list[np.ndarray] = []
        self.R: list[np.ndarray] = []
        self.energy: list[float] = []
        self.actions: list[np.ndarray | None] = []
        self.controls: list[np.ndarray | None] = []
        self.terms = _Columns()
        self.target = _Columns()
        self.distance: list[float] = []


# -- rerun ----------------------------------------------------------------------------------------------
_MATRIX_TYPES: dict[str, tuple] = {}


def _matrix_column(component: str, M: np.ndarray):
    """The writer's one escape hatch from rerun's archetype columns: a column of one 3×3 matrix per
    step, ``"Tensor:data"`` (G, C) or ``"Transform3D:mat3x3"`` (Φ, the target ellipse), built in Arrow.

    rerun 0.41 has no public way to send these fast: ``rr.Tensor.columns()`` cannot express a time
    series of tensors (a ``TensorDataBatch`` holds one tensor: "Tensors do not support batches"),
    and ``rr.Transform3D.columns(mat3x3=...)`` converts the matrices one at a time in Python. So the
    Arrow array is assembled here in the layout of rerun's own one-element batches — ``TensorData``:
    shape [3, 3], names ``row``/``col`` and a dense union whose ``F64`` arm holds the nine entries;
    ``Mat3x3``: nine float32, column-major — with the Arrow type those public batches report, and it
    goes out through the public ``rr.ComponentColumn`` (any ``rerun.ComponentBatchLike``). What
    depends on rerun's layout is this function only; the values read back from a file equal the
    ones sent (``tests/recording/test_writer.py``, against the pinned rerun).
    """
    import pyarrow as pa
    import rerun as rr

    if component not in _MATRIX_TYPES:
        one = (
            rr.encodings.TensorDataBatch(np.zeros((3, 3)))
            if component == "Tensor:data"
            else rr.components.TransformMat3x3Batch(np.eye(3))
        )
        descriptor = rr.Tensor.descriptor_data() if component == "Tensor:data" else rr.Transform3D.descriptor_mat3x3()
        _MATRIX_TYPES[component] = (descriptor, one.as_arrow_array().type)
    descriptor, typ = _MATRIX_TYPES[component]
    M = np.asarray(M, dtype=np.float64)
    n = M.shape[0]
    if component == "Transform3D:mat3x3":
        array = pa.FixedSizeListArray.from_arrays(pa.array(np.swapaxes(M, 1, 2).astype(np.float32).ravel()), type=typ)
    else:
        pair = pa.array(np.arange(0, 2 * n + 1, 2, dtype=np.int32))
        shape = pa.ListArray.from_arrays(
            pair, pa.array(np.full(2 * n, 3, dtype=np.uint64)), type=typ.field("shape").type
        )
        names = pa.ListArray.from_arrays(
            pair, pa.array(["row", "col"] * n, type=pa.string()), type=typ.field("names").type
        )
        union = typ.field("buffer").type
        arms = [f.name for f in union]
        children = [pa.array([], type=f.type) for f in union]
        children[arms.index("F64")] = pa.ListArray.from_arrays(
            pa.array(np.arange(0, 9 * n + 1, 9, dtype=np.int32)),
            pa.array(np.ascontiguousarray(M).ravel()),
            type=union.field(arms.index("F64")).type,
        )
        codes = np.full(n, union.type_codes[arms.index("F64")], dtype=np.int8)
        buffer = pa.Array.from_buffers(
            union,
            n,
            [None, pa.py_buffer(codes.tobytes()), pa.py_buffer(np.arange(n, dtype=np.int32).tobytes())],
            children=children,
        )
        array = pa.StructArray.from_arrays([shape, names, buffer], fields=list(typ))

    class _Batch:  # the rerun.ComponentBatchLike protocol
        def as_arrow_array(self):
            return array

        def component_descriptor(self):
            return descriptor

    return rr.ComponentColumn(descriptor, _Batch())


_STATIC: dict[tuple, Any] = {}


def _static(key: tuple, build) -> Any:
    """A static archetype that does not change between files, built once per process."""
    arch = _STATIC.get(key)
    if arch is None:
        arch = _STATIC[key] = build()
    return arch


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
    success_tolerance : float, optional
        Episodes: the distance at or below which the target counts as reached, drawn as a line on the
        distance plot.

    Use as a context manager or call :meth:`close`; the file is complete only after that.

    The file is opened (``RecordingStream.save``) when the first block is sent; rerun keeps what was
    logged before in memory and writes it then. When the whole recording is one block — a free scene
    from :func:`record_arrays`, an env episode of up to ``block`` steps — the default blueprint is
    built from the values logged (fixed axes, round-off drawn flat, the whole run on every time axis:
    :func:`flatbody_env.recording.layout.blueprint`); a recording sent in several blocks gets axes that
    follow the data.
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
        success_tolerance: float | None = None,
        t_end: float | None = None,
    ) -> None:
        import rerun as rr

        for name, value in (("block", block), ("tensor_every", tensor_every), ("spokes", spokes)):
            validation.integer(name, value, low=1)
        validation.number("extent", extent, positive=True)
        self.path = Path(path)
        if self.path.suffix != ".rrd":
            raise ValueError(f"path: a rerun recording file must end in .rrd, got {str(path)!r}")
        self.body = body
        self.block = int(block)
        self.tensor_every = int(tensor_every)
        self.action_names = tuple(action_names) if action_names is not None else None
        self.episode = bool(episode)
        self._buf = _Steps()
        self._closed = False
        self._steps = 0
        self._styled: dict[str, int] = {}
        self._members: dict[str, list[str]] = {"action": [], "reward": []}
        self._q0: dict[str, float] | None = None
        self._extent = float(extent)
        self._tolerance = None if success_tolerance is None else float(success_tolerance)
        self._scale, self._unit = time_unit(t_end) if t_end is not None and math.isfinite(t_end) else (1.0, "s")
        self._title = title
        self._description = description
        self._ranges: dict[str, tuple[float, float, int]] = {}
        self._t_range: tuple[float, float] | None = None
        self._blocks = 0
        self._layout_key: list | None = None  # the axes of the last blueprint sent after a later block (_update_layout)
        self._saved = False
        self._sink = None  # the file: flatbody_env.recording.sink.FileSink, opened with the first block
        self._work = 0.0
        self._last: tuple[float, np.ndarray] | None = (
            None  # (t, state) of the last step sent: the start of the next step's work
        )
        self._rr = rr
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id or str(uuid.uuid4()), send_properties=True)
        if not self.rec.is_enabled():
            raise ValueError(
                "RERUN: rerun logging is disabled by the environment variable RERUN (e.g. RERUN=off); unset it to record"
            )
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec.send_recording_name(title)
        self.rec.send_property("time", rr.AnyValues(seconds_per_unit=self._scale, unit=self._unit))
        self._log_static(title, description, int(spokes))

    # -- static parts ------------------------------------------------------------------------------
    def _static_log(self, path: str, archetype) -> None:
        self.rec.log(path, archetype, static=True, strict=True)

    def _log_static(self, title: str, description: str, spokes: int) -> None:
        rr = self._rr
        self._describe()
        self._static_log(
            "/tensors/numbers",
            _static(("numbers",), lambda: rr.TextDocument.from_fields(media_type=rr.MediaType.MARKDOWN)),
        )
        for ent in ("/world", "/material"):
            self._static_log(ent, rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        lines = _static(
            ("lines", spokes),
            lambda: rr.LineStrips3D(material_lines(spokes), colors=material_line_colors(spokes), radii=0.008),
        )
        self._static_log("/world/material/lines", lines)
        self._static_log("/material/reference", lines)
        ellipsoid = _static(
            ("ellipsoid",),
            lambda: rr.Ellipsoids3D.from_fields(
                colors=[rgba((150, 165, 195))], fill_mode=rr.components.FillMode.MajorWireframe, line_radii=0.006
            ),
        )
        self._static_log("/world/body", ellipsoid)
        self._static_log("/material/G_ellipsoid", ellipsoid)
        arrows = _static(
            ("arrows",), lambda: rr.Arrows3D.from_fields(colors=AXIS_COLORS, radii=0.02, show_labels=False)
        )
        for ent in ("/world/axes_C", "/material/axes_G"):
            self._static_log(ent, arrows)
        for ent, colors in (
            ("/world/labels/in_plane", AXIS_COLORS[:2]),
            ("/world/labels/normal", AXIS_COLORS[2:]),
            ("/material/labels", AXIS_COLORS),
        ):
            self._static_log(
                ent,
                _static(
                    ("labels", ent),
                    lambda colors=colors: rr.Points3D.from_fields(colors=colors, radii=0.012, show_labels=True),
                ),
            )
        for name in BODY_SERIES:
            self._style(f"/series/{name}")
        if not self.episode:
            for name, _ in DRIFT_SERIES:
                self._style(f"/series/drift/{name}")
        for sym in ("G", "C"):
            entries = _static(
                ("entries", sym),
                lambda sym=sym: rr.SeriesLines(
                    names=[f"{sym}{ij}" for ij in ("11", "22", "33", "12", "13", "23")], colors=TENSOR_ENTRY_COLORS
                ),
            )
            self._static_log(f"/series/{sym}", entries)
        if self.episode:
            from flatbody_env.env.rendering import COLORS

            self._static_log(
                "/world/target/outline",
                _static(
                    ("outline",), lambda: rr.LineStrips3D([unit_circle()], colors=[rgba(COLORS["target"])], radii=0.012)
                ),
            )
            self._style("/series/distance")
            self._style("/series/balance/delta_energy")
            for name in TARGET_SERIES:
                self._style(f"/series/target/{name}")

    def _describe(self, outcome: str | None = None) -> None:
        rr = self._rr
        text = description_markdown(
            self._title,
            self.body,
            self._description,
            episode=self.episode,
            outcome=outcome,
            time_note=time_note(self._scale, self._unit),
        )
        self._static_log("/description", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN))

    def set_outcome(self, outcome: str, *, short: str | None = None) -> None:
        """An episode's outcome, once it is known: first in the description (a static log replaces the one logged at
        the start) and, with ``short``, after the recording's name (``flatbody episode 0 — MISSED``)."""
        self._describe(outcome)
        if short:
            self.rec.send_recording_name(f"{self._title} — {short}")

    def _style(self, path: str, index: int = 0) -> None:
        if path not in self._styled:
            rr = self._rr

            def build():
                name, color, width = series_style(path, index)
                return rr.SeriesLines(names=name, colors=[color], widths=width)

            self._static_log(path, _static(("style", path, index), build))
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
        reward: float | None = None,
        target: Mapping[str, float] | None = None,
        distance: float | None = None,
        control: np.ndarray | Sequence[float] | None = None,
    ) -> None:
        """Buffer one step (numbers and array copies, in columns); a full buffer (``block`` steps) is
        sent as one block. The one per-step buffer: :class:`~flatbody_env.recording.wrapper.RerunRecorder`
        feeds its episodes through it.

        ``state`` is a dict of the eleven names or an array in :data:`STATE_NAMES` order;
        ``energy`` defaults to H(state) (eq. (41) of [1]); ``step`` to the running count.
        An env episode's (``episode=True``) ``action``, ``reward_terms`` (their numeric entries;
        ``reward`` is plotted as ``total`` unless the terms have one), ``target`` (its
        :data:`~flatbody_env.recording.layout.TARGET_SERIES` entries) and ``distance``: a value that
        is missing or not finite is not drawn at that step, a non-finite target is an error; a step
        whose state or R is not finite is noted on ``/events`` and not drawn (:meth:`flush`).
        ``control`` is the physical u = (τ₁, τ₂, τ₃, f_ϱ) that ``action`` applied over the step that led
        here: with it the recording draws the control's power and work (:mod:`flatbody_env.recording.work`).
        """
        if self._closed:
            raise ValueError("recorder: already closed")
        if isinstance(state, Mapping):
            missing = [k for k in STATE_NAMES if k not in state]
            if missing:
                raise ValueError(f"state: missing entries {', '.join(missing)}")
            y = np.array([float(state[k]) for k in STATE_NAMES])
        else:
            y = np.array(state, dtype=np.float64).ravel()
            if y.shape != (len(STATE_NAMES),):
                raise ValueError(f"state: expected {len(STATE_NAMES)} entries, got shape {y.shape}")
        if (
            action is not None or reward_terms or reward is not None or target or distance is not None
        ) and not self.episode:
            raise ValueError(
                "recorder: actions, reward terms, target and distance belong to an episode (Recorder(..., episode=True))"
            )
        b = self._buf
        b.t.append(float(t))
        b.y.append(y)
        b.R.append(np.array(rotation, dtype=np.float64))
        b.energy.append(math.nan if energy is None else float(energy))
        b.step.append(self._steps if step is None else int(step))
        if self.episode:
            b.actions.append(None if action is None else np.array(action, dtype=np.float64).ravel())
            b.controls.append(None if control is None else np.array(control, dtype=np.float64).ravel())
            b.terms.add(reward_terms, total=None if reward is None else float(reward))
            b.target.add(target, names=TARGET_SERIES)
            d = None if distance is None else _number(distance)
            b.distance.append(d if d is not None and math.isfinite(d) else math.nan)
        self._steps += 1
        if len(b.t) >= self.block:
            self.flush()

    def flush(self, *, final: bool = False) -> None:
        """Send the steps buffered by :meth:`append` as one block (no-op when empty). In an episode a
        step whose state or R is not finite is noted on ``/events`` and not drawn. ``final``: no step
        follows (:meth:`close`), so a recording of one block gets its blueprint from its values."""
        b = self._buf
        n = len(b.t)
        if not n:
            return
        self._buf = _Steps()
        t, Y, R, step = np.array(b.t), np.stack(b.y, axis=1), np.stack(b.R), np.array(b.step, dtype=np.int64)
        energy = np.array(b.energy)
        episode = {}
        if self.episode:
            keep = np.isfinite(Y).all(axis=0) & np.isfinite(R.reshape(n, 9)).all(axis=1)
            for i in np.flatnonzero(~keep):
                self.note(
                    "non-finite state (integration failure): step not drawn",
                    step=step[i],
                    t=t[i] if math.isfinite(t[i]) else 0.0,
                )
            if not keep.any():
                return
            actions = None
            rows = [i for i, a in enumerate(b.actions) if a is not None and keep[i]]
            if rows:
                sizes = {b.actions[i].size for i in rows}
                if len(sizes) != 1:
                    raise ValueError(f"action: sizes differ within an episode ({sorted(sizes)})")
                given = np.stack([b.actions[i] for i in rows])
                given[~np.isfinite(given).all(axis=1)] = np.nan  # not drawn
                actions = np.full((n, given.shape[1]), np.nan)
                actions[rows] = given
                actions = actions[keep]
            target = {k: v[keep] for k, v in b.target.arrays().items()}
            for name, values in target.items():
                if not np.all(np.isfinite(values[~np.isnan(values)])):
                    raise validation.refusal(f"target[{name!r}]", "be finite")
            terms = {k: np.where(np.isfinite(v), v, np.nan)[keep] for k, v in b.terms.arrays().items()}
            controls = None
            if any(c is not None for c in b.controls):
                controls = np.full((n, 4), np.nan)
                for i, c in enumerate(b.controls):
                    if c is not None and c.size == 4:
                        controls[i] = c
                controls = controls[keep]
            episode = {
                "actions": actions,
                "reward_terms": terms or None,
                "target": target or None,
                "distance": np.array(b.distance)[keep],
                "controls": controls,
            }
            t, Y, R, step, energy = t[keep], Y[:, keep], R[keep], step[keep], energy[keep]
        missing = np.isnan(energy)
        if missing.any():
            from flatbody_env.physics.hamiltonian import hamiltonian_series

            _check_finite("states", Y.T)
            energy[missing] = hamiltonian_series(Y[:, missing], self.body)
        self._extend(t, Y, R, step=step, energy=energy, **episode)
        if not final and not self._saved:
            self._save()
        if self._sink is not None:
            self._sink.check()  # a failed write (disk full) stops the run here: OutputError, one line

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
        controls=None,
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
        controls : array (n, 4), optional
            Episodes: u = (τ₁, τ₂, τ₃, f_ϱ) applied over the step that led to each step (NaN: none).

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
        self._extend(
            t,
            states,
            rotations,
            step=step,
            energy=energy,
            actions=actions,
            reward_terms=reward_terms,
            target=target,
            distance=distance,
            controls=controls,
        )
        if not self._saved:
            self._save()

    def _extend(
        self,
        t,
        states,
        rotations,
        *,
        step,
        energy,
        actions=None,
        reward_terms=None,
        target=None,
        distance=None,
        controls=None,
    ) -> None:
        if (
            actions is not None or reward_terms or target or distance is not None or controls is not None
        ) and not self.episode:
            raise ValueError(
                "recorder: actions, reward terms, target and distance belong to an episode (Recorder(..., episode=True))"
            )
        if energy is None:
            from flatbody_env.physics.hamiltonian import hamiltonian_series

            Y = np.asarray(states, dtype=np.float64)
            if Y.ndim != 2 or Y.shape[0] != len(STATE_NAMES):
                raise ValueError(f"states: expected shape ({len(STATE_NAMES)}, n), got {Y.shape}")
            _check_finite("states", Y.T)
            energy = hamiltonian_series(Y, self.body)
        block = _as_block(t, states, rotations, energy=energy, step=step, scale=self._scale)
        n = block.t.size
        episode = None
        if self.episode:
            episode = {
                "actions": None if actions is None else _optional_column("actions", actions, n, np.shape(actions)[-1]),
                "reward_terms": {
                    str(k): _optional_column(f"reward_terms[{k!r}]", v, n) for k, v in (reward_terms or {}).items()
                },
                "target": {
                    k: _optional_column(f"target[{k!r}]", target[k], n) for k in TARGET_SERIES if target and k in target
                },
                "distance": None if distance is None else _optional_column("distance", distance, n),
                "controls": None if controls is None else _optional_column("controls", controls, n, 4),
            }
        self._send_block(block)
        if episode is not None:
            self._send_episode(block, **episode)
        self._update_layout()

    def note(self, text: str, *, step: int, t: float, level: str = "WARN") -> None:
        """Log one event (e.g. an integrator failure) as a ``TextLog`` on ``/events``."""
        rr = self._rr
        self.rec.set_time("step", sequence=int(step))
        self.rec.set_time("sim_time", duration=np.timedelta64(int(round(float(t) * 1e9 * self._scale)), "ns"))
        self.rec.log("/events", rr.TextLog(str(text), level=level), strict=True)

    def _send(self, path: str, timelines: list, columns) -> None:
        self.rec.send_columns(path, indexes=timelines, columns=columns, strict=True)

    def _scalars(self, values: np.ndarray, per: int = 1) -> list:
        """A ``Scalars`` column of rows of ``per`` values each."""
        rr = self._rr
        values = np.ascontiguousarray(values, dtype=np.float64).ravel()
        offsets = np.arange(0, values.size + 1, per, dtype=np.int32)
        return [rr.ComponentColumn(rr.Scalars.descriptor_scalars(), rr.components.ScalarBatch(values), offsets=offsets)]

    def _update_layout(self) -> None:
        """A recording of several blocks: its file was opened with the first block, before the values of
        the later ones were known. After each later block, send a default blueprint built from all values
        logged so far (the flat rule and fixed axes of a one-block recording, the whole run on the time
        axes) — only when the axes sent last no longer hold the data, with room to grow
        (:func:`~flatbody_env.recording.layout.grow_axes`), so a long recording sends a few."""
        if not self._saved or self._blocks < 2:
            return
        needed = series_axes(episode=self.episode, ranges=self._ranges, t_range=self._t_range)
        axes = grow_axes(needed, self._layout_key, self._t_range[0])
        if axes is None:
            return
        self._layout_key = axes
        bp = blueprint(
            episode=self.episode,
            extent=self._extent,
            ranges=self._ranges,
            t_range=self._t_range,
            axes=axes,
            time_scale=self._scale,
        )
        self.rec.send_blueprint(bp, make_active=True, make_default=True)

    def _note(self, path: str, values: np.ndarray, per: int = 1) -> None:
        """Keep the range of what ``path`` shows (the blueprint of a one-block recording is built from it)."""
        v = np.asarray(values, dtype=np.float64)
        v = v[np.isfinite(v)]
        if v.size:
            lo, hi = float(v.min()), float(v.max())
            old = self._ranges.get(path)
            self._ranges[path] = (lo, hi, per) if old is None else (min(old[0], lo), max(old[1], hi), per)

    def _save(self, *, final: bool = False) -> None:
        """Open the file with the default blueprint: built from the logged values when all of them
        are one block (``final``: no block follows; see the class docstring), else with axes that
        follow the data."""
        one = final and self._blocks == 1
        bp = blueprint(
            episode=self.episode,
            extent=self._extent,
            ranges=self._ranges if one else None,
            t_range=self._t_range if one else None,
            time_scale=self._scale,
        )
        from flatbody_env.recording.sink import FileSink

        # rerun's file sink writes into a pipe that our thread copies to a temporary file, renamed at close:
        # a failed write (disk full) is an OSError in our code, never a hang in rerun's flush (see sink.py)
        self._sink = FileSink(self.rec, self.path, bp)
        self._saved = True

    def _send_block(self, block: _Block) -> None:
        """Log a whole block of steps column-wise (one chunk per entity)."""
        rr = self._rr
        n = block.t.size
        self._blocks += 1
        t0 = float(block.t[0]) if self._t_range is None else self._t_range[0]
        self._t_range = (t0, float(block.t[-1]))
        y = block.states
        lam, mu, rho, theta = (y[_IDX[k]] for k in ("lambda", "mu", "rho", "theta"))
        R = block.rotations
        U = material_rotation(theta)
        half = np.stack([lam, mu, rho], axis=1)
        G = green_tensor(lam, mu, rho, theta)
        C = cauchy_tensor(lam, mu, rho, R)
        Phi = configuration(lam, mu, rho, theta, R)
        idx = block.index
        self._send("/world/body", idx, rr.Ellipsoids3D.columns(half_sizes=half, quaternions=quaternions_xyzw(R)))
        self._send(
            "/material/G_ellipsoid", idx, rr.Ellipsoids3D.columns(half_sizes=half, quaternions=quaternions_xyzw(U))
        )
        self._send("/world/material", idx, [_matrix_column("Transform3D:mat3x3", Phi)])
        labels = np.array(axis_labels(half), dtype=object).reshape(n, 3)
        for ent, frames in (("/world/axes_C", R), ("/material/axes_G", U)):
            vectors = principal_axes(frames, half)  # (n, 3 arrows, 3)
            self._send(ent, idx, rr.Arrows3D.columns(vectors=vectors.reshape(3 * n, 3)).partition(np.full(n, 3)))
            # labels beyond the arrows' tips, their boxes clear of the arrows, the spokes, the fibre and each other
            tips = label_points(vectors, frames, labels, self._extent)
            if ent == "/world/axes_C":
                self._send(
                    "/world/labels/in_plane",
                    idx,
                    rr.Points3D.columns(
                        positions=tips[:, :2].reshape(2 * n, 3), labels=labels[:, :2].ravel().tolist()
                    ).partition(np.full(n, 2)),
                )
                self._send(
                    "/world/labels/normal", idx, rr.Points3D.columns(positions=tips[:, 2], labels=labels[:, 2].tolist())
                )
            else:
                self._send(
                    "/material/labels",
                    idx,
                    rr.Points3D.columns(positions=tips.reshape(3 * n, 3), labels=labels.ravel().tolist()).partition(
                        np.full(n, 3)
                    ),
                )
        for sym, M in (("G", G), ("C", C)):
            entries = symmetric_entries(M)
            self._send(f"/series/{sym}", idx, self._scalars(entries, 6))
            self._note(f"/series/{sym}", entries, 6)
        casimir = y[_IDX["s1"]] ** 2 + y[_IDX["s2"]] ** 2 + y[_IDX["s3"]] ** 2
        series = {
            "lambda": lam,
            "mu": mu,
            "rho": rho,
            "theta": theta,
            "s3": y[_IDX["s3"]],
            "p_theta": y[_IDX["p_theta"]],
            "energy": block.energy,
            "casimir": casimir,
        }
        if self._q0 is None:
            self._q0 = {name: float(series[name][0]) for name in ("energy", "casimir", "p_theta")}
        for name, values in series.items():
            self._send(f"/series/{name}", idx, self._scalars(values))
            self._note(f"/series/{name}", values)
        if not self.episode:  # under control H and |s|² change on purpose: episodes draw the control's work instead
            for name, _ in DRIFT_SERIES:
                drift = relative_drift(series[name], self._q0[name])
                self._send(f"/series/drift/{name}", idx, self._scalars(drift))
                self._note(f"/series/drift/{name}", drift)
        sel = np.flatnonzero(block.step % self.tensor_every == 0)
        if sel.size:
            tidx = idx if sel.size == n else _timelines(block.step[sel], block.t[sel], self._scale)
            self._send(
                "/tensors/numbers",
                tidx,
                rr.TextDocument.columns(text=tensor_text(block.t[sel], G[sel], C[sel], half[sel])),
            )

    def _send_episode(self, block: _Block, *, actions, reward_terms, target, distance, controls=None) -> None:
        """Actions, reward terms, target (series and outline), distance and the control's power and
        work of a block; a NaN is a step without that value."""
        if actions is not None:
            has = ~np.isnan(actions).any(axis=1)
            if has.any():
                k = actions.shape[1]
                names = self.action_names or (
                    ACTION_NAMES if k == len(ACTION_NAMES) else tuple(f"a{i}" for i in range(k))
                )
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
                self._send(
                    "/world/target",
                    self._rows(block, has),
                    [_matrix_column("Transform3D:mat3x3", block.rotations[has] * d[has][:, None, :])],
                )
        if distance is not None:
            has = ~np.isnan(distance)
            if has.any():
                self._series("/series/distance", self._rows(block, has), distance[has])
                if self._tolerance is not None:
                    self._series(
                        "/series/distance_tolerance", self._rows(block, has), np.full(int(has.sum()), self._tolerance)
                    )
        dH = block.energy - self._q0["energy"]
        self._series("/series/balance/delta_energy", block.index, dH)
        if controls is not None:  # the work of the control, step by step (flatbody_env.recording.work)
            from flatbody_env.recording.work import step_work

            n = block.t.size
            t_prev = np.concatenate([[np.nan if self._last is None else self._last[0]], block.t[:-1]])
            y_prev = np.concatenate(
                [(np.full((11, 1), np.nan) if self._last is None else self._last[1][:, None]), block.states[:, :-1]],
                axis=1,
            )
            has = ~np.isnan(controls).any(axis=1) & np.isfinite(t_prev)
            dW = np.zeros(n)
            if has.any():
                dW[has] = step_work(
                    t_prev[has], y_prev[:, has], block.t[has], block.states[:, has], controls[has], self.body
                )
            W = self._work + np.cumsum(dW)
            self._work = float(W[-1])
            self._series("/series/balance/work", block.index, W)
            self._series("/series/residual", block.index, dH - W)  # the balance's check, on its own scale
            if has.any():
                h = block.t[has] - t_prev[has]
                self._series(
                    "/series/power", self._rows(block, has), np.where(h > 0, dW[has] / np.where(h > 0, h, 1.0), 0.0)
                )
        self._last = (float(block.t[-1]), block.states[:, -1].copy())

    def _rows(self, block: _Block, has: np.ndarray) -> list:
        """The timelines of the steps ``has`` of ``block`` (the block's own when it is all of them)."""
        if has.all():
            return block.index
        return _timelines(block.step[has], block.t[has], self._scale)

    def _series(self, path: str, idx: list, values: np.ndarray, *, group: str | None = None) -> None:
        if path not in self._styled:
            index = 0
            if group is not None:
                members = self._members[group]
                members.append(path)
                index = len(members) - 1
            self._style(path, index)
        self._send(path, idx, self._scalars(values))
        self._note(path, values)

    # -- finishing ---------------------------------------------------------------------------------
    @property
    def steps(self) -> int:
        """Steps appended so far."""
        return self._steps

    def close(self) -> Path:
        """Flush, write the footer and release the file; returns the path. Idempotent."""
        if not self._closed:
            try:
                self.flush(final=True)
                if not self._saved:
                    self._save(final=True)
            except BaseException:
                self._closed = True
                if self._sink is not None:
                    self._sink.abandon()  # the temporary file is removed; rerun is stopped
                else:
                    self.rec.disconnect()
                raise
            self._closed = True
            if self._sink is not None:
                self._sink.close()  # footer, copy, rename: OutputError (one line) if a write failed
            else:
                self.rec.disconnect()
        return self.path

    def __enter__(self) -> Recorder:
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
    t = np.asarray(t, dtype=np.float64).ravel()
    t_end = float(np.max(np.abs(t))) if t.size and np.all(np.isfinite(t)) else None
    block = _as_block(t, Y, rotations, energy=energy, step=step, scale=1.0 if t_end is None else time_unit(t_end)[0])
    extent = float(max(Y[_IDX["lambda"]].max(), Y[_IDX["mu"]].max(), Y[_IDX["rho"]].max()))
    with Recorder(
        path,
        body,
        title=title,
        description=description,
        tensor_every=tensor_every,
        recording_id=recording_id,
        extent=extent,
        t_end=t_end,
    ) as rec:
        rec._send_block(block)
    return Path(path)


def record_trajectory(
    traj,
    body,
    path: str | Path,
    *,
    title: str | None = None,
    description: str = "",
    tensor_every: int = 1,
    recording_id: str | None = None,
) -> Path:
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
