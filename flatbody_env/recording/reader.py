"""Reading recordings back offline: :func:`read_recording` (rerun's own chunk reader, pyarrow only),
:func:`verify_recording` (``rerun rrd verify``), :func:`summarize_recording` (``flatbody record-info``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


@dataclass
class EntityData:
    """The temporal rows of one entity, sorted by ``step``: timelines and decoded components."""

    step: np.ndarray
    sim_time: np.ndarray  # model time (float64, from the timeline's integer nanoseconds and its time unit)
    components: dict[str, Any]


@dataclass
class RecordingData:
    """What :func:`read_recording` returns."""

    application_id: str
    recording_id: str
    entities: dict[str, EntityData]
    static: dict[str, dict[str, Any]]
    blueprints: int
    views: list[tuple[str, str]] = field(default_factory=list)
    """(view class, display name) of the default blueprint's views, e.g. ``("3D", "…")``."""

    def __getitem__(self, path: str) -> EntityData:
        return self.entities[path]


def _decode(column) -> Any:
    """An Arrow list column (one list per row) → numpy where the layout allows it."""
    import pyarrow as pa

    typ = column.type
    inner = typ.value_type
    lengths = column.value_lengths().to_numpy(zero_copy_only=False)
    values = column.flatten()
    if pa.types.is_struct(inner) and inner.get_field_index("buffer") >= 0:  # TensorData
        out = []
        for row in values.to_pylist():
            buf = row["buffer"]
            data = np.asarray(buf[1] if isinstance(buf, tuple) else buf, dtype=np.float64)
            out.append(data.reshape([int(s) for s in row["shape"]]))
        return np.stack(out) if out else np.empty((0, 3, 3))
    if pa.types.is_fixed_size_list(inner) and pa.types.is_floating(inner.value_type):
        flat = values.flatten().to_numpy(zero_copy_only=False).reshape(-1, inner.list_size)
        if np.all(lengths == lengths[0]):
            return flat.reshape(len(column), int(lengths[0]), inner.list_size)
        return np.split(flat, np.cumsum(lengths)[:-1])
    if pa.types.is_floating(inner) or pa.types.is_integer(inner):
        flat = values.to_numpy(zero_copy_only=False)
        if lengths.size and np.all(lengths == lengths[0]):
            return flat.reshape(len(column), int(lengths[0]))
        return np.split(flat, np.cumsum(lengths)[:-1])
    return column.to_pylist()


def _latest_row(rb) -> int:
    """The index of the row with the largest row id of a record batch (0 when it has no row ids)."""
    if "rerun.controls.RowId" not in rb.schema.names:
        return rb.num_rows - 1
    ids = [bytes(v) if v is not None else b"" for v in rb.column("rerun.controls.RowId").to_pylist()]
    return max(range(len(ids)), key=ids.__getitem__)


def _last_row_id(rb) -> bytes:
    """The largest row id of a chunk's record batch (rerun's row ids grow with time), b"" when it has none."""
    if "rerun.controls.RowId" not in rb.schema.names:
        return b""
    ids = [bytes(v) for v in rb.column("rerun.controls.RowId").to_pylist() if v is not None]
    return max(ids) if ids else b""


def time_scale(static: dict[str, dict[str, Any]]) -> float:
    """Seconds of the ``sim_time`` timeline per model time unit, from the recording's property ``time``
    (:func:`flatbody_env.recording.layout.time_unit`); 1 for a recording made before it was written."""
    try:
        scale = float(np.asarray(static["/__properties/time"]["seconds_per_unit"], dtype=float).ravel()[0])
    except (KeyError, IndexError, TypeError, ValueError):
        return 1.0
    return scale if np.isfinite(scale) and scale > 0 else 1.0


