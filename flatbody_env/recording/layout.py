"""The layout of a recording: the default blueprint, the series' names and colours, the description.

One layout code path for every kind of recording — a free scene (:func:`flatbody_env.recording.writer.record_trajectory`),
an env episode and an agent demo (both :class:`flatbody_env.recording.wrapper.RerunRecorder`);
an episode adds the target, distance, reward and action views to the same layout.

The window (time panel collapsed, side panels closed)::

    ┌───────────────┬───────────────┬──────────┬────────────────┐
    │ plate, top    │ 3-D view /    │ G tensor │ G, C: numbers  │
    │ view (lab +z) │ material frame│ C tensor │ and eigenvalues│
    ├───────────────┴──┬────────────┴─────┬────┴────────────────┤
    │ λ, μ, ϱ (+ λ*,…) │ episode: reward,  │ s₃ · p_θ · drift ·  │
    │                  │ distance, actions │ H · θ · G · C · text│
    └──────────────────┴───────────────────┴─────────────────────┘

Colours come from :data:`flatbody_env.env.rendering.COLORS`, the same as the ``rgb_array`` frames:
one colour per variable, its target drawn in the same colour as a faint wide band.
"""

from __future__ import annotations

import numpy as np

from flatbody_env.env.rendering import COLORS

ACTION_NAMES = ("tau1", "tau2", "tau3", "f_rho")
"""Default entity names of the four controls u = (τ₁, τ₂, τ₃, f_ϱ) (see :mod:`flatbody_env.physics.equations`)."""

GREEK = {
    "lambda": "λ",
    "mu": "μ",
    "rho": "ϱ",
    "theta": "θ",
    "s3": "s₃",
    "p_theta": "p_θ",
    "energy": "H",
    "casimir": "|s|²",
    "tau1": "τ₁",
    "tau2": "τ₂",
    "tau3": "τ₃",
    "f_rho": "f_ϱ",
    "omega3": "ω₃",
    "theta_dot": "θ̇",
}
"""Display names of the state, conserved quantities and controls."""

TARGET_SERIES = ("lambda", "mu", "rho", "s3", "p_theta", "energy")
"""Target entries plotted beside their variable (``/series/target/NAME``); the rest of the target
(ω₃*, θ̇*) is printed in the description."""

DRIFT_SERIES = (("energy", "ΔH/|H₀|"), ("casimir", "Δ|s|²/|s|²₀"), ("p_theta", "Δp_θ/|p_θ,₀|"))
"""Relative drift of the conserved quantities, (Q − Q₀)/|Q₀| (absolute Q − Q₀ where Q₀ = 0)."""

TENSOR_ENTRY_COLORS = np.array(
    [COLORS["lambda"], COLORS["mu"], COLORS["rho"], COLORS["p_theta"], COLORS["s3"], COLORS["theta"]], dtype=np.uint8
)
"""Colours of the entries 11, 22, 33 (the diagonal, in the colours of λ, μ, ϱ), 12, 13, 23."""

CATEGORICAL = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207))
"""Distinct colours for the members of one view (actions, reward terms)."""

AXIS_COLORS = np.array([(*COLORS["lambda"], 255), (*COLORS["mu"], 255), (*COLORS["rho"], 255)], dtype=np.uint8)
"""Principal-axis arrows e₁, e₂, e₃ (semi-axes λ, μ, ϱ) in the colours of λ, μ, ϱ."""

LINE_WIDTH = 2.0
TARGET_WIDTH = 6.0
TARGET_ALPHA = 90


def rgba(rgb, alpha: int = 255) -> list[int]:
    """``[r, g, b, alpha]``."""
    return [int(rgb[0]), int(rgb[1]), int(rgb[2]), int(alpha)]


def display_name(name: str) -> str:
    """The Greek display name of an entity name (``tau1`` → ``τ₁``); other names unchanged."""
    return GREEK.get(name, name)


def series_style(path: str, index: int = 0) -> tuple[str, list[int], float]:
    """(display name, RGBA colour, width) of a one-scalar series entity ``/series/...``.

    ``index`` is the series' place among the actions or reward terms of its recording (in order of
    appearance): each member of those views gets a colour of its own.

    Raises
    ------
    ValueError
        For a path this layout does not know (every logged series must have a place).
    """
    parts = path.strip("/").split("/")
    if parts[0] != "series" or len(parts) < 2:
        raise ValueError(f"path: not a series entity: {path!r}")
    if len(parts) == 2 and parts[1] in COLORS:
        return display_name(parts[1]), rgba(COLORS[parts[1]]), LINE_WIDTH
    group, name = parts[1], "/".join(parts[2:])
    if group == "target" and name in COLORS:
        return f"{display_name(name)}* (target)", rgba(COLORS[name], TARGET_ALPHA), TARGET_WIDTH
    if group == "drift":
        label = dict(DRIFT_SERIES).get(name)
        if label is not None:
            return label, rgba(COLORS[name]), LINE_WIDTH
    if group == "action":
        return display_name(name), rgba(CATEGORICAL[index % len(CATEGORICAL)]), LINE_WIDTH
    if group == "reward":
        if name == "total":
            return "total reward", rgba((90, 90, 90)), 3.0
        return name, rgba(CATEGORICAL[index % len(CATEGORICAL)]), LINE_WIDTH
    raise ValueError(f"path: no place in the layout for the series {path!r}")


