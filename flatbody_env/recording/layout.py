"""The layout of a recording: the default blueprint, the series' names and colours, the description.

One layout code path for every kind of recording — a free scene (:func:`flatbody_env.recording.writer.record_trajectory`),
an env episode and an agent demo (both :class:`flatbody_env.recording.wrapper.RerunRecorder`);
an episode adds the target, distance, reward and action views to the same layout.

The window (time panel collapsed, side panels closed)::

    ┌───────────────┬───────────────┬──────────┬────────────────┐
    │ plate, top    │ 3-D view /    │ G tensor │ G, C: numbers  │
    │ view (lab +z) │ material frame│ C tensor │ and eigenvalues│
    ├───────────────┴──┬────────────┴─────┬────┴────────────────┤
    │ λ, μ, ϱ (+ λ*,…) │ episode: distance │ episode: energy     │
    │                  │ · reward · actions│ balance H − H₀ = W  │
    │                  │ free: drift · H   │ ─────────────────── │
    │                  │                   │ residual · P̄ · s₃ … │
    └──────────────────┴───────────────────┴─────────────────────┘

Colours come from :data:`flatbody_env.env.rendering.COLORS`, the same as the ``rgb_array`` frames:
one colour per variable, its target drawn in the same colour as a faint wide band.
"""

from __future__ import annotations

import math

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

SERIES_COLORS: dict[str, tuple[int, int, int]] = {
    # the controls u = (τ₁, τ₂, τ₃, f_ϱ): hues of their own, no pale tint of a variable's colour (a tint reads as
    # that variable or as its target's faint band)
    "action/tau1": (255, 225, 0),
    "action/tau2": (255, 75, 165),
    "action/tau3": (0, 225, 165),
    "action/f_rho": (180, 120, 255),
    # the energy balance of an episode: H − H₀ wide in H's colour, the work W thin and light on top of it, the
    # residual H − H₀ − W and the control's power on their own
    "power": (255, 240, 165),
    "balance/work": (150, 210, 255),
    "balance/delta_energy": COLORS["energy"],
    "residual": (255, 150, 150),
    # the reward terms of the v1 tasks (success, proximity) and of FlatBody-v0 (others take the spare colours)
    "reward/success": (0, 255, 105),
    "reward/proximity": (255, 180, 75),
    "reward/shape": (255, 165, 210),
    "reward/spin": (180, 240, 240),
    "reward/tumble": (195, 120, 60),
    "reward/rest": (0, 165, 105),
    "reward/action": (195, 75, 255),
    "reward/failure": (255, 45, 105),
    "reward/alive": (150, 150, 90),
    "reward/total": (195, 195, 210),
    "distance_tolerance": (255, 255, 255),
}
"""Colours of the series that are not state variables (actions, reward terms, the energy balance, the tolerance
line): each differs from every variable's colour in :data:`COLORS` by a CIE ΔE ≥ 27 and from the others by ΔE ≥ 21
(``tests/recording/test_layout.py`` checks ≥ 19 in the files)."""

SPARE_COLORS = ((195, 255, 0), (225, 195, 255), (150, 165, 240), (255, 135, 90), (90, 240, 240), (210, 210, 180))
"""Colours for reward terms or actions this layout does not name, in order of appearance."""

TENSOR_ENTRY_COLORS = np.array(
    [(255, 135, 90), (90, 240, 240), (210, 210, 180), (255, 0, 255), (135, 255, 135), (255, 255, 105)],
    dtype=np.uint8,
)
"""Colours of the entries 11, 22, 33, 12, 13, 23 of G and C (the same entry the same colour in both
views; none of them a variable's colour, each far from the others: 11 salmon, 22 aqua, 33 beige, 12 magenta,
13 light green, 23 yellow)."""

AXIS_COLORS = np.array([(*COLORS["lambda"], 255), (*COLORS["mu"], 255), (*COLORS["rho"], 255)], dtype=np.uint8)
"""Principal-axis arrows e₁, e₂, e₃ (semi-axes λ, μ, ϱ) in the colours of λ, μ, ϱ."""

LINE_WIDTH = 2.0
TARGET_WIDTH = 6.0
TARGET_ALPHA = 90
BALANCE_WIDTH = 5.0
"""Width of H − H₀ in the energy balance: the work W (1.5 wide, light) is drawn inside it, so both are seen."""