def read_recording(path: str | Path) -> RecordingData:
    """Read an ``.rrd`` offline with :class:`rerun.chunk.RrdReader` (pyarrow chunk path).

    Temporal chunks of each entity are concatenated and sorted by ``step``; static data land in
    ``static[entity][component]``. Geometry reads back as float32 (rerun's storage type),
    scalars and tensors as float64.
    """
    import rerun.chunk as rrc

    path = Path(path)
    if not path.exists():
        raise ValueError(f"path: no file {str(path)!r}")
    reader = rrc.RrdReader(path)
    recs = reader.recordings()
    if not recs:
        raise ValueError(f"path: {str(path)!r} holds no recording")
    entry = recs[0]
    parts: dict[str, list[tuple[np.ndarray, np.ndarray, dict[str, Any]]]] = {}
    static: dict[str, dict[str, Any]] = {}
    static_rows: dict[tuple[str, str], bytes] = {}
    for chunk in reader.stream(store=entry):
        rb = chunk.to_record_batch()
        if chunk.is_static and rb.num_rows > 1:  # several writes of static data in one chunk: the latest holds
            rb = rb.slice(_latest_row(rb), 1)
        comps = {}
        for i, f in enumerate(rb.schema):
            md = f.metadata or {}
            if md.get(b"rerun:kind") == b"data":
                comps[md.get(b"rerun:component", f.name.encode()).decode()] = _decode(rb.column(i))
        if chunk.is_static:  # the latest write wins (its row id), as in the viewer, whatever the file's order
            row = _last_row_id(rb)
            mine = static.setdefault(chunk.entity_path, {})
            for name, value in comps.items():
                if name not in mine or row >= static_rows.get((chunk.entity_path, name), b""):
                    mine[name] = value
                    static_rows[(chunk.entity_path, name)] = row
            continue
        if "step" not in rb.schema.names:
            continue
        step = rb.column("step").to_numpy(zero_copy_only=False).astype(np.int64)
        if "sim_time" in rb.schema.names:
            sim = rb.column("sim_time").cast("int64").to_numpy(zero_copy_only=False) * 1e-9
        else:
            sim = np.full(step.shape, np.nan)
        parts.setdefault(chunk.entity_path, []).append((step, sim, comps))
    views: list[tuple[str, str]] = []
    for bp in reader.blueprints():
        for chunk in reader.stream(store=bp):
            rb = chunk.to_record_batch()
            names = rb.schema.names
            if "ViewBlueprint:class_identifier" in names:
                cls = rb.column("ViewBlueprint:class_identifier").to_pylist()
                disp = (
                    rb.column("ViewBlueprint:display_name").to_pylist()
                    if "ViewBlueprint:display_name" in names
                    else [None] * len(cls)
                )
                for c, d in zip(cls, disp):
                    if c:
                        views.append((str(c[0]), str(d[0]) if d else ""))
    scale = time_scale(static)
    entities = {}
    for ent, plist in parts.items():
        step = np.concatenate([p[0] for p in plist])
        sim = np.concatenate([p[1] for p in plist]) / scale  # model time (the timeline's seconds per unit apart)
        order = np.argsort(step, kind="stable")
        comps: dict[str, Any] = {}
        names = {k for p in plist for k in p[2]}
        for name in names:
            pieces = [p[2].get(name) for p in plist]
            if all(isinstance(x, np.ndarray) for x in pieces) and len({x.shape[1:] for x in pieces}) == 1:
                comps[name] = np.concatenate(pieces)[order]
            else:
                flat: list[Any] = []
                for p, x in zip(plist, pieces):
                    flat.extend(list(x) if x is not None else [None] * len(p[0]))
                comps[name] = [flat[i] for i in order]
        entities[ent] = EntityData(step=step[order], sim_time=sim[order], components=comps)
    return RecordingData(
        application_id=entry.application_id,
        recording_id=entry.recording_id,
        entities=entities,
        static=static,
        blueprints=len(reader.blueprints()),
        views=sorted(views),
    )


@dataclass(frozen=True, kw_only=True)
class ViewInfo:
    """One view of a recording's default blueprint, as stored in the file."""

    view_class: str
    """``"3D"``, ``"TimeSeries"``, ``"Tensor"``, ``"TextDocument"``, …"""
    name: str
    origin: str
    contents: tuple[str, ...]
    """The view's entity-path query (``$origin`` expanded)."""
    properties: dict[str, Any]
    """The view's own settings (``"EyeControls3D:position"`` → value, …)."""

    def shows(self, entity: str) -> bool:
        """Whether the contents query includes ``entity`` (exact paths and ``PATH/**`` subtrees)."""
        hit = False
        for rule in self.contents:
            exclude = rule.startswith("- ")
            rule = rule[2:] if rule[:2] in ("- ", "+ ") else rule
            if rule.endswith("/**"):
                base = rule[:-3].rstrip("/") or "/"
                match = entity == base or entity.startswith(base.rstrip("/") + "/")
            else:
                match = entity == rule
            if match:
                hit = not exclude
        return hit