def nice_range(m: float) -> float:
    """Smallest of 1, 1.5, 2, 3, 4, 5, 6, 8 × 10ᵏ ≥ ``m`` (the tensor views' fixed colour range)."""
    from flatbody_env.env.rendering import nice_half_width

    return nice_half_width(max(float(m), 1e-12))


def camera_kind(view_name: str) -> str:
    """``"top"`` for the plate's top view, ``"oblique"`` for the other 3-D views (where :func:`camera` places the eye)."""
    return "top" if view_name.startswith("plate") else "oblique"


def camera(view: str, extent: float):
    """The eye of a 3-D view: ``"top"`` straight down the laboratory's +z axis, ``"oblique"`` from
    above the plate; its distance grows with ``extent`` (the body's largest expected semi-axis)."""
    import rerun.blueprint as rrb

    d = float(extent)
    if view == "top":  # straight down the laboratory's +z axis, x to the right, y up
        return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=[0.0, 0.0, 2.6 * d], look_target=[0.0, 0.0, 0.0], eye_up=[0.0, 1.0, 0.0])
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=[1.4 * d, -1.9 * d, 1.6 * d], look_target=[0.0, 0.0, 0.0], eye_up=[0.0, 0.0, 1.0])


def _series_view(name: str, paths: list[str], *, origin: str = "/series", y_range: float | None = None):
    import rerun.blueprint as rrb

    axis = rrb.ScalarAxis(range=(-y_range, y_range)) if y_range else None
    return rrb.TimeSeriesView(name=name, origin=origin, contents=paths, plot_legend=rrb.PlotLegend(corner="RightBottom", visible=True), axis_y=axis)


DRIFT_FLOOR = 1e-6
"""Smallest half-range of the drift plot's fixed axis: round-off (1e-12 … 1e-9) reads as a flat line at 0."""


def drift_axis(max_abs_drift: float) -> float:
    """Half-range of the relative-drift axis of a free scene: nice ≥ 1.2 × the largest drift, at least :data:`DRIFT_FLOOR`."""
    return max(DRIFT_FLOOR, nice_range(1.2 * float(max_abs_drift))) if max_abs_drift > 0 else DRIFT_FLOOR


def view_specs(*, episode: bool) -> list[tuple[str, str, tuple[str, ...]]]:
    """(view class, name, entity paths or origins) of every view :func:`blueprint` lays out, in order.

    The single source of the layout: :func:`blueprint` builds the views from it and the tests check
    the file against it.
    """
    shape = ["/series/lambda", "/series/mu", "/series/rho"] + (["/series/target/lambda", "/series/target/mu", "/series/target/rho"] if episode else [])
    specs = [
        ("3D", "plate, top view (lab +z)", ("/world",)),
        ("3D", "3-D view", ("/world",)),
        ("3D", "material frame: U(θ), G axes", ("/material",)),
        ("Tensor", "G = ΦᵀΦ (fixed colour range)", ("/tensors/G",)),
        ("Tensor", "C = Φ⁻ᵀΦ⁻¹ (fixed colour range)", ("/tensors/C",)),
        ("TextDocument", "G, C: numbers and eigenvalues", ("/tensors/numbers",)),
        ("TimeSeries", "λ, μ, ϱ" + (" vs target λ*, μ*, ϱ*" if episode else ""), tuple(shape)),
    ]
    if episode:
        specs += [
            ("TimeSeries", "reward terms", ("/series/reward",)),
            ("TimeSeries", "distance to the target", ("/series/distance",)),
            ("TimeSeries", "actions u = (τ₁, τ₂, τ₃, f_ϱ)", ("/series/action",)),
        ]
    specs += [
        ("TimeSeries", "conserved: relative drift", ("/series/drift",)),
        ("TimeSeries", "s₃" + (" vs s₃*" if episode else ""), ("/series/s3",) + (("/series/target/s3",) if episode else ())),
        ("TimeSeries", "p_θ" + (" vs p_θ*" if episode else ""), ("/series/p_theta",) + (("/series/target/p_theta",) if episode else ())),
        ("TimeSeries", "energy H" + (" vs H*" if episode else ""), ("/series/energy",) + (("/series/target/energy",) if episode else ())),
        ("TimeSeries", "|s|² (Casimir)", ("/series/casimir",)),
        ("TimeSeries", "θ", ("/series/theta",)),
        ("TimeSeries", "G entries 11 22 33 12 13 23", ("/series/G",)),
        ("TimeSeries", "C entries 11 22 33 12 13 23", ("/series/C",)),
        ("TextDocument", "description", ("/description",)),
    ]
    return specs


