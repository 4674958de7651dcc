"""Frames for ``render_mode="rgb_array"``: the plate seen from the laboratory's +z axis, and the colours
every picture of the body shares (these frames and the rerun recordings' views).

Drawn with aggdraw on Pillow images (both declared in pyproject for this module). The plate is
the ellipse Φ·(unit disc) = R·diag(λ, μ)·(unit circle) projected on the laboratory x–y plane
(eq. (23) of the paper), filled with a shade that darkens with the thickness ϱ; its principal
semi-axes are drawn in the colours of λ (red) and μ (green), the material fibre Φe₁ in gold (it
turns inside the ellipse with U(θ), eq. (24)), and the target ellipse (λ*, μ*) is outlined in
magenta along the current principal axes — the same colours as the top-down view of a recording.

Anti-aliasing: the shapes are drawn with aggdraw (Anti-Grain Geometry, sub-pixel coverage) — a
supersampled Pillow drawing cost several milliseconds a frame; the text (time, ϱ, scale) is Pillow's
bitmap font and the legend a cached image. The view's half-width is a "nice"
number (1, 1.5, 2, 3, 4, 5, 6, 8, 10, …) that holds 1.25 × the target's larger semi-axis, so it
stays fixed through an episode, and grows (never clips) when the body stretches beyond it; a scale
bar gives the length unit.
"""

from __future__ import annotations

import math

import numpy as np

SIZE = 256
"""Frame side in pixels."""

COLORS: dict[str, tuple[int, int, int]] = {
    "lambda": (214, 39, 40),
    "mu": (44, 160, 44),
    "rho": (31, 119, 180),
    "theta": (23, 170, 190),
    "s3": (148, 103, 189),
    "p_theta": (255, 127, 14),
    "energy": (188, 170, 34),
    "casimir": (140, 86, 75),
    "distance": (127, 127, 127),
    "target": (220, 40, 200),
    "plate": (120, 160, 230),
    "plate_edge": (25, 45, 120),
    "fibre": (225, 170, 0),
    "material": (140, 140, 140),
    "normal": (110, 110, 255),
}
"""One colour per quantity (RGB), shared by the rerun views (series, arrows, outlines) and these frames:
λ red, μ green, ϱ blue (also the principal axes e₁, e₂, e₃ of the body), θ cyan, s₃ purple, p_θ orange,
H olive, |s|² brown, the distance grey, the target outline magenta, the material fibre e₁ gold."""

_NICE = (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0)


def nice_half_width(extent: float) -> float:
    """The smallest "nice" number (1, 1.5, 2, 3, 4, 5, 6, 8 × 10ᵏ) ≥ ``extent`` (> 0)."""
    if not (extent > 0.0 and math.isfinite(extent)):
        raise ValueError(f"extent: must be a finite number > 0, got {extent!r}")
    k = math.floor(math.log10(extent))
    for m in _NICE:
        v = m * 10.0**k
        if v >= extent * (1.0 - 1e-12):
            return v
    return 10.0 ** (k + 1)


def view_half_width(lam: float, mu: float, target: dict | None) -> float:
    """Half-width of the frame's view: nice ≥ 1.25 × the target's larger semi-axis (fixed through an
    episode), widened to hold 1.1 × the body's larger semi-axis when it stretches beyond."""
    ref = 0.0
    if target:
        ref = 1.25 * max(float(target.get("lambda", 0.0)), float(target.get("mu", 0.0)))
    need = max(ref, 1.1 * max(lam, mu), 1e-3)
    return nice_half_width(need)


_ANG = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
_CIRCLE = np.stack([np.cos(_ANG), np.sin(_ANG)])


def _scale_bar_length(half: float) -> float:
    """The largest "nice" length ≤ half the view's half-width (a bar ≤ a quarter of the frame)."""
    k = math.floor(math.log10(half / 2.0))
    return max(m * 10.0**k for m in _NICE if m * 10.0**k <= half / 2.0 * (1.0 + 1e-12))


_FONT = None
_LEGEND: tuple[np.ndarray, np.ndarray] | None = None
_BACKGROUND = (250, 250, 250)
_INK = np.array([20, 20, 20], dtype=np.uint8)


def _font():
    """Pillow's built-in bitmap font (fast: no FreeType rasterising per frame), loaded once."""
    global _FONT
    if _FONT is None:
        from PIL import ImageFont

        _FONT = ImageFont.load_default_imagefont() if hasattr(ImageFont, "load_default_imagefont") else ImageFont.load_default()
    return _FONT


def _text_mask(text: str) -> np.ndarray:
    """Boolean mask (h, w) of ``text`` in the bitmap font."""
    from PIL import Image, ImageDraw

    font = _font()
    box = font.getbbox(text)
    img = Image.new("L", (box[2] + 1, box[3] + 1), 0)
    ImageDraw.Draw(img).text((0, 0), text, fill=255, font=font)
    return np.asarray(img) > 127