@dataclass(frozen=True, kw_only=True)
class BlueprintInfo:
    """What :func:`read_blueprint` returns: the default blueprint's views and panel states."""

    views: tuple[ViewInfo, ...]
    front: tuple[str, ...] = ()
    """The names of the views on screen at first open, in the layout's order: every view but those in a tab that is
    not a group's active one."""
    panels: dict[str, str]
    """``"time_panel"``, ``"blueprint_panel"``, ``"selection_panel"`` → ``"hidden"``, ``"collapsed"`` or ``"expanded"``."""
    timeline: str | None

    def view(self, name: str) -> ViewInfo:
        """The view called ``name`` (ValueError naming the views there are, if none)."""
        for v in self.views:
            if v.name == name:
                return v
        raise ValueError(f"name: no view {name!r} (views: {', '.join(v.name for v in self.views)})")


_PANEL_STATES = {1: "hidden", 2: "collapsed", 3: "expanded"}


def _chunk_time(chunk) -> int:
    """When a chunk was made: the first 64 bits of its id (a TUID: nanoseconds since the epoch)."""
    text = str(chunk.id)
    try:
        return int(text.removeprefix("chunk_")[:16], 16)
    except ValueError:
        return -1


def read_blueprint(path: str | Path) -> BlueprintInfo:
    """Read the default blueprint stored in a recording: views (class, name, origin, contents,
    properties) and the state of the time, blueprint and selection panels.

    A recording sent in several blocks holds several blueprints, each sent as the default (the file
    opened with the first block's, then one built from all values after a later block): the last sent
    is the one the viewer shows, and the one read here (the latest chunk id; rerun's chunk ids start
    with the time they were made)."""
    import rerun.chunk as rrc

    path = Path(path)
    if not path.exists():
        raise ValueError(f"path: no file {str(path)!r}")
    reader = rrc.RrdReader(path)
    props: dict[str, dict[str, Any]] = {}
    stores = [(bp, list(reader.stream(store=bp))) for bp in reader.blueprints()]
    if stores:
        stores = [max(stores, key=lambda s: max((_chunk_time(c) for c in s[1]), default=-1))]
    for _bp, chunks in stores:
        for chunk in chunks:
            rb = chunk.to_record_batch()
            for i, f in enumerate(rb.schema):
                md = f.metadata or {}
                if md.get(b"rerun:kind") != b"data":
                    continue
                values = rb.column(i).to_pylist()
                last = next((v for v in reversed(values) if v is not None), None)
                if last is not None:
                    props.setdefault(chunk.entity_path, {})[f.name] = (
                        last[0] if isinstance(last, list) and len(last) == 1 else last
                    )
    views = []
    names = {ent.lstrip("/"): str(c.get("ViewBlueprint:display_name", "")) for ent, c in props.items()}
    hidden: set[str] = set()
    order: list[str] = []

    def walk(node: str, shown: bool) -> None:  # the containers from the root: tabs hide all but their active one
        comp = props.get("/" + node, {})
        if "ViewBlueprint:class_identifier" in comp:
            order.append(node)
            if not shown:
                hidden.add(node)
            return
        kids = comp.get("ContainerBlueprint:contents") or []
        kids = [kids] if isinstance(kids, str) else list(kids)
        active = comp.get("ContainerBlueprint:active_tab")
        tabs = comp.get("ContainerBlueprint:container_kind") == 1
        for kid in kids:
            walk(str(kid), shown and (not tabs or kid == (active or (kids[0] if kids else None))))

    root = props.get("/viewport", {}).get("ViewportBlueprint:root_container")
    if isinstance(root, (list, tuple)) and len(root) == 16:  # a UUID as its 16 bytes: the container's entity
        import uuid

        walk(f"container/{uuid.UUID(bytes=bytes(int(b) for b in root))}", True)
    elif root:
        walk(str(root), True)
    front = tuple(names.get(n, "") for n in order if n not in hidden)
    for ent, comp in props.items():
        if "ViewBlueprint:class_identifier" not in comp:
            continue
        origin = str(comp.get("ViewBlueprint:space_origin", "/"))
        query = props.get(ent + "/ViewContents", {}).get("ViewContents:query", ["$origin/**"])
        query = [query] if isinstance(query, str) else list(query)
        settings = {
            k: v
            for sub, c in props.items()
            if sub.startswith(ent + "/") and not sub.endswith("/ViewContents")
            for k, v in c.items()
        }
        views.append(
            ViewInfo(
                view_class=str(comp["ViewBlueprint:class_identifier"]),
                name=str(comp.get("ViewBlueprint:display_name", "")),
                origin=origin,
                contents=tuple(q.replace("$origin", origin.rstrip("/")) for q in query),
                properties=settings,
            )
        )
    panels = {}
    for name, key in (
        ("time_panel", "TimePanelBlueprint:state"),
        ("blueprint_panel", "PanelBlueprint:state"),
        ("selection_panel", "PanelBlueprint:state"),
    ):
        state = props.get(f"/{name}", {}).get(key)
        if state is not None:
            panels[name] = _PANEL_STATES.get(int(state), str(state))
    timeline = props.get("/time_panel", {}).get("TimePanelBlueprint:timeline")
    return BlueprintInfo(
        views=tuple(sorted(views, key=lambda v: (v.view_class, v.name))), front=front, panels=panels, timeline=timeline
    )