def blueprint(*, episode: bool, extent: float = 2.0, drift_range: float | None = None):
    """The default blueprint of a recording.

    Parameters
    ----------
    episode : bool
        An env episode (adds the target, reward, distance and action views).
    extent : float
        The body's size (largest semi-axis expected); sets the cameras' distance.
    drift_range : float, optional
        A fixed axis ±``drift_range`` for the relative-drift plot (free scenes, where the drift
        is known before the file is written: :func:`drift_axis`); None lets the axis follow the
        data (episodes, where control changes H, |s|² and p_θ on purpose).
    """
    import rerun.blueprint as rrb

    specs = {name: (cls, paths) for cls, name, paths in view_specs(episode=episode)}

    def view(name: str):
        cls, paths = specs[name]
        if cls == "3D":
            kind = camera_kind(name)
            return rrb.Spatial3DView(
                name=name,
                origin=paths[0],
                eye_controls=camera(kind, extent),
                line_grid=rrb.LineGrid3D(visible=kind != "top", spacing=0.5),
            )
        if cls == "Tensor":
            return rrb.TensorView(name=name, origin=paths[0], scalar_mapping=rrb.TensorScalarMapping(colormap="cyantoyellow"), view_fit="Fill")
        if cls == "TextDocument":
            return rrb.TextDocumentView(name=name, origin=paths[0])
        if len(paths) == 1:
            return _series_view(name, [paths[0], paths[0] + "/**"], y_range=drift_range if paths[0] == "/series/drift" else None)
        return _series_view(name, list(paths))

    names = [n for _, n, _ in view_specs(episode=episode)]
    shape, rest = names[6], names[7:]
    if episode:
        middle = rrb.Tabs(*(view(n) for n in rest[:3]), active_tab=0)
        right = rrb.Tabs(*(view(n) for n in rest[3:]), active_tab=0)
    else:
        middle = rrb.Tabs(*(view(n) for n in rest[:1] + rest[3:4]), active_tab=0)  # drift, H
        right = rrb.Tabs(*(view(n) for n in rest[1:3] + rest[4:]), active_tab=0)  # s₃, p_θ, |s|², θ, G, C, text
    top_row = rrb.Horizontal(
        view(names[0]),
        rrb.Tabs(view(names[1]), view(names[2]), active_tab=0),
        rrb.Vertical(view(names[3]), view(names[4])),
        view(names[5]),
        column_shares=[3, 3, 2, 2.4],
    )
    bottom_row = rrb.Horizontal(view(shape), middle, right, column_shares=[1, 1, 1])
    return rrb.Blueprint(
        rrb.Vertical(top_row, bottom_row, row_shares=[3, 2]),
        rrb.TimePanel(state="collapsed", timeline="sim_time"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        auto_views=False,
    )


_TENSOR_TEXT = (
    "**t = %.3f**\n\n"
    "```\n"
    "G = ΦᵀΦ               eigenvalue\n"
    "%+7.3f%+7.3f%+7.3f  λ² %.3f\n"
    "%+7.3f%+7.3f%+7.3f  μ² %.3f\n"
    "%+7.3f%+7.3f%+7.3f  ϱ² %.3f\n"
    "\n"
    "C = Φ⁻ᵀΦ⁻¹            eigenvalue\n"
    "%+7.3f%+7.3f%+7.3f  λ⁻² %.3f\n"
    "%+7.3f%+7.3f%+7.3f  μ⁻² %.3f\n"
    "%+7.3f%+7.3f%+7.3f  ϱ⁻² %.3f\n"
    "```\n\n"
    "Heat maps: fixed range −%s (cyan) … 0 (grey) … +%s (yellow)."
)
"""One step of :func:`tensor_text`: 1 + 2 × 12 numbers and the colour range twice (its only ``%s``)."""

_SEP = "\x00"  # joins the steps' texts for one formatting call; no number or label contains it


def tensor_text(t: np.ndarray, G: np.ndarray, C: np.ndarray, half: np.ndarray, value_range: float) -> list[str]:
    """Markdown, one per step: G and C as numbers with their eigenvalues.

    The eigenvalues are λ², μ², ϱ² for G and 1/λ², 1/μ², 1/ϱ² for C (eq. (35) of the paper; C per
    the corrected eq. (51) remark in ``docs/physics.md``), computed from the semi-axes ``half``
    (n, 3); ``value_range`` is the tensor views' colour range ±r. All steps are formatted in one
    ``%`` call over a table of their numbers (the per-step text is the same as formatting each alone).
    """
    t = np.asarray(t, dtype=np.float64).ravel()
    n = t.size
    if n == 0:
        return []
    half = np.asarray(half, dtype=np.float64).reshape(n, 3)
    sq = half * half
    r = "%g" % value_range  # the same in every step: written into the template, not formatted n times
    step = _TENSOR_TEXT.replace("%s", r)  # its only %s are the range's two
    cols = [t[:, None]]
    for M, eig in ((np.asarray(G, dtype=np.float64).reshape(n, 3, 3), sq), (np.asarray(C, dtype=np.float64).reshape(n, 3, 3), 1 / sq)):
        cols.append(np.concatenate([M, eig[:, :, None]], axis=2).reshape(n, 12))
    return ((step + _SEP) * n % tuple(np.concatenate(cols, axis=1).ravel().tolist())).split(_SEP)[:n]


def axis_labels(half: np.ndarray) -> list[str]:
    """Labels of the principal-axis arrows, three per step: ``λ = 1.203`` … — the arrows' lengths."""
    half = np.asarray(half, dtype=np.float64).reshape(-1, 3)
    n = half.shape[0]
    if n == 0:
        return []
    return (("λ = %.3f" + _SEP + "μ = %.3f" + _SEP + "ϱ = %.3f" + _SEP) * n % tuple(half.ravel().tolist())).split(_SEP)[: 3 * n]


def description_markdown(title: str, body, extra: str, *, episode: bool) -> str:
    """The ``/description`` document: the model, the body, what each view shows."""
    try:
        desc = body.describe()
    except AttributeError:  # a duck-typed body without describe()
        desc = repr(body)
    text = f"""# {title}

A flat affinely-rigid body with thickness (V. Kovalchuk & E. E. Rożko, arXiv:0902.3573; corrections in `docs/physics.md`). Body: {desc}.

**Configuration** Φ = R · diag(λ, μ, ϱ) · U(θ)⁻¹ (eqs. (23)–(24) of the paper).

* **plate, top view** — the body seen from the laboratory's +z axis: the blue wireframe ellipsoid
  has semi-axes λ, μ, ϱ along the columns of R; the grey material lines (rim, spokes; the gold
  spoke is the fibre along e₁) are drawn under Φ, so the spokes turn inside the ellipse with U(θ).
  Arrows: the principal axes, **length = the semi-axis printed on them** (λ red, μ green, ϱ blue);
  they are the eigenvectors of C = Φ⁻ᵀΦ⁻¹ = R D⁻² Rᵀ (eigenvalues 1/λ², 1/μ², 1/ϱ²).{" The magenta outline is the target ellipse (λ*, μ*) along the current axes." if episode else ""}
* **3-D view** — the same, from an oblique camera; **material frame** — the undeformed material
  lines and G^½(ball) = U D (ball); arrows along the columns of U(θ), the principal axes of the
  Green tensor G = ΦᵀΦ = U D² Uᵀ (eq. (33)), length λ, μ, ϱ (eigenvalues λ², μ², ϱ², eq. (35)).
* **G, C** — heat maps with a fixed, symmetric colour range, and beside them the numbers with
  their eigenvalues.
* **time series** — λ, μ, ϱ{" with the target as a faint band of the same colour" if episode else ""}; s₃, p_θ, θ, the
  energy H (eq. (41)) and the Casimir |s|²; the conserved quantities H, |s|², p_θ as relative drift
  (Q − Q₀)/|Q₀|{"; reward terms, the distance to the target and the actions u = (τ₁, τ₂, τ₃, f_ϱ), drawn at the step they lead to" if episode else ""}.

Timelines: `sim_time` (simulated time, the default) and `step`.
"""
    if extra:
        text += "\n" + extra.strip() + "\n"
    return text


def material_line_colors(spokes: int) -> np.ndarray:
    """RGBA of the material lines: rim and spokes grey (readable on dark and light themes), the
    fibre along e₁ gold, the normal blue."""
    colors = np.tile(np.array([rgba(COLORS["material"])], dtype=np.uint8), (spokes + 2, 1))
    colors[1] = rgba(COLORS["fibre"])
    colors[-1] = rgba(COLORS["normal"])
    return colors
