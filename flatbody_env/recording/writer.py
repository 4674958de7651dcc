"""rerun recordings (``.rrd``) of the flat body for offline playback — the project's only rerun module.

rerun is imported lazily, inside functions: nothing else in the project needs it, and importing
this module costs nothing. Every recording goes to an explicit :class:`rerun.RecordingStream`
saved to a file (no viewer, no network); the file is complete — footer written — when
:func:`record_arrays` / :func:`record_trajectory` return or :meth:`Recorder.close` does.

What is logged (entity paths; ``step`` and ``sim_time`` timelines on everything temporal)
-----------------------------------------------------------------------------------------
=====================================  =====================================================
entity                                 content
=====================================  =====================================================
``/description``                       markdown: the model, the scene, what each panel shows
``/world/body``                        ``Ellipsoids3D``: half-sizes (λ, μ, ϱ), orientation R
                                       — the body R·D·(unit ball), eqs. (23)–(24) of [1]
``/world/material``                    ``Transform3D(mat3x3=Φ)``, Φ = R D U(θ)⁻¹ (eq. (23))
``/world/material/lines``              static material lines (unit circle, spokes, normal)
                                       drawn under Φ: the spokes turn inside the ellipse with
                                       U(θ), which the ellipsoid alone (R only) cannot show
``/world/axes_C``                      ``Arrows3D``: principal axes of C = R D⁻² Rᵀ (spatial
                                       frame, columns of R), length 1.25 × (λ, μ, ϱ)
``/material/reference``                static undeformed material lines (reference frame)
``/material/G_ellipsoid``              ``Ellipsoids3D``: U D (unit ball) = G^{1/2}(unit ball)
``/material/axes_G``                   ``Arrows3D``: principal axes of G = U D² Uᵀ (material
                                       frame, columns of U(θ)), length 1.25 × (λ, μ, ϱ)
``/tensors/G``, ``/tensors/C``         ``Tensor`` 3×3 (float64), every ``tensor_every`` steps
``/series/G``, ``/series/C``           ``Scalars``: the 6 independent entries
                                       (11, 22, 33, 12, 13, 23) at every step
``/series/{lambda,mu,rho,theta}``      the shape and material angle
``/series/{energy,casimir,p_theta}``   H (eq. (41)), |s|², p_θ — conserved quantities
``/series/action/NAME``                env episodes: the actions (u = τ1, τ2, τ3, f_ϱ)
``/series/reward/NAME``                env episodes: the reward terms (and ``total``)
``/series/target/NAME``                env episodes: the target shape
=====================================  =====================================================

G = ΦᵀΦ = U D² U⁻¹ (eq. (33) of [1]); C = Φ⁻ᵀΦ⁻¹ = R D⁻² R⁻¹ (eq. (51)'s remark with
erratum E7 of [2]); both come from :mod:`flatbody_env.physics.kinematics`.

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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flatbody_env.physics.kinematics import cauchy_tensor, configuration, green_tensor, material_rotation
from flatbody_env.physics.state import STATE_NAMES
from flatbody_env.recording.geometry import ARROW_SCALE, TENSOR_ENTRIES, material_lines, quaternions_xyzw, symmetric_entries
from flatbody_env.recording.layout import ACTION_NAMES, COLOR_AXES, SCALAR_SERIES, blueprint, description_markdown, material_line_colors

APP_ID = "flatbody"
"""rerun application id of every flatbody recording."""

TIMELINES = ("step", "sim_time")
"""The two timelines: ``step`` (sequence) and ``sim_time`` (duration, integer nanoseconds)."""



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
    "/series/G",
    "/series/C",
    "/series/lambda",
    "/series/mu",
    "/series/rho",
    "/series/theta",
    "/series/energy",
    "/series/casimir",
    "/series/p_theta",
)
"""Entity paths present in every recording (env episodes add ``/series/{action,reward,target}/…``)."""

_IDX = {name: i for i, name in enumerate(STATE_NAMES)}

@dataclass
class _Block:
    """Arrays for one ``send_columns`` block (n steps)."""

    step: np.ndarray
    t: np.ndarray
    states: np.ndarray
    rotations: np.ndarray
    energy: np.ndarray
    actions: np.ndarray | None = None
    reward_terms: dict[str, np.ndarray] = field(default_factory=dict)
    target: dict[str, np.ndarray] = field(default_factory=dict)


def _check_finite(name: str, a: np.ndarray) -> None:
    if not np.all(np.isfinite(a)):
        bad = int(np.argmax(~np.isfinite(a).reshape(a.shape[0], -1).all(axis=1))) if a.ndim else 0
        raise ValueError(f"{name}: must be finite (first non-finite entry at step index {bad})")


def _as_block(
    t,
    states,
    rotations,
    *,
    energy,
    step,
    actions,
    reward_terms,
    target,
) -> _Block:
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
    act = None
    if actions is not None:
        act = np.asarray(actions, dtype=np.float64)
        if act.ndim == 1:
            act = act[:, None]
        if act.ndim != 2 or act.shape[0] != n:
            raise ValueError(f"actions: expected shape ({n}, k), got {np.shape(actions)}")
        _check_finite("actions", act)
    terms = {}
    for name, values in (reward_terms or {}).items():
        v = np.asarray(values, dtype=np.float64).ravel()
        if v.shape != (n,):
            raise ValueError(f"reward_terms[{name!r}]: expected shape ({n},), got {v.shape}")
        _check_finite(f"reward_terms[{name!r}]", v)
        terms[str(name)] = v
    tgt = {}
    for name, values in (target or {}).items():
        try:
            v = np.broadcast_to(np.asarray(values, dtype=np.float64), (n,)).copy()
        except ValueError:
            raise ValueError(f"target[{name!r}]: expected a number or shape ({n},), got shape {np.shape(values)}") from None
        _check_finite(f"target[{name!r}]", v)
        tgt[str(name)] = v
    return _Block(step=step_arr, t=t, states=states, rotations=rotations, energy=energy, actions=act, reward_terms=terms, target=tgt)


def _safe_name(name: str) -> str:
    out = "".join(c if (c.isalnum() or c in "_-") else "_" for c in str(name))
    return out or "_"


# --------------------------------------------------------------------------------------------------
# the recorder (the only rerun user)
# --------------------------------------------------------------------------------------------------


class Recorder:
    """A live recording to an ``.rrd`` file, sent in blocks with ``send_columns``.

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file (parent folders are created).
    body : flatbody_env.physics.body.Body
        The body (named in the description; its parameters go into the markdown).
    title : str
        Recording name shown in the viewer.
    description : str, optional
        Extra markdown appended to the standard description.
    block : int
        Steps buffered by :meth:`append` before a ``send_columns`` block is flushed (≥ 1).
    tensor_every : int
        Log the ``Tensor`` views of G and C every k-th step (k ≥ 1; the 6-scalar series are
        logged at every step regardless).
    action_names : sequence of str, optional
        Names of the action components (default ``tau1, tau2, tau3, f_rho`` for four).
    recording_id : str, optional
        rerun recording id (default: a fresh UUID).
    spokes : int
        Material spokes drawn under Φ.
    episode : bool
        An env episode: the default blueprint opens on the reward-term and action plots.

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
    ) -> None:
        import rerun as rr

        for name, value in (("block", block), ("tensor_every", tensor_every), ("spokes", spokes)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name}: must be an integer ≥ 1, got {value!r}")
        self.path = Path(path)
        if self.path.suffix != ".rrd":
            raise ValueError(f"path: a rerun recording file must end in .rrd, got {str(path)!r}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.body = body
        self.block = int(block)
        self.tensor_every = int(tensor_every)
        self.action_names = tuple(action_names) if action_names is not None else None
        self._buf: list[dict[str, Any]] = []
        self._closed = False
        self._steps = 0
        self._static_env: set[str] = set()
        self._tensor_batch_type = None
        self._rr = rr
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id or str(uuid.uuid4()), send_properties=True)
        if not self.rec.is_enabled():
            raise ValueError("RERUN: rerun logging is disabled by the environment variable RERUN (e.g. RERUN=off); unset it to record")
        self.rec.save(str(self.path), default_blueprint=blueprint(rr, env=episode))
        self.rec.send_recording_name(title)
        self._log_static(title, description, spokes)

    # -- static parts ------------------------------------------------------------------------------
    def _log_static(self, title: str, description: str, spokes: int) -> None:
        rr = self._rr
        rec = self.rec
        rec.log("/description", rr.TextDocument(description_markdown(title, self.body, description), media_type=rr.MediaType.MARKDOWN), static=True)
        rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log("/material", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        lines = material_lines(spokes)
        colors = material_line_colors(spokes)
        rec.log("/world/material/lines", rr.LineStrips3D(lines, colors=colors, radii=0.008), static=True)
        rec.log("/material/reference", rr.LineStrips3D(lines, colors=colors, radii=0.008), static=True)
        rec.log(
            "/world/body",
            rr.Ellipsoids3D.from_fields(colors=[[90, 140, 255, 255]], fill_mode=rr.components.FillMode.MajorWireframe, line_radii=0.006),
            static=True,
        )
        rec.log(
            "/material/G_ellipsoid",
            rr.Ellipsoids3D.from_fields(colors=[[255, 160, 60, 255]], fill_mode=rr.components.FillMode.MajorWireframe, line_radii=0.006),
            static=True,
        )
        rec.log("/world/axes_C", rr.Arrows3D.from_fields(colors=COLOR_AXES, labels=["C: 1/λ²", "C: 1/μ²", "C: 1/ϱ²"]), static=True)
        rec.log("/material/axes_G", rr.Arrows3D.from_fields(colors=COLOR_AXES, labels=["G: λ²", "G: μ²", "G: ϱ²"]), static=True)
        for name, label in SCALAR_SERIES:
            rec.log(f"/series/{name}", rr.SeriesLines(names=label), static=True)
        rec.log("/series/G", rr.SeriesLines(names=[f"G{ij}" for ij in TENSOR_ENTRIES]), static=True)
        rec.log("/series/C", rr.SeriesLines(names=[f"C{ij}" for ij in TENSOR_ENTRIES]), static=True)

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
    ) -> None:
        """Buffer one step; a full buffer is flushed as one ``send_columns`` block.

        ``state`` is a dict of the eleven names or an array in :data:`STATE_NAMES` order;
        ``energy`` defaults to H(state) (eq. (41) of [1]); ``step`` to the running count.
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
                "reward_terms": dict(reward_terms) if reward_terms else None,
                "target": dict(target) if target else None,
            }
        )
        self._steps += 1
        if len(self._buf) >= self.block:
            self.flush()

    def flush(self) -> None:
        """Send the buffered steps as one block (no-op when empty).

        The body, tensors and state series go out for every buffered step; actions, reward
        terms and targets for the steps that carry them (a reset has no action or reward).
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
            actions=None,
            reward_terms=None,
            target=None,
        )
        self._send_block(block)
        with_action = [b for b in buf if b["action"] is not None]
        if with_action:
            sizes = {b["action"].size for b in with_action}
            if len(sizes) != 1:
                raise ValueError(f"action: sizes differ within an episode ({sorted(sizes)})")
            self._send_actions(
                np.array([b["step"] for b in with_action], dtype=np.int64),
                np.array([b["t"] for b in with_action]),
                np.stack([b["action"] for b in with_action]),
            )
        for key, prefix, label in (("reward_terms", "/series/reward/", "{}"), ("target", "/series/target/", "target {}")):
            names = sorted({k for b in buf if b[key] for k in b[key]})
            for name in names:
                rows = [b for b in buf if b[key] and name in b[key]]
                values = np.array([float(b[key][name]) for b in rows])
                _check_finite(f"{key}[{name!r}]", values)
                self._env_series(
                    prefix + _safe_name(name),
                    label.format(name),
                    np.array([b["step"] for b in rows], dtype=np.int64),
                    np.array([b["t"] for b in rows]),
                    values,
                )

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
        ns = np.round(block.t * 1e9).astype(np.int64)
        idx = [
            rr.TimeColumn("step", sequence=block.step),
            rr.TimeColumn("sim_time", duration=ns.astype("timedelta64[ns]")),
        ]
        rec.send_columns("/world/body", indexes=idx, columns=rr.Ellipsoids3D.columns(half_sizes=half, quaternions=quaternions_xyzw(R)))
        rec.send_columns("/material/G_ellipsoid", indexes=idx, columns=rr.Ellipsoids3D.columns(half_sizes=half, quaternions=quaternions_xyzw(U)))
        rec.send_columns("/world/material", indexes=idx, columns=rr.Transform3D.columns(mat3x3=Phi))
        scaled = ARROW_SCALE * half[:, None, :]
        vec_C = np.swapaxes(R * scaled, 1, 2).reshape(3 * n, 3)  # rows: columns of R × semi-axis
        vec_G = np.swapaxes(U * scaled, 1, 2).reshape(3 * n, 3)
        three = np.full(n, 3, dtype=np.int32)
        rec.send_columns("/world/axes_C", indexes=idx, columns=rr.Arrows3D.columns(vectors=vec_C).partition(three))
        rec.send_columns("/material/axes_G", indexes=idx, columns=rr.Arrows3D.columns(vectors=vec_G).partition(three))
        six = np.full(n, 6, dtype=np.int32)
        rec.send_columns("/series/G", indexes=idx, columns=rr.Scalars.columns(scalars=symmetric_entries(G).ravel()).partition(six))
        rec.send_columns("/series/C", indexes=idx, columns=rr.Scalars.columns(scalars=symmetric_entries(C).ravel()).partition(six))
        casimir = y[_IDX["s1"]] ** 2 + y[_IDX["s2"]] ** 2 + y[_IDX["s3"]] ** 2
        series = {"lambda": lam, "mu": mu, "rho": rho, "theta": theta, "energy": block.energy, "casimir": casimir, "p_theta": y[_IDX["p_theta"]]}
        for name, values in series.items():
            rec.send_columns(f"/series/{name}", indexes=idx, columns=rr.Scalars.columns(scalars=values))
        sel = np.flatnonzero(block.step % self.tensor_every == 0)
        if sel.size:
            tidx = [
                rr.TimeColumn("step", sequence=block.step[sel]),
                rr.TimeColumn("sim_time", duration=ns[sel].astype("timedelta64[ns]")),
            ]
            rec.send_columns("/tensors/G", indexes=tidx, columns=[self._tensor_column(G[sel])])
            rec.send_columns("/tensors/C", indexes=tidx, columns=[self._tensor_column(C[sel])])
        if block.actions is not None:
            self._send_actions(block.step, block.t, block.actions)
        for name, values in block.reward_terms.items():
            self._env_series(f"/series/reward/{_safe_name(name)}", name, block.step, block.t, values)
        for name, values in block.target.items():
            self._env_series(f"/series/target/{_safe_name(name)}", f"target {name}", block.step, block.t, values)

    def _send_actions(self, step: np.ndarray, t: np.ndarray, actions: np.ndarray) -> None:
        k = actions.shape[1]
        names = self.action_names or (ACTION_NAMES if k == len(ACTION_NAMES) else tuple(f"a{i}" for i in range(k)))
        if len(names) != k:
            raise ValueError(f"action_names: {len(names)} names for actions of size {k}")
        _check_finite("actions", actions)
        for i, name in enumerate(names):
            self._env_series(f"/series/action/{_safe_name(name)}", name, step, t, actions[:, i])

    def _env_series(self, path: str, label: str, step: np.ndarray, t: np.ndarray, values: np.ndarray) -> None:
        rr = self._rr
        if path not in self._static_env:
            self.rec.log(path, rr.SeriesLines(names=str(label)), static=True)
            self._static_env.add(path)
        idx = [
            rr.TimeColumn("step", sequence=step),
            rr.TimeColumn("sim_time", duration=np.round(np.asarray(t) * 1e9).astype(np.int64).astype("timedelta64[ns]")),
        ]
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




# --------------------------------------------------------------------------------------------------
# one-call recording of a whole trajectory
# --------------------------------------------------------------------------------------------------


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
    """Record a whole trajectory given as arrays to ``path`` (``.rrd``), column-wise.

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
        Log the ``Tensor`` views every k-th step.
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
    if energy is None:
        from flatbody_env.physics.hamiltonian import hamiltonian_series

        Y = np.asarray(states, dtype=np.float64)
        if Y.ndim != 2 or Y.shape[0] != len(STATE_NAMES):
            raise ValueError(f"states: expected shape ({len(STATE_NAMES)}, n), got {Y.shape}")
        energy = hamiltonian_series(Y, body)
    block = _as_block(t, states, rotations, energy=energy, step=step, actions=None, reward_terms=None, target=None)
    with Recorder(path, body, title=title, description=description, tensor_every=tensor_every, recording_id=recording_id) as rec:
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