FLAT_RTOL = 1e-8
"""A panel whose values spread by less than this, relative to the panel's scale, is round-off: it is
drawn flat on a fixed axis and its title says so (:func:`y_axis`)."""


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
    key = "/".join(parts[1:])
    if len(parts) == 2 and parts[1] in COLORS:
        return display_name(parts[1]), rgba(COLORS[parts[1]]), LINE_WIDTH
    if key in SERIES_LABELS:
        if key == "balance/delta_energy":  # wide, in H's colour: the work W, thin and light, runs inside it
            return SERIES_LABELS[key], rgba(SERIES_COLORS[key]), BALANCE_WIDTH
        if key == "balance/work":
            return SERIES_LABELS[key], rgba(SERIES_COLORS[key]), 1.5
        return SERIES_LABELS[key], rgba(SERIES_COLORS[key]), (3.0 if key == "reward/total" else LINE_WIDTH)
    group, name = parts[1], "/".join(parts[2:])
    if group == "target" and name in COLORS:
        return f"{display_name(name)}* (target)", rgba(COLORS[name], TARGET_ALPHA), TARGET_WIDTH
    if group == "drift":
        label = dict(DRIFT_SERIES).get(name)
        if label is not None:
            return label, rgba(COLORS[name]), LINE_WIDTH
    if group in ("action", "reward"):
        color = SERIES_COLORS.get(key) or SPARE_COLORS[index % len(SPARE_COLORS)]
        return (display_name(name) if group == "action" else name), rgba(color), LINE_WIDTH
    raise ValueError(f"path: no place in the layout for the series {path!r}")


SERIES_LABELS = {
    "power": "P̄ = ω·τ + ϱ̇ f_ϱ (mean over the step)",
    "balance/work": "W = ∫ P dt (work of the control), inside",
    "balance/delta_energy": "H − H₀ (wide)",
    "residual": "H − H₀ − W",
    "distance_tolerance": "success tolerance",
    "reward/total": "total reward",
}
"""Legend names of the series that are not state variables."""


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
        return rrb.EyeControls3D(
            kind=rrb.Eye3DKind.Orbital,
            position=[0.0, 0.0, 2.6 * d],
            look_target=[0.0, 0.0, 0.0],
            eye_up=[0.0, 1.0, 0.0],
        )
    return rrb.EyeControls3D(
        kind=rrb.Eye3DKind.Orbital,
        position=[1.4 * d, -1.9 * d, 1.6 * d],
        look_target=[0.0, 0.0, 0.0],
        eye_up=[0.0, 0.0, 1.0],
    )


def _series_view(
    name: str,
    contents: list[str],
    *,
    axis: tuple[float, float] | None,
    legend: bool,
    t_range: tuple[float, float] | None,
    end: float | None,
    scale: float = 1.0,
):
    import rerun as rr
    import rerun.blueprint as rrb

    axis_y = rrb.ScalarAxis(range=axis, zoom_lock=False) if axis is not None else None
    axis_x = None
    if t_range is not None and end is not None:  # the whole run, and room on the right for the last tick label
        axis_x = rrb.TimeAxis(
            view_range=rr.TimeRange(
                start=rr.TimeRangeBoundary.absolute(seconds=t_range[0] * scale),
                end=rr.TimeRangeBoundary.absolute(seconds=end * scale),
            )
        )
    return rrb.TimeSeriesView(
        name=name,
        origin="/series",
        contents=contents,
        plot_legend=rrb.PlotLegend(corner="RightTop", visible=legend),
        axis_y=axis_y,
        axis_x=axis_x,
    )


TIME_UNITS = ((1.0, "s"), (1e-3, "ms"), (1e-6, "µs"))
"""Seconds of the ``sim_time`` timeline per model time unit, and rerun's name of that duration, tried in turn
(:func:`time_unit`)."""


