"""The one figure helper of every chart: size, fonts, palette, legends, captions, layout and saving.

Every chart function of the project (the analysis charts, the agents' charts, the benchmarks' charts) draws
inside :func:`chart`::

    with chart(png_path, size=(7.5, 4.2), ncols=2) as c:
        c.axes[0, 0].plot(...)                       # c.ax is the first axes
        c.legend(where="below", ncol=4)              # optional: one figure legend under the axes
        c.caption(CAPTION)                           # the jargon explained, under everything
        c.title("...")                               # the figure's title
    # leaving the block: the layout leaves the title, legend and caption their measured room, the PNG is
    # written atomically at DPI (its folder made if missing), the figure is closed

House style (applied while the chart is drawn, so nothing else in the process changes): the fonts of
:data:`FONTS`, the colour cycle :data:`CYCLE` and the named colours of :data:`PALETTE`, the resolution
:data:`DPI`, the light grid. Rule: every chart explains its own jargon in the figure itself — in a legend
entry or in the caption (:meth:`Chart.caption`) — and no text lies under a legend, over a data marker or
outside the figure (:func:`layout_problems`, which the tests run on every committed chart). matplotlib only
(the Agg backend); the file is written by :func:`flatbody_env.output.save_figure`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

DPI = 120
"""Resolution of every chart (pixels per inch)."""

FONTS = {"base": 9.0, "small": 8.0, "tiny": 7.0, "caption": 7.5, "title": 10.0, "suptitle": 10.5}
"""Font sizes (points): text, tick labels and legends, dense labels, captions, axes titles, figure titles."""

CYCLE = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)
"""The colour cycle (matplotlib's tab10: distinct in print and for the common colour-vision deficiencies
when paired with markers or line styles)."""

PALETTE = {
    "ours": "#1f77b4",
    "yardstick": "#7f7f7f",
    "reference": "#000000",
    "goal": "#555555",
    "good": "#2ca02c",
    "bad": "#d62728",
    "band": "0.88",
    "neutral": "0.8",
}
"""Named colours: flatbody's own rows, the yardsticks it is compared with, a reference line, a goal line,
better / worse, a shaded band (e.g. below a reference's floor), a faint connecting line."""

CAPTION_GID = "caption"
"""``gid`` of caption texts (:func:`caption_text` finds them)."""

_RC = {
    "font.size": FONTS["base"],
    "axes.titlesize": FONTS["title"],
    "axes.labelsize": FONTS["base"],
    "xtick.labelsize": FONTS["small"],
    "ytick.labelsize": FONTS["small"],
    "legend.fontsize": FONTS["small"],
    "legend.title_fontsize": FONTS["small"],
    "figure.titlesize": FONTS["suptitle"],
    "grid.alpha": 0.3,
    "legend.framealpha": 0.92,
    "figure.dpi": DPI,
    "savefig.dpi": DPI,
}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _rc() -> dict[str, Any]:
    from cycler import cycler

    return {**_RC, "axes.prop_cycle": cycler(color=list(CYCLE))}


# --------------------------------------------------------------------------------------------- captions
def caption_height(fig, text: str, fontsize: float = FONTS["caption"]) -> float:
    """The fraction of ``fig``'s height that a caption of ``text`` takes."""
    lines = text.count("\n") + 1
    return (lines * fontsize * 1.32 + 8.0) / 72.0 / fig.get_figheight()


def wrap_to_width(text: str, width_in: float, fontsize: float) -> str:
    """``text`` with each of its lines wrapped to fit ``width_in`` inches at ``fontsize`` points (an average glyph of
    the sans-serif font is taken as 0.56 of the size wide; the caller's line breaks are kept)."""
    import textwrap

    chars = max(20, int((width_in * 72.0 - 10.0) / (0.56 * fontsize)))
    return "\n".join(
        "\n".join(textwrap.wrap(line, chars, break_on_hyphens=False)) if len(line) > chars else line
        for line in text.split("\n")
    )


def add_caption(fig, text: str, *, fontsize: float = FONTS["caption"], bottom: float = 0.0) -> float:
    """Write ``text`` (lines broken by the caller) at the bottom left of ``fig``, above ``bottom`` (a fraction of
    the figure's height); return the fraction of the height it takes, ``bottom`` included."""
    fig.text(
        0.008,
        bottom + 3.0 / 72.0 / fig.get_figheight(),
        text,
        ha="left",
        va="bottom",
        fontsize=fontsize,
        color="0.2",
        gid=CAPTION_GID,
        linespacing=1.25,
    )
    return bottom + caption_height(fig, text, fontsize)


def caption_text(fig) -> str:
    """The caption(s) of ``fig`` (texts with gid :data:`CAPTION_GID`), joined by newlines."""
    return "\n".join(t.get_text() for t in fig.texts if t.get_gid() == CAPTION_GID)


def all_text(fig) -> str:
    """Every visible text of ``fig`` (titles, labels, legends, annotations, captions), joined by newlines."""
    from matplotlib.text import Text

    return "\n".join(t.get_text() for t in fig.findobj(Text) if t.get_visible() and t.get_text())


# --------------------------------------------------------------------------------------------- the chart
@dataclass
class Chart:
    """A figure being drawn inside :func:`chart`: its axes and what goes around them.

    Attributes
    ----------
    fig : matplotlib.figure.Figure
    axes : numpy.ndarray of Axes
        Always two-dimensional (``nrows`` × ``ncols``).
    """

    fig: Any
    axes: Any
    _caption: tuple[str, float] | None = None
    _legend: dict[str, Any] | None = None
    _title: tuple[str, float] | None = None
    _extra: list[Any] = field(default_factory=list)

    @property
    def ax(self):
        """The first (or only) axes."""
        return self.axes[0, 0]

    def caption(self, text: str, *, fontsize: float = FONTS["caption"]) -> None:
        """The caption under everything: the chart's jargon explained. The caller's line breaks are kept; a line
        wider than the figure is wrapped (:func:`wrap_to_width`)."""
        self._caption = (wrap_to_width(text, self.fig.get_figwidth(), fontsize), fontsize)

    def title(self, text: str, *, fontsize: float = FONTS["suptitle"]) -> None:
        """The figure's title, above every axes."""
        self._title = (text, fontsize)

    def legend(
        self,
        handles: Sequence[Any] | None = None,
        labels: Sequence[str] | None = None,
        *,
        where: str = "below",
        ncol: int = 1,
        fontsize: float = FONTS["small"],
        title: str | None = None,
    ) -> None:
        """One legend for the whole figure, outside every axes (so it covers no data): ``where`` "below" (between
        the axes and the caption, ``ncol`` columns) or "right" (beside the axes, one column). Without ``handles``,
        the labelled artists of every axes, each label once."""
        if where not in ("below", "right"):
            raise ValueError(f"where: expected 'below' or 'right', got {where!r}")
        if handles is None:
            handles, labels = [], []
            for ax in self.axes.flat:
                for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
                    if lab not in labels:
                        handles.append(h)
                        labels.append(lab)
        self._legend = {
            "handles": list(handles),
            "labels": list(labels),
            "where": where,
            "ncol": ncol,
            "fontsize": fontsize,
            "title": title,
        }

    def _layout(self) -> None:
        """Title, legend and caption placed and measured, the axes laid out in the room left between them."""
        fig = self.fig
        height = fig.get_figheight() * fig.dpi
        width = fig.get_figwidth() * fig.dpi
        bottom, top, right = 0.0, 1.0, 1.0
        if self._caption is not None:
            bottom = add_caption(fig, self._caption[0], fontsize=self._caption[1])
        if self._title is not None:  # tight_layout leaves a figure title its room itself
            fig.suptitle(self._title[0], fontsize=self._title[1], y=0.995, va="top")
        lg = self._legend
        if lg is not None and lg["handles"]:
            if lg["where"] == "below":
                legend = fig.legend(
                    lg["handles"],
                    lg["labels"],
                    loc="lower center",
                    bbox_to_anchor=(0.5, bottom),
                    ncol=lg["ncol"],
                    fontsize=lg["fontsize"],
                    frameon=False,
                    title=lg["title"],
                )
                bottom += (legend.get_window_extent(fig.canvas.get_renderer()).height + 4.0) / height
            else:
                legend = fig.legend(
                    lg["handles"],
                    lg["labels"],
                    loc="upper right",
                    bbox_to_anchor=(1.0, top),
                    ncol=1,
                    fontsize=lg["fontsize"],
                    frameon=False,
                    title=lg["title"],
                )
                right = 1.0 - (legend.get_window_extent(fig.canvas.get_renderer()).width + 6.0) / width
        fig.tight_layout(rect=(0.0, bottom, right, top), pad=0.6)

    def save(self, png_path: str | os.PathLike) -> Path:
        """Lay out and write the PNG (its folder made if missing); :func:`chart` calls this on leaving."""
        from flatbody_env.output import save_figure

        self._layout()
        png = Path(png_path)
        png.parent.mkdir(parents=True, exist_ok=True)
        return save_figure(self.fig, png, dpi=DPI)


@contextlib.contextmanager
def chart(
    png_path: str | os.PathLike, *, size: tuple[float, float], nrows: int = 1, ncols: int = 1, **subplots: Any
) -> Iterator[Chart]:
    """Draw a chart of ``nrows`` × ``ncols`` axes, ``size`` (width, height) inches, in the house style; on leaving
    the block it is laid out, written to ``png_path`` (module docstring) and closed. ``subplots``: further keywords of
    ``plt.subplots`` (``sharex``, ``gridspec_kw``, ...)."""
    import matplotlib

    plt = _pyplot()
    with matplotlib.rc_context(_rc()):
        fig, axes = plt.subplots(nrows, ncols, figsize=size, squeeze=False, **subplots)
        try:
            c = Chart(fig=fig, axes=axes)
            yield c
            c.save(png_path)
        finally:
            plt.close(fig)


def fraction_axis(ax, label: str | None, *, margin: float = 0.03) -> None:
    """A rate's axis (success, share): 0 % to 100 % with ``margin`` of room, ticks every 20 % (never a tick above
    100 %, never an axis squeezed around one value), labelled ``label`` (None: no label)."""
    from matplotlib.ticker import FixedLocator, PercentFormatter

    ax.set_ylim(-margin, 1.0 + margin)
    ax.yaxis.set_major_locator(FixedLocator([0.0, 0.2, 0.4, 0.6, 0.8, 1.0]))
    ax.yaxis.set_major_formatter(PercentFormatter(1.0, decimals=0))
    if label is not None:
        ax.set_ylabel(label)


def log_axis_if_decades(ax, values, *, axis: str = "x", decades: float = 2.0) -> bool:
    """Put ``axis`` of ``ax`` on a log scale when every value is positive and they span more than ``decades``
    decades (a family over J from 1e-6 to 1e6 on a linear axis shows one point); returns whether it did."""
    import numpy as np

    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size < 2 or np.any(v <= 0) or np.log10(v.max() / v.min()) <= decades:
        return False
    (ax.set_xscale if axis == "x" else ax.set_yscale)("log")
    return True


# --------------------------------------------------------------------------------------------- layout check
def _undrawn_tick_labels(fig) -> set[int]:
    """ids of the tick labels matplotlib keeps but does not draw (ticks outside the view limits)."""
    import numpy as np

    out = set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            scale = axis.get_transform()  # compared in the axis's own scale (a log axis spans decades)
            lo, hi = sorted(float(v) for v in scale.transform(np.asarray(axis.get_view_interval(), dtype=float)))
            slack = 1e-9 * max(hi - lo, 1e-300)
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                loc = tick.get_loc()
                where = None if loc is None else float(scale.transform(np.array([float(loc)]))[0])
                if where is None or not np.isfinite(where) or not lo - slack <= where <= hi + slack:
                    out.update({id(tick.label1), id(tick.label2)})
    return out


def _texts(fig):
    from matplotlib.text import Text

    skip = _undrawn_tick_labels(fig)
    return [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip() and id(t) not in skip]


def _along(xy, step: float = 2.0):
    """Points every ``step`` pixels along the polyline ``xy`` (pixels; NaN breaks it)."""
    import numpy as np

    out = [xy[np.isfinite(xy).all(axis=1)]]
    for a, b in zip(xy[:-1], xy[1:], strict=True):
        if np.isfinite(a).all() and np.isfinite(b).all():
            n = int(min(np.hypot(*(b - a)) / step, 5000))
            if n > 1:
                t = np.linspace(0.0, 1.0, n)[:, None]
                out.append(a + t * (b - a))
    return np.concatenate(out) if out else np.empty((0, 2))


def _data_points(ax, *, lines: bool = False) -> list[Any]:
    """Pixel positions of the data of ``ax``: line vertices with markers, scatter offsets, error-bar caps; with
    ``lines``, also points along every drawn line (a legend must not hide a curve either)."""
    import numpy as np
    from matplotlib.collections import PathCollection

    out = []
    for line in ax.lines:
        if not line.get_visible():
            continue
        xy = np.asarray(line.get_xydata(), dtype=float)
        if not xy.size:
            continue
        pix = line.get_transform().transform(xy)
        if line.get_marker() not in (None, "", " ", "None", "none"):
            out.append((pix, line.get_markersize() * ax.figure.dpi / 72.0 / 2.0))
        if lines and line.get_linestyle() not in ("None", "none", "", " ") and len(pix) > 1:
            out.append((_along(pix), line.get_linewidth() * ax.figure.dpi / 72.0 / 2.0))
    for coll in ax.collections:
        if isinstance(coll, PathCollection) and coll.get_visible():
            xy = np.asarray(coll.get_offsets(), dtype=float)
            if xy.size:
                sizes = coll.get_sizes()
                r = (float(np.sqrt(sizes.max())) if len(sizes) else 6.0) * ax.figure.dpi / 72.0 / 2.0
                out.append((coll.get_offset_transform().transform(xy), r))
    return out


def layout_problems(fig, *, tol: float = 1.0) -> list[str]:
    """Layout defects of a drawn figure, measured with the renderer's window extents (pixels):

    * a text (title, label, tick label, annotation, caption) reaching outside the figure;
    * an annotation (a text drawn on an axes: ``ax.text``/``ax.annotate``) reaching outside its axes' frame;
    * a text that is not part of a legend overlapping a legend's box;
    * a legend drawn inside an axes covering data of that axes (a marker, a scatter point, a curve);
    * two annotations overlapping each other, or an annotation over a data marker of its axes.
    """
    from matplotlib.legend import Legend

    fig.canvas.draw()
    texts = _texts(fig)
    renderer = fig.canvas.get_renderer()
    fbox = fig.bbox
    legends = [lg for lg in fig.findobj(Legend) if lg.get_visible()]
    in_legend = {id(t) for lg in legends for t in lg.findobj()}
    problems = []

    def name(t):
        return repr(t.get_text()[:40])

    for t in texts:
        bb = t.get_window_extent(renderer)
        if bb.x0 < fbox.x0 - tol or bb.y0 < fbox.y0 - tol or bb.x1 > fbox.x1 + tol or bb.y1 > fbox.y1 + tol:
            problems.append(
                f"text {name(t)} reaches outside the figure ({bb.x0:.0f}..{bb.x1:.0f} x {bb.y0:.0f}..{bb.y1:.0f} "
                f"of {fbox.width:.0f} x {fbox.height:.0f})"
            )
        if id(t) in in_legend:
            continue
        for lg in legends:
            lb = lg.get_window_extent(renderer)
            if bb.overlaps(lb) and bb.intersection(bb, lb).width > tol and bb.intersection(bb, lb).height > tol:
                problems.append(f"text {name(t)} lies under a legend")
    for ax in fig.axes:
        ab = ax.get_window_extent(renderer)
        notes = [t for t in ax.texts if t.get_visible() and t.get_text().strip()]
        boxes = [t.get_window_extent(renderer) for t in notes]
        for t, bb in zip(notes, boxes, strict=True):
            if bb.x0 < ab.x0 - tol or bb.y0 < ab.y0 - tol or bb.x1 > ab.x1 + tol or bb.y1 > ab.y1 + tol:
                problems.append(f"annotation {name(t)} is cut by its axes' frame")
        for i in range(len(notes)):
            for j in range(i + 1, len(notes)):
                inter = boxes[i].intersection(boxes[i], boxes[j])
                if inter is not None and inter.width > tol and inter.height > tol:
                    problems.append(f"annotations {name(notes[i])} and {name(notes[j])} overlap")
        points, curves = _data_points(ax), _data_points(ax, lines=True)
        legend = ax.get_legend()
        inner = [(f"the legend of {ax.get_title()[:30]!r}", legend.get_window_extent(renderer))] if legend else []
        checks = [(f"annotation {name(t)}", b, points) for t, b in zip(notes, boxes, strict=True)]
        for what, bb, data in checks + [(w, b, curves) for w, b in inner]:
            for xy, r in data:
                hit = (
                    (xy[:, 0] + r > bb.x0 + tol)
                    & (xy[:, 0] - r < bb.x1 - tol)
                    & (xy[:, 1] + r > bb.y0 + tol)
                    & (xy[:, 1] - r < bb.y1 - tol)
                )
                if hit.any():
                    problems.append(
                        f"{what} covers " + ("a data marker" if data is points else "data (a marker or a curve)")
                    )
                    break
    return problems


__all__ = [
    "CAPTION_GID",
    "CYCLE",
    "Chart",
    "DPI",
    "FONTS",
    "PALETTE",
    "add_caption",
    "all_text",
    "caption_height",
    "caption_text",
    "chart",
    "fraction_axis",
    "layout_problems",
    "log_axis_if_decades",
    "wrap_to_width",
]