def _put(frame: np.ndarray, mask: np.ndarray, colors: np.ndarray, x: int, y: int) -> None:
    """Paint ``colors`` (h, w, 3 or 3) where ``mask`` (h, w) is set, with its top-left at (x, y), clipped."""
    h = min(mask.shape[0], frame.shape[0] - y)
    w = min(mask.shape[1], frame.shape[1] - x)
    if h <= 0 or w <= 0:
        return
    m = mask[:h, :w]
    region = frame[y : y + h, x : x + w]
    region[m] = colors[:h, :w][m] if colors.ndim == 3 else colors


def _legend() -> tuple[np.ndarray, np.ndarray]:
    """The static legend (λ axis, μ axis, target, fibre e₁) as a mask and its colours, built once."""
    global _LEGEND
    if _LEGEND is None:
        rows = (("lambda", "lambda axis"), ("mu", "mu axis"), ("target", "target"), ("fibre", "fibre e1"))
        h, w = 12 * len(rows), 80
        mask = np.zeros((h, w), dtype=bool)
        colors = np.zeros((h, w, 3), dtype=np.uint8)
        for i, (name, label) in enumerate(rows):
            y = 12 * i
            mask[y + 4 : y + 6, 0:12] = True
            colors[y + 4 : y + 6, 0:12] = COLORS[name]
            tm = _text_mask(label)[:12, : w - 16]
            mask[y : y + tm.shape[0], 16 : 16 + tm.shape[1]] |= tm
            colors[y : y + tm.shape[0], 16 : 16 + tm.shape[1]][tm] = _INK
        _LEGEND = (mask, colors)
    return _LEGEND


def render_frame(y: np.ndarray, R: np.ndarray, target: dict, t: float, *, half_width: float | None = None) -> np.ndarray:
    """An RGB frame of the plate seen from +z, shape (256, 256, 3), dtype uint8.

    Parameters
    ----------
    y : array (11,)
        The state (``flatbody_env.physics.state.STATE_NAMES`` order: λ, μ, ϱ, θ are entries 7–10).
    R : array (3, 3)
        The rotation R(t) of eq. (23).
    target : dict
        The target (``lambda``, ``mu`` used; empty for none).
    t : float
        Simulated time, printed in the corner.
    half_width : float, optional
        Half-width of the view in length units (default :func:`view_half_width`).
    """
    import aggdraw

    lam, mu, rho, theta = float(y[7]), float(y[8]), float(y[9]), float(y[10])
    R2 = np.asarray(R, dtype=np.float64)[:2, :2]
    half = view_half_width(lam, mu, target) if half_width is None else float(half_width)
    scale = SIZE / (2.0 * half)  # pixels per unit length
    c0 = SIZE / 2.0

    def px(xy: np.ndarray) -> list[float]:
        return np.stack([c0 + scale * xy[0], c0 - scale * xy[1]], axis=1).ravel().tolist()

    canvas = aggdraw.Draw("RGB", (SIZE, SIZE), _BACKGROUND)
    # plate: R·diag(λ, μ)·circle, shaded darker for a thicker plate (ϱ = 1: the palette's tone)
    k = float(np.clip(0.5 + 0.5 * math.tanh(1.5 * (rho - 1.0)), 0.0, 1.0))
    fill = tuple(int(v) for v in np.clip(np.array(COLORS["plate"], dtype=float) * (1.25 - 0.5 * k), 0, 255))
    canvas.polygon(px(R2 @ (np.array([[lam], [mu]]) * _CIRCLE)), aggdraw.Pen(COLORS["plate_edge"], 1.2), aggdraw.Brush(fill))
    # principal semi-axes (columns of R, lengths λ, μ) in the colours of λ and μ
    for col, (length, name) in enumerate(((lam, "lambda"), (mu, "mu"))):
        end = R2[:, col] * length
        canvas.line(px(np.array([[0.0, end[0]], [0.0, end[1]]])), aggdraw.Pen(COLORS[name], 2.2))
    # material fibre Φe₁ = R D U(θ)⁻¹ e₁ (eqs. (23)–(24)), both halves
    fib = R2 @ np.array([lam * math.cos(theta), -mu * math.sin(theta)])
    canvas.line(px(np.array([[-fib[0], fib[0]], [-fib[1], fib[1]]])), aggdraw.Pen(COLORS["fibre"], 1.4))
    if target:
        tgt = R2 @ (np.array([[float(target["lambda"])], [float(target["mu"])]]) * _CIRCLE)
        canvas.polygon(px(tgt), aggdraw.Pen(COLORS["target"], 1.6))
    frame = np.frombuffer(canvas.tobytes(), dtype=np.uint8).reshape(SIZE, SIZE, 3).copy()
    _put(frame, _text_mask(f"t = {t:6.2f}   rho = {rho:.3f}"), _INK, 5, 4)
    mask, colors = _legend()
    _put(frame, mask, colors, 4, SIZE - mask.shape[0] - 3)
    bar = _scale_bar_length(half)
    bar_px = int(round(bar * scale))
    x1 = SIZE - 8
    frame[SIZE - 10 : SIZE - 8, x1 - bar_px : x1] = _INK
    frame[SIZE - 14 : SIZE - 4, x1 - bar_px : x1 - bar_px + 1] = _INK
    frame[SIZE - 14 : SIZE - 4, x1 - 1 : x1] = _INK
    _put(frame, _text_mask(f"{bar:g}"), _INK, x1 - bar_px, SIZE - 25)
    return frame