def time_unit(t_end: float) -> tuple[float, str]:
    """(seconds per model time unit, unit) of a recording whose run ends at ``t_end``.

    rerun 0.41 prints a duration axis in the largest unit that reaches a whole one: seconds up to a minute, then
    minutes — so 1 model unit = 1 s read a 200-unit run as ``+1m +2m +3m``. A run is logged with the first unit
    of :data:`TIME_UNITS` under which its whole time axis (with :data:`TIME_MARGIN`) stays below a minute: model
    time then reads as rerun's number, in powers of ten: ``+150ms`` is t = 150 and ``+2s`` t = 2000 in a run
    logged in milliseconds (the description says so)."""
    end = abs(float(t_end)) * (1.0 + TIME_MARGIN)
    for scale, name in TIME_UNITS:
        if end * scale < 60.0:
            return scale, name
    return TIME_UNITS[-1]


def time_note(scale: float, name: str) -> str:
    """How to read a recording's time axes, for its description."""
    if scale == 1.0:
        return "model time on the time axis: 1 model time unit is shown as 1 s (+10s is t = 10)"
    return (
        f"model time on the time axis, logged as 1 model time unit = 1 {name} so that rerun never prints minutes: "
        f"+150{name} is t = 150" + (", +2s is t = 2000" if name == "ms" else ", +2ms is t = 2000")
    )


TIME_MARGIN = 0.07
"""Room right of the last sample on every time axis (a fraction of the run), so that the last tick
label is not cut by the panel's edge."""

LEGEND_ROW = 0.075
"""Head room above the data per legend entry (a fraction of the data's span): the legend, in the top
right corner, sits over empty space instead of over the curves' ends."""

FLAT_PAD = 0.06
"""A flat view's axis reaches this fraction of its half-width beyond its end ticks."""

FLAT_NOTE = " (flat: constant to 1e-8)"
"""Appended to the title of a panel whose values are constant to :data:`FLAT_RTOL` (:func:`y_axis`)."""

SHAPE_TITLE = "λ (red), μ (green), ϱ (blue)"
"""Title of the semi-axes' view: it names the colours, so the view needs no legend and its whole height
is data (:func:`y_axis`): at 1600 × 1000 a step of 0.1 is then ≥ 20 px for a spread up to ≈ 2, the
height at which rerun labels the 0.1 ticks (it labels powers of ten only: with the head room of a
six-entry legend the view had labels at 1 and 2 alone)."""

SHAPE_TARGETS = "; targets λ*, μ*, ϱ*: wide faint bands"
"""Added to :data:`SHAPE_TITLE` in an episode."""

BOTTOM_ROW_SHARE = 1.3
"""Height of the row of time plots relative to the row of 3-D views and text."""


def _shape_paths(episode: bool) -> tuple[str, ...]:
    return ("/series/lambda", "/series/mu", "/series/rho") + (
        ("/series/target/lambda", "/series/target/mu", "/series/target/rho") if episode else ()
    )


def series_views(*, episode: bool) -> list[tuple[str, tuple[str, ...], str]]:
    """(base title, series entity paths or groups, scale rule) of every time-series view, in layout order.

    The scale rule names what a spread is compared with (:func:`y_axis`): ``"self"`` the largest
    value shown, ``"spin"`` |s| (for s₃, p_θ), ``"angle"`` π, ``"relative"`` 1 (a relative drift),
    ``"energy"`` the largest |H| (the energy balance), ``"power"`` the largest |H| per unit time,
    ``"unit"`` 1 (actions in [−1, 1]), ``"residual"`` its own largest value (the balance's residual, always
    drawn as a signal, however small). Titles are short (they are tab labels) and hold no " · ", which
    starts the notes :func:`view_specs` adds from the values."""
    views = [(SHAPE_TITLE + (SHAPE_TARGETS if episode else ""), _shape_paths(episode), "self")]
    if episode:
        views += [
            ("distance, tolerance", ("/series/distance", "/series/distance_tolerance"), "self"),
            ("reward terms", ("/series/reward",), "self"),
            ("actions in [−1, 1]", ("/series/action",), "unit"),
            ("energy balance H − H₀ = W", ("/series/balance",), "energy"),
            ("residual H − H₀ − W", ("/series/residual",), "residual"),
            ("control power P̄", ("/series/power",), "power"),
        ]
    else:
        views += [
            ("conserved: drift (Q − Q₀)/|Q₀|", ("/series/drift",), "relative"),
            ("energy H", ("/series/energy",), "self"),
        ]
    views += [
        ("s₃" + (" vs s₃*" if episode else ""), ("/series/s3",) + (("/series/target/s3",) if episode else ()), "spin"),
        (
            "p_θ" + (" vs p_θ*" if episode else ""),
            ("/series/p_theta",) + (("/series/target/p_theta",) if episode else ()),
            "spin",
        ),
    ]
    if episode:
        views.append(("energy H vs H*", ("/series/energy", "/series/target/energy"), "self"))
    views += [
        ("|s|² (Casimir)", ("/series/casimir",), "self"),
        ("θ (material angle)", ("/series/theta",), "angle"),
        ("G = ΦᵀΦ entries 11 22 33 12 (13 = 23 = 0)", ("/series/G",), "self"),
        ("C = Φ⁻ᵀΦ⁻¹ entries 11 22 33 12 13 23", ("/series/C",), "self"),
    ]
    return views


