"""Frames for ``render_mode="rgb_array"``: the plate seen from the laboratory's +z axis.

Drawn with Pillow (a dependency of matplotlib, declared in pyproject for this module): the plate
is the ellipse Φ·(unit disc) = R·diag(λ, μ)·(unit circle) projected on the laboratory x–y plane
(eq. (23) of the paper), shaded by its thickness ϱ; two material lines Φe₁, Φe₂ show the material
rotation U(θ); the target ellipse (λ*, μ*) is outlined in green along the current principal axes.
"""

from __future__ import annotations

import math

import numpy as np

SIZE = 256
SCALE = 48.0  # pixels per unit length


def _to_px(xy: np.ndarray) -> list[tuple[float, float]]:
    return [(SIZE / 2 + SCALE * x, SIZE / 2 - SCALE * y) for x, y in xy]


def render_frame(y: np.ndarray, R: np.ndarray, target: dict, t: float) -> np.ndarray:
    """An RGB frame, shape (256, 256, 3), dtype uint8."""
    from PIL import Image, ImageDraw

    lam, mu, rho, theta = float(y[7]), float(y[8]), float(y[9]), float(y[10])
    img = Image.new("RGB", (SIZE, SIZE), (250, 250, 250))
    draw = ImageDraw.Draw(img)
    ang = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
    circle = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)])
    plate = (R @ np.diag([lam, mu, 0.0]) @ circle)[:2].T
    shade = int(np.clip(200 - 80 * rho, 40, 200))
    draw.polygon(_to_px(plate), fill=(shade, shade + 30 if shade < 225 else 255, 240), outline=(20, 40, 120))
    if target:
        tgt = (R @ np.diag([target["lambda"], target["mu"], 0.0]) @ circle)[:2].T
        pts = _to_px(tgt)
        draw.line(pts + [pts[0]], fill=(20, 160, 60), width=2)
    c, s = math.cos(theta), math.sin(theta)
    Uinv = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    Phi = R @ np.diag([lam, mu, rho]) @ Uinv
    for col, colour in ((0, (200, 40, 40)), (1, (230, 150, 0))):
        end = Phi[:2, col]
        draw.line(_to_px(np.array([-end, end])), fill=colour, width=2)
    draw.text((6, 6), f"t = {t:6.2f}  rho = {rho:.3f}", fill=(0, 0, 0))
    return np.asarray(img, dtype=np.uint8).copy()
