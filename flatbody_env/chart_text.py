"""Captions and layout checks shared by the charts (matplotlib; no drawing backend chosen here).

House rule: every chart explains its own jargon in the figure itself — in a legend entry or in a
caption under the axes (:func:`add_caption`) — and no text lies under a legend or outside the figure
(:func:`layout_problems`, used by the tests).

* :func:`add_caption` — a left-aligned caption at the bottom of the figure; returns the fraction of
  the figure's height it takes, to pass to ``tight_layout(rect=(0, frac, 1, top))``.
* :func:`layout_problems` — after drawing: texts outside the figure, annotations outside their axes,
  texts under a legend, annotations overlapping each other (empty list when the layout is clean).
"""

from __future__ import annotations

CAPTION_GID = "caption"
"""``gid`` of the caption text (tests find it with :func:`caption_text`)."""


def caption_height(fig, text: str, fontsize: float = 7.5) -> float:
    """The fraction of ``fig``'s height that :func:`add_caption` takes for ``text``."""
    lines = text.count("\n") + 1
    return (lines * fontsize * 1.32 + 8.0) / 72.0 / fig.get_figheight()


def add_caption(fig, text: str, *, fontsize: float = 7.5, bottom: float = 0.0) -> float:
    """Write ``text`` (lines broken by the caller) at the bottom left of ``fig``, above ``bottom`` (a
    fraction of the figure's height); return the fraction of the height it takes, ``bottom`` included."""
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


def _undrawn_tick_labels(fig) -> set[int]:
    """ids of the tick labels matplotlib keeps but does not draw (ticks outside the view limits)."""
    out = set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            slack = 1e-9 * max(abs(lo), abs(hi), 1e-300)
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                loc = tick.get_loc()
                if loc is None or not lo - slack <= loc <= hi + slack:
                    out.update({id(tick.label1), id(tick.label2)})
    return out


def _texts(fig):
    from matplotlib.text import Text

    skip = _undrawn_tick_labels(fig)
    return [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip() and id(t) not in skip]


def layout_problems(fig, *, tol: float = 1.0) -> list[str]:
    """Layout defects of a drawn figure, measured with the renderer's window extents (pixels):

    * a text (title, label, tick label, annotation, caption) reaching outside the figure;
    * an annotation (a text drawn on an axes: ``ax.text``/``ax.annotate``) reaching outside its axes' frame;
    * a text that is not part of a legend overlapping a legend's box;
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
        for t, bb in zip(notes, boxes):
            if bb.x0 < ab.x0 - tol or bb.y0 < ab.y0 - tol or bb.x1 > ab.x1 + tol or bb.y1 > ab.y1 + tol:
                problems.append(f"annotation {name(t)} is cut by its axes' frame")
        for i in range(len(notes)):
            for j in range(i + 1, len(notes)):
                inter = boxes[i].intersection(boxes[i], boxes[j])
                if inter is not None and inter.width > tol and inter.height > tol:
                    problems.append(f"annotations {name(notes[i])} and {name(notes[j])} overlap")
        for line in ax.lines:
            if not line.get_visible() or line.get_marker() in (None, "", " ", "None", "none"):
                continue
            r = line.get_markersize() * fig.dpi / 72.0 / 2.0
            xy = line.get_transform().transform(line.get_xydata())
            for t, bb in zip(notes, boxes):
                hit = (
                    (xy[:, 0] + r > bb.x0 + tol)
                    & (xy[:, 0] - r < bb.x1 - tol)
                    & (xy[:, 1] + r > bb.y0 + tol)
                    & (xy[:, 1] - r < bb.y1 - tol)
                )
                if hit.any():
                    problems.append(f"annotation {name(t)} covers a data marker")
    return problems


__all__ = ["CAPTION_GID", "add_caption", "all_text", "caption_height", "caption_text", "layout_problems"]