NOTE_SEP = " · "
"""Starts a note that :func:`view_specs` adds to a title from the logged values (a magnitude, the reward terms left
out); :func:`base_title` strips it."""


def base_title(name: str) -> str:
    """The title :func:`series_views` gives a view whose name carries notes (:data:`NOTE_SEP`, :data:`FLAT_NOTE`)."""
    return name.removesuffix(FLAT_NOTE).split(NOTE_SEP)[0]


def _short(x: float) -> str:
    return f"{x:.2g}" if x != 0 else "0"


def constant_terms(ranges: dict[str, tuple[float, float, int]] | None) -> dict[str, float]:
    """Reward terms that keep one value over the whole recording (``alive``: 1 at every step), by entity path: they
    are left out of the reward view, which would otherwise be scaled to them and flatten the terms that move, and
    its title names them (:func:`view_specs`). The total is always drawn."""
    out = {}
    for path, (lo, hi, _) in (ranges or {}).items():
        if path.startswith("/series/reward/") and path != "/series/reward/total" and lo == hi:
            out[path] = lo
    return out


def _notes(base: str, paths: tuple[str, ...], ranges: dict | None) -> str:
    """The notes of a view from the logged values: the largest relative drift of each conserved quantity, the
    balance's residual, the reward terms left out (:func:`constant_terms`)."""
    if not ranges:
        return ""
    if "/series/drift" in paths:
        parts = []
        for name, _ in DRIFT_SERIES:
            r = ranges.get(f"/series/drift/{name}")
            if r is not None:
                parts.append(f"{GREEK.get(name, name)} {_short(max(abs(r[0]), abs(r[1])))}")
        return f"{NOTE_SEP}largest: " + ", ".join(parts) if parts else ""
    if "/series/residual" in paths:
        r = ranges.get("/series/residual")
        return f"{NOTE_SEP}largest {_short(max(abs(r[0]), abs(r[1])))}" if r else ""
    if "/series/reward" in paths:
        const = constant_terms(ranges)
        if const:
            terms = ", ".join(f"{p.rsplit('/', 1)[-1]} ≡ {v + 0.0:g}" for p, v in sorted(const.items()))  # no -0
            return f"{NOTE_SEP}not drawn: {terms}"
    return ""


def _members(paths: tuple[str, ...], ranges: dict[str, tuple[float, float, int]]) -> list[str]:
    """The logged series a view shows: its paths, and the entities under a group path."""
    out = []
    for p in paths:
        out += [q for q in ranges if q == p or q.startswith(p + "/")]
    return out


def time_axis_end(t_range: tuple[float, float]) -> float:
    """The right end of every time axis: the last time plus :data:`TIME_MARGIN` of the run (room for
    the last tick label)."""
    t0, t1 = (float(v) for v in t_range)
    return t0 + max(t1 - t0, 1e-9) * (1.0 + TIME_MARGIN)


LIVE_ROOM = (0.25, 0.5)
"""A recording sent in several blocks: room added to an axis that no longer holds the data, a fraction
of its span (y axes, time axis), so that a later block seldom changes the axes (:func:`grow_axes`)."""