def verify_recording(path: str | Path) -> str:
    """Run ``rerun rrd verify PATH`` (the SDK's own checker) and return its output.

    Raises
    ------
    ValueError
        If the file fails verification (the message carries rerun's output).
    """
    import os
    import subprocess
    import sys

    env = dict(os.environ, CI="1")  # no usage files under the home directory
    cmd = [sys.executable, "-m", "rerun", "rrd", "verify", str(path)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    out = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0:
        raise ValueError(
            f"path: {str(path)!r} failed 'rerun rrd verify': {out.splitlines()[-1] if out else proc.returncode}"
        )
    return out


def sdk_version() -> str:
    """The installed rerun-sdk version (play recordings back with a viewer of this version)."""
    import rerun as rr

    return str(rr.__version__)


def summarize_recording(path: str | Path, *, rows: int = 3) -> str:
    """A readable account of a recording, read back from the file: entities, rows, first values, and G and C
    as 3×3 matrices at the first and the last step (rebuilt from their entry series, :func:`_tensor_lines`)."""
    data = read_recording(path)
    lines = [
        f"{path}: application {data.application_id!r}, recording {data.recording_id}, {data.blueprints} blueprint(s)"
    ]
    if data.views:
        lines.append("default blueprint: " + "; ".join(f"{c} '{d}'" for c, d in data.views))
    lines.append(f"{'entity':<26} {'rows':>6} {'steps':>13} {'model time':>19}  components")
    for ent in sorted(data.entities):
        e = data.entities[ent]
        lines.append(
            f"{ent:<26} {e.step.size:>6} {int(e.step[0]):>6}–{int(e.step[-1]):<6} {e.sim_time[0]:>9.4g}–{e.sim_time[-1]:<9.4g}  "
            + ", ".join(sorted(e.components))
        )
    for ent in sorted(data.static):
        lines.append(f"{ent:<26} {'static':>6}  " + ", ".join(sorted(data.static[ent])))
    lines.append("")
    lines.append(f"first and last {rows} rows read back:")
    for name in ("lambda", "mu", "rho", "theta", "s3", "p_theta", "energy", "casimir", "drift/energy", "distance"):
        ent = f"/series/{name}"
        if ent in data.entities:
            v = np.asarray(data.entities[ent].components["Scalars:scalars"])[:, 0]
            head = "  ".join(f"{x:.6f}" for x in v[:rows])
            tail = "  ".join(f"{x:.6f}" for x in v[-rows:])
            lines.append(f"  {ent:<22} {head}  …  {tail}")
    lines.extend(_tensor_lines(data))
    return "\n".join(lines)


def _tensor_lines(data) -> list[str]:
    """G = ΦᵀΦ and C = Φ⁻ᵀΦ⁻¹ as 3×3 matrices at the first and the last logged step, rebuilt from their
    entries (11, 22, 33, 12, 13, 23) logged as the scalar series ``/series/G`` and ``/series/C``; a recording
    made before that change still has the tensor entities ``/tensors/G``, ``/tensors/C``, read as they are."""
    from flatbody_env.recording.geometry import symmetric_from_entries

    out = []
    for sym in ("G", "C"):
        series, tensor = f"/series/{sym}", f"/tensors/{sym}"
        if series in data.entities:
            e = data.entities[series]
            mats = symmetric_from_entries(np.asarray(e.components["Scalars:scalars"], dtype=np.float64).reshape(-1, 6))
            ent = series
        elif tensor in data.entities:
            e = data.entities[tensor]
            mats = np.asarray(e.components["Tensor:data"], dtype=np.float64).reshape(-1, 3, 3)
            ent = tensor
        else:
            continue
        for k in dict.fromkeys((0, len(mats) - 1)):
            out.append(f"  {sym} ({ent}) at step {int(e.step[k])} (sim_time {e.sim_time[k]:g}):")
            out.extend("    [" + "  ".join(f"{x:+.6f}" for x in row) + "]" for row in mats[k])
    return out