def grow_axes(needed: list[tuple], sent: list[tuple] | None, t0: float = 0.0) -> list[tuple] | None:
    """The axes of the next blueprint of a recording sent in several blocks, or None when ``sent`` (the
    axes of the last one sent) still fits ``needed`` (:func:`series_axes` of all values so far).

    The axes fit when every view has the same title (flat or not) and legend, its y range holds the
    needed one and its time axis reaches the needed end. Otherwise every axis is built again from the
    needed one with room: a y range that is not flat grows by :data:`LIVE_ROOM` of its span on each
    side (flat ranges are fixed to ±10 % of their scale and are taken as they are), the time axis by
    LIVE_ROOM of the run. ``t0``: the run's first time."""

    def holds(outer, inner):
        return inner is None or (outer is not None and outer[0] <= inner[0] and inner[1] <= outer[1])

    if (
        sent is not None
        and len(sent) == len(needed)
        and all(
            s[0] == n[0]
            and s[2] == n[2]
            and holds(s[1], n[1])
            and (n[3] is None or (s[3] is not None and s[3] >= n[3]))
            for s, n in zip(sent, needed)
        )
    ):
        return None
    out = []
    for name, axis, legend, end in needed:
        if axis is not None and not name.endswith(FLAT_NOTE):
            room = LIVE_ROOM[0] * (axis[1] - axis[0])
            axis = (axis[0] - room, axis[1] + room)
        if end is not None:
            end = end + LIVE_ROOM[1] * (end - t0)
        out.append((name, axis, legend, end))
    return out


def y_axis(
    paths: tuple[str, ...],
    rule: str,
    ranges: dict[str, tuple[float, float, int]],
    t_range: tuple[float, float] | None = None,
    *,
    legend: bool = True,
):
    """(y range, flat, legend entries) of a time-series view from the logged values' ranges.

    ``ranges``: entity path → (min, max, number of series in it). The view's values are *flat* when
    their spread is at most :data:`FLAT_RTOL` × the view's scale (``rule``, see :func:`series_views`):
    round-off then sits on a fixed axis of ±10 % of the scale around the value, plus :data:`FLAT_PAD` (drawn as a flat line,
    ticks labelled with a few digits) and the title says so. Otherwise the axis holds the data with 5 %
    margins and head room above for the legend (:data:`LEGEND_ROW` per entry; none when ``legend`` is
    False: the title names the colours), the lower margin widened to keep a labelled tick off the lower
    edge (:func:`_clear_bottom`). None when nothing is logged.
    """
    members = [m for m in _members(paths, ranges) if m not in constant_terms(ranges)]
    if not members:
        return None, False, 0
    lo = min(ranges[m][0] for m in members)
    hi = max(ranges[m][1] for m in members)
    entries = sum(ranges[m][2] for m in members)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return None, False, entries
    big = max(abs(lo), abs(hi))
    if rule == "spin":
        cas = ranges.get("/series/casimir")
        big = max(big, float(np.sqrt(max(cas[1], 0.0))) if cas else 0.0)
    elif rule == "angle":
        big = max(big, float(np.pi))
    elif rule in ("relative", "unit"):
        big = max(big, 1.0)
    elif rule == "energy":
        h = ranges.get("/series/energy")
        big = max(big, max(abs(h[0]), abs(h[1])) if h else 0.0)
    elif rule == "power":
        h = ranges.get("/series/energy")
        if h and t_range and t_range[1] > t_range[0]:
            big = max(big, max(abs(h[0]), abs(h[1])) / (t_range[1] - t_range[0]))
    if rule == "residual":
        big = 0.0  # drawn as a signal however small: its size is the point (the title says it)
    if hi - lo <= FLAT_RTOL * big or hi == lo:
        half = nice_range(0.1 * big) if big > 0 else (nice_range(0.1 * abs(hi)) if hi else 1.0)
        step = half / 5.0
        c = round(0.5 * (lo + hi) / step) * step
        pad = FLAT_PAD * half  # the end ticks (c ± half) sit inside the view: their labels are not cut by its edges
        return (c - half - pad, c + half + pad), True, entries
    span = hi - lo
    if not legend:
        entries = 0
    top = hi + span * (0.05 + (LEGEND_ROW * entries + 0.05 if entries > 1 else 0.0))
    return (_clear_bottom(lo - 0.05 * span, top), top), False, entries


BOTTOM_CLEAR = 0.03
"""Least room (a fraction of the axis) between a view's lower edge and the lowest labelled tick above it."""


def _clear_bottom(bottom: float, top: float) -> float:
    """``bottom``, lowered where a tick that rerun labels (powers of ten, at most ~25 over the axis) sits
    less than :data:`BOTTOM_CLEAR` of the axis above it: rerun centres a y label on its tick, so a tick at
    the lower edge put its label on the time axis's labels (0.6 in the demo's λ, μ, ϱ view)."""
    span = top - bottom
    if not (span > 0 and np.isfinite(span)):
        return bottom
    step = 10.0 ** math.floor(math.log10(span))
    while span / step <= 25.0:
        tick = math.ceil(bottom / step - 1e-9) * step
        if tick - bottom < BOTTOM_CLEAR * (top - bottom):
            bottom = tick - BOTTOM_CLEAR * (top - tick) / (1.0 - BOTTOM_CLEAR)
        step /= 10.0
    return bottom


def view_specs(
    *, episode: bool, ranges: dict | None = None, t_range: tuple[float, float] | None = None
) -> list[tuple[str, str, tuple[str, ...]]]:
    """(view class, name, entity paths or origins) of every view :func:`blueprint` lays out, in order.

    The single source of the layout: :func:`blueprint` builds the views from it and the tests check
    the file against it. With the logged values' ``ranges`` (:func:`y_axis`) a time-series view whose
    values are round-off carries :data:`FLAT_NOTE` in its name.
    """
    specs = [
        ("3D", "plate, top view (lab +z)", ("/world",)),
        ("3D", "3-D view", ("/world",)),
        ("3D", "material frame: U(θ), G axes", ("/material",)),
        ("TextDocument", "G, C: numbers and eigenvalues", ("/tensors/numbers",)),
        ("TextDocument", "description: what each view shows", ("/description",)),
    ]
    for name, paths, rule in series_views(episode=episode):
        flat = bool(ranges) and y_axis(paths, rule, ranges, t_range)[1]
        specs.append(("TimeSeries", name + _notes(name, paths, ranges) + (FLAT_NOTE if flat else ""), paths))
    return specs


def series_axes(*, episode: bool, ranges: dict | None, t_range: tuple[float, float] | None) -> list[tuple]:
    """(name, y range, legend shown, time axis end) of every time-series view :func:`blueprint` draws,
    in layout order, from the logged values' ``ranges`` and the run's ``t_range``."""
    out = []
    for cls, name, _ in view_specs(episode=episode, ranges=ranges, t_range=t_range):
        if cls != "TimeSeries":
            continue
        base = base_title(name)
        sp, rule = {n: (p, r) for n, p, r in series_views(episode=episode)}[base]
        legend = not base.startswith(SHAPE_TITLE)
        axis, entries = None, len(sp)
        if ranges:
            axis, _, entries = y_axis(sp, rule, ranges, t_range, legend=legend)
        end = None if t_range is None else time_axis_end(t_range)
        out.append((name, axis, legend and entries > 1, end))
    return out


def blueprint(
    *,
    episode: bool,
    extent: float = 2.0,
    ranges: dict | None = None,
    t_range: tuple[float, float] | None = None,
    axes: list[tuple] | None = None,
    time_scale: float = 1.0,
):
    """The default blueprint of a recording.

    Parameters
    ----------
    episode : bool
        An env episode (adds the target, reward, distance, action and energy-balance views).
    extent : float
        The body's size (largest semi-axis expected); sets the cameras' distance.
    ranges : dict, optional
        Entity path → (min, max, series) of everything logged (the writer knows them when the whole
        recording is one block: a free scene, an episode): every time-series view then gets a fixed
        y axis (:func:`y_axis`: round-off drawn flat, room for the legend). None: axes follow the data.
    t_range : (float, float), optional
        The run's first and last ``sim_time``: every time axis shows the whole run.
    axes : list, optional
        The time-series views' axes when not :func:`series_axes` of ``ranges`` (a recording of several
        blocks: :func:`grow_axes`).
    time_scale : float
        Seconds of ``sim_time`` per model time unit (:func:`time_unit`).
    """
    import rerun.blueprint as rrb

    series = {name: (paths, rule) for name, paths, rule in series_views(episode=episode)}
    specs = view_specs(episode=episode, ranges=ranges, t_range=t_range)
    if axes is None:
        axes = series_axes(episode=episode, ranges=ranges, t_range=t_range)
    axes = {name: (axis, legend, end) for name, axis, legend, end in axes}

    def view(cls: str, name: str, paths: tuple[str, ...]):
        if cls == "3D":
            kind = camera_kind(name)
            contents = [paths[0] + "/**"]
            if kind == "top":  # seen from +z the ϱ axis is a point at the centre: its label would sit on μ's
                contents.append("- /world/labels/normal")
            return rrb.Spatial3DView(
                name=name,
                origin=paths[0],
                contents=contents,
                eye_controls=camera(kind, extent),
                line_grid=rrb.LineGrid3D(visible=kind != "top", spacing=0.5),
            )
        if cls == "TextDocument":
            return rrb.TextDocumentView(name=name, origin=paths[0])
        sp, _ = series[base_title(name)]
        contents = [c for p in sp for c in (p, p + "/**")]
        contents += [f"- {p}" for p in constant_terms(ranges) if any(p.startswith(q + "/") for q in sp)]
        axis, legend, end = axes[name]
        return _series_view(name, contents, axis=axis, legend=legend, t_range=t_range, end=end, scale=time_scale)

    views = [view(*s) for s in specs]
    top_row = rrb.Horizontal(
        views[0], rrb.Tabs(views[1], views[2], active_tab=0), views[3], views[4], column_shares=[3, 3, 2.2, 2.6]
    )
    shape, rest = views[5], views[6:]
    # episode: distance (the criterion, in front), reward, actions | the balance over its residual (both on screen),
    # power, …; free: drift, H | s₃, …
    k = 3 if episode else 2
    middle = rrb.Tabs(*rest[:k], active_tab=0)
    if episode:
        right = rrb.Vertical(rest[k], rrb.Tabs(*rest[k + 1 :], active_tab=0), row_shares=[1.5, 1])
    else:
        right = rrb.Tabs(*rest[k:], active_tab=0)
    bottom_row = rrb.Horizontal(shape, middle, right, column_shares=[1, 1, 1])
    return rrb.Blueprint(
        rrb.Vertical(top_row, bottom_row, row_shares=[1, BOTTOM_ROW_SHARE]),
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
    "Green tensor G (material frame) and Cauchy tensor C (laboratory): their entries over time are "
    "the tabs *G entries* and *C entries*."
)
"""One step of :func:`tensor_text`: 1 + 2 × 12 numbers."""

_SEP = "\x00"  # joins the steps' texts for one formatting call; no number or label contains it


def tensor_text(t: np.ndarray, G: np.ndarray, C: np.ndarray, half: np.ndarray) -> list[str]:
    """Markdown, one per step: G and C as numbers with their eigenvalues.

    The eigenvalues are λ², μ², ϱ² for G and 1/λ², 1/μ², 1/ϱ² for C (eq. (35) of the paper; C per
    the corrected eq. (51) remark in ``docs/physics.md``), computed from the semi-axes ``half``
    (n, 3). All steps are formatted in one ``%`` call over a table of their numbers (the per-step
    text is the same as formatting each alone).

    (G and C are shown as numbers only: rerun 0.41's tensor view covers a 3×3 heat map with its
    row/column selectors and has no colour key, so a heat map of them could not be read.)
    """
    t = np.asarray(t, dtype=np.float64).ravel()
    n = t.size
    if n == 0:
        return []
    half = np.asarray(half, dtype=np.float64).reshape(n, 3)
    sq = half * half
    cols = [t[:, None]]
    for M, eig in (
        (np.asarray(G, dtype=np.float64).reshape(n, 3, 3), sq),
        (np.asarray(C, dtype=np.float64).reshape(n, 3, 3), 1 / sq),
    ):
        cols.append(np.concatenate([M, eig[:, :, None]], axis=2).reshape(n, 12))
    return ((_TENSOR_TEXT + _SEP) * n % tuple(np.concatenate(cols, axis=1).ravel().tolist())).split(_SEP)[:n]


def axis_labels(half: np.ndarray) -> list[str]:
    """Labels of the principal-axis arrows, three per step: ``λ = 1.203`` … — the arrows' lengths."""
    half = np.asarray(half, dtype=np.float64).reshape(-1, 3)
    n = half.shape[0]
    if n == 0:
        return []
    return (("λ = %.3f" + _SEP + "μ = %.3f" + _SEP + "ϱ = %.3f" + _SEP) * n % tuple(half.ravel().tolist())).split(_SEP)[
        : 3 * n
    ]


def description_markdown(
    title: str, body, extra: str, *, episode: bool, outcome: str | None = None, time_note: str = ""
) -> str:
    """The ``/description`` document: the title and, for an episode once it has ended, its outcome first (what a
    reader looks for), then what is recorded (``extra``: the scene or the env and its target), the body and what
    each view shows. ``time_note``: how to read the time axes (:func:`time_unit`)."""
    try:
        desc = body.describe()
    except AttributeError:  # a duck-typed body without describe()
        desc = repr(body)
    head = f"# {title}\n\n" + (f"**{outcome}**\n\n" if outcome else "")
    balance = (
        "\n* **energy balance** — the controls u = (τ₁, τ₂, τ₃, f_ϱ) change H on purpose: H − H₀ (wide, olive) and the"
        " work W = ∫P dt of the control (thin, light blue, inside it), P = ω·τ + ϱ̇ f_ϱ; **residual H − H₀ − W** on its"
        " own scale (its largest size in the title); **control power** P̄, P's mean over each step. **distance** to the"
        " target with the success tolerance (in front: the task's criterion), the **reward terms** (a term constant"
        " over the episode is named in the title, not drawn) and the **actions** in [−1, 1], drawn at the step they"
        " lead to."
        if episode
        else "\n* **conserved: drift** — (Q − Q₀)/|Q₀| of H, |s|² and p_θ, which the free motion conserves; the title"
        " gives the largest of each."
    )
    when = f"**Time axis**: {time_note}.\n\n" if time_note and "1 s" not in time_note else ""
    text = f"""{head}{extra.strip() + chr(10) + chr(10) if extra else ""}{when}A flat affinely-rigid body with thickness (V. Kovalchuk & E. E. Rożko, arXiv:0902.3573; corrections in
`docs/physics.md`). Body: {desc}. Configuration Φ = R · diag(λ, μ, ϱ) · U(θ)⁻¹ (eqs. (23)–(24)).

**What each view shows** (scrub the time bar at the bottom; tabs hold more plots):

* **plate, top view** — the body seen down the lab's z axis: blue-grey wireframe ellipsoid with semi-axes λ, μ, ϱ
  along the columns of R; grey material lines (the gold spoke is the fibre e₁) drawn under Φ. Arrows: the principal
  axes of C = Φ⁻ᵀΦ⁻¹ (λ red, μ green; ϱ blue points at you and is labelled in the 3-D view), **length = the number on
  their label**.{" Magenta: the target ellipse (λ*, μ*) along the body's current axes." if episode else ""}
* **3-D view** — the same from above the plate; **material frame** — the undeformed body and G^½(ball).
* **G, C: numbers** — both tensors and their eigenvalues (λ², μ², ϱ² and their inverses) at the current time.
* **time plots** — {time_note or "model time on the time axis"}; every plot shows the whole run, the white line is the
  current time; a plot constant to 1 part in 10⁸ (round-off) is drawn flat and says so.
  λ, μ, ϱ{" (targets λ*, μ*, ϱ*: wide faint bands)" if episode else ""}; s₃, p_θ, θ, H (eq. (41)), |s|², G and C.{balance}

One colour per variable (λ red, μ green, ϱ blue, θ cyan, s₃ purple, p_θ orange, H olive, |s|² brown); actions,
reward terms and the energy balance have colours of their own. Timelines: `sim_time` (model time) and `step`.
"""
    return text


def material_line_colors(spokes: int) -> np.ndarray:
    """RGBA of the material lines: rim and spokes grey (readable on dark and light themes), the
    fibre along e₁ gold, the normal blue."""
    colors = np.tile(np.array([rgba(COLORS["material"])], dtype=np.uint8), (spokes + 2, 1))
    colors[1] = rgba(COLORS["fibre"])
    colors[-1] = rgba(COLORS["normal"])
    return colors
