"""Frames for ``render_mode="rgb_array"``: the plate seen from the laboratory's +z axis, and the colours
every picture of the body shares (these frames and the rerun recordings' views).

Drawn with aggdraw on Pillow images (both declared in pyproject for this module). The plate is
the ellipse Φ·(unit disc) = R·diag(λ, μ)·(unit circle) projected on the laboratory x–y plane
(eq. (23) of the paper), filled with a shade that darkens with the thickness ϱ; its principal
semi-axes are drawn in the colours of λ (red) and μ (green), the material fibre Φe₁ in gold (it
turns inside the ellipse with U(θ), eq. (24)), and the target ellipse (λ*, μ*) as a wide magenta line
along the body's current principal axes (the target is a shape, λ*, μ*, ϱ*, not an
orientation), with a dot in λ's red at the end of λ* and one in μ's green at the end of μ* — so a target whose
λ* is the longer axis while the body's λ is the shorter one reads as what it is, not as a turn by 90°. The
plate's edge is drawn over the target, so on target both are seen — the same colours as the top-down view of a
recording.

The status of the episode (:func:`frame_status`: the task, the step, the distance to the target against the
task's tolerance, and what ended the episode, in red) is written in the top left corner when the caller gives
it (``render_frame(..., status=...)``).

Anti-aliasing: the shapes are drawn with aggdraw (Anti-Grain Geometry, sub-pixel coverage) — a
supersampled Pillow drawing cost several milliseconds a frame. The text is DejaVu Sans (Greek
included) at 12–13 px, anti-aliased: each character is rasterised once and cached, and a line of text
is composed from the cached glyphs (the bitmap fallback, ASCII names, only where no DejaVu font is
found). A key in the top right corner says what the fill's shade means (the thickness ϱ, with a mark
at the current value); the legend (bottom left) names the lines.

The view's half-width is fixed, :data:`HALF_WIDTH` = 2.5 length units for every episode of every task
(the targets of FlatBody-v0 have semi-axes up to ≈ 2), and widens to a "nice" number (3, 4, 5, 6, 8,
10, …) only when the body itself stretches beyond 1.1 × it — it never clips. The scale bar is one
length unit: the radius of the undeformed plate (λ = μ = 1).
"""

from __future__ import annotations

import math

import numpy as np

from flatbody_env.physics import validation

SIZE = 256
"""Frame side in pixels."""

COLORS: dict[str, tuple[int, int, int]] = {
    "lambda": (214, 39, 40),
    "mu": (44, 160, 44),
    "rho": (60, 140, 255),
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
    validation.number("extent", extent, positive=True)
    k = math.floor(math.log10(extent))
    for m in _NICE:
        v = m * 10.0**k
        if v >= extent * (1.0 - 1e-12):
            return v
    return 10.0 ** (k + 1)


HALF_WIDTH = 2.5
"""The frame's half-width in length units, the same for every episode (see the module docstring)."""


def view_half_width(lam: float, mu: float, target: dict | None = None) -> float:
    """Half-width of the frame's view: :data:`HALF_WIDTH`, widened to a nice number that holds 1.1 ×
    the body's larger semi-axis when it stretches beyond (the target does not change it)."""
    need = 1.1 * max(lam, mu)
    return HALF_WIDTH if need <= HALF_WIDTH else nice_half_width(need)


_ANG = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
_CIRCLE = np.stack([np.cos(_ANG), np.sin(_ANG)])


_FONTS: dict[int, object] = {}
_GLYPHS: dict[tuple[str, int], tuple[np.ndarray, int]] = {}
_STATIC: dict[str, tuple[np.ndarray, np.ndarray]] = {}
_BACKGROUND = (250, 250, 250)
_INK = np.array([20, 20, 20], dtype=np.float32)
_FONT_FILES = (
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
)


def _font_file() -> str | None:
    """DejaVu Sans (has Greek): the system's, else matplotlib's copy (found without importing it)."""
    import importlib.util
    import os

    for f in _FONT_FILES:
        if os.path.exists(f):
            return f
    spec = importlib.util.find_spec("matplotlib")
    for base in (spec.submodule_search_locations or []) if spec else []:
        f = os.path.join(base, "mpl-data", "fonts", "ttf", "DejaVuSans.ttf")
        if os.path.exists(f):
            return f
    return None


def _font(size: int):
    """The frame's font at ``size`` px (DejaVu Sans; Pillow's bitmap font where none is installed)."""
    font = _FONTS.get(size)
    if font is None:
        from PIL import ImageFont

        path = _font_file()
        if path is not None:
            font = ImageFont.truetype(path, size)
        else:  # pragma: no cover - a system without DejaVu
            font = (
                ImageFont.load_default_imagefont()
                if hasattr(ImageFont, "load_default_imagefont")
                else ImageFont.load_default()
            )
        _FONTS[size] = font
    return font


def _ascii(text: str) -> str:
    return text.replace("ϱ", "rho").replace("λ", "lambda").replace("μ", "mu").replace("₁", "1")


def _glyph(ch: str, size: int) -> tuple[np.ndarray, int]:
    """Coverage (h, w) in [0, 1] of one character and its advance in pixels, rasterised once."""
    key = (ch, size)
    g = _GLYPHS.get(key)
    if g is None:
        from PIL import Image, ImageDraw

        font = _font(size)
        h = size + size // 3 + 2
        adv = int(round(font.getlength(ch))) if hasattr(font, "getlength") else font.getbbox(ch)[2]
        img = Image.new("L", (max(adv, 1) + 2, h), 0)
        ImageDraw.Draw(img).text((0, 0), ch, fill=255, font=font)
        g = _GLYPHS[key] = (np.asarray(img, dtype=np.float32) / 255.0, adv)
    return g


def _text_alpha(text: str, size: int = 13) -> np.ndarray:
    """Coverage (h, w) of a line of text composed from cached glyphs (no kerning)."""
    if _font_file() is None:  # pragma: no cover
        text = _ascii(text)
    glyphs = [_glyph(c, size) for c in text]
    w = sum(a for _, a in glyphs) + 2
    h = size + size // 3 + 2
    out = np.zeros((h, w), dtype=np.float32)
    x = 0
    for m, a in glyphs:
        ww = min(m.shape[1], w - x)
        np.maximum(out[:, x : x + ww], m[:, :ww], out=out[:, x : x + ww])
        x += a
    return out


def _blend(frame: np.ndarray, alpha: np.ndarray, color, x: int, y: int) -> None:
    """Paint ``color`` (3,) or (h, w, 3) with coverage ``alpha`` (h, w) at top-left (x, y), clipped."""
    h = min(alpha.shape[0], frame.shape[0] - y)
    w = min(alpha.shape[1], frame.shape[1] - x)
    if h <= 0 or w <= 0:
        return
    a = alpha[:h, :w, None]
    region = frame[y : y + h, x : x + w]
    c = color[:h, :w] if np.ndim(color) == 3 else np.asarray(color, dtype=np.float32)
    region[:] = (region * (1.0 - a) + c * a + 0.5).astype(np.uint8)


def plate_fill(rho: float) -> tuple[int, int, int]:
    """The plate's fill for the thickness ϱ: the palette's tone at ϱ = 1, darker for a thicker plate."""
    k = float(np.clip(0.5 + 0.5 * math.tanh(1.5 * (rho - 1.0)), 0.0, 1.0))
    return tuple(int(v) for v in np.clip(np.array(COLORS["plate"], dtype=float) * (1.25 - 0.5 * k), 0, 255))


RHO_KEY = (0.5, 1.5)
"""The ϱ range of the fill key (the shade saturates outside it)."""


def _legend(target: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The static legend (λ axis, μ axis, the target's shape when there is one, fibre e₁) as coverage and colours,
    built once."""
    key = "legend" if target else "legend-no-target"
    got = _STATIC.get(key)
    if got is None:
        rows = (("lambda", "λ axis"), ("mu", "μ axis")) + ((("target", "target shape"),) if target else ())
        rows += (("fibre", "fibre e₁"),)
        h, w = 15 * len(rows), 96
        alpha = np.zeros((h, w), dtype=np.float32)
        colors = np.zeros((h, w, 3), dtype=np.float32)
        for i, (name, label) in enumerate(rows):
            y = 15 * i
            alpha[y + 7 : y + 10, 0:14] = 1.0
            colors[y + 7 : y + 10, 0:14] = COLORS[name]
            tm = _text_alpha(label, 12)[:15, : w - 18]
            alpha[y : y + tm.shape[0], 18 : 18 + tm.shape[1]] = np.maximum(
                alpha[y : y + tm.shape[0], 18 : 18 + tm.shape[1]], tm
            )
            colors[y : y + tm.shape[0], 18 : 18 + tm.shape[1]][tm > 0] = _INK
        got = _STATIC[key] = (alpha, colors)
    return got


def _rho_key() -> tuple[np.ndarray, np.ndarray]:
    """The static key of the fill: "fill = ϱ" over a strip of the shades from ϱ = 0.5 to 1.5."""
    got = _STATIC.get("rho_key")
    if got is None:
        title = _text_alpha("fill: thickness ϱ", 12)
        lo, hi = _text_alpha(f"{RHO_KEY[0]:g}", 11), _text_alpha(f"{RHO_KEY[1]:g}", 11)
        w = max(title.shape[1], KEY_W + 4)
        h = title.shape[0] + 10 + lo.shape[0]
        alpha = np.zeros((h, w), dtype=np.float32)
        colors = np.zeros((h, w, 3), dtype=np.float32)
        alpha[: title.shape[0], : title.shape[1]] = title
        colors[: title.shape[0], : title.shape[1]] = _INK
        y0 = title.shape[0]
        for j in range(KEY_W):
            rho = RHO_KEY[0] + (RHO_KEY[1] - RHO_KEY[0]) * j / (KEY_W - 1)
            colors[y0 : y0 + 8, j] = plate_fill(rho)
        alpha[y0 : y0 + 8, :KEY_W] = 1.0
        yl = y0 + 9
        alpha[yl : yl + lo.shape[0], : lo.shape[1]] = lo
        colors[yl : yl + lo.shape[0], : lo.shape[1]] = _INK
        xr = KEY_W - hi.shape[1] + 2
        alpha[yl : yl + hi.shape[0], xr : xr + hi.shape[1]] = np.maximum(
            alpha[yl : yl + hi.shape[0], xr : xr + hi.shape[1]], hi
        )
        colors[yl : yl + hi.shape[0], xr : xr + hi.shape[1]] = _INK
        got = _STATIC["rho_key"] = (alpha, colors)
    return got


KEY_W = 80
"""Width of the fill key's strip in pixels."""


def _scale_bar() -> tuple[np.ndarray, np.ndarray]:
    """The static label of the scale bar."""
    got = _STATIC.get("bar")
    if got is None:
        a = _text_alpha("1 = rest radius", 11)
        got = _STATIC["bar"] = (a, np.broadcast_to(_INK, a.shape + (3,)).copy())
    return got


STATUS_INK = {"ok": (20, 120, 40), "ended": (190, 30, 30)}
"""Colours of the status lines: the distance within the tolerance (green), the end of the episode (red)."""


def frame_status(env, info: dict | None = None) -> dict:
    """The status a frame writes (:func:`render_frame`'s ``status``) of a :class:`~flatbody_env.env.env.FlatBodyEnv`
    (or a wrapper of one): its id, the step, the distance to the target, the task's tolerance, whether the distance
    is within it, and what ended the episode ("" when nothing did). ``info``: the last step's, when the caller has it
    (else the env's current one)."""
    from flatbody_env.env.core import end_reason

    u = getattr(env, "unwrapped", env)
    if info is None:
        info = u._info(False)
    spec = getattr(u, "spec", None) or getattr(env, "spec", None)
    dt = float(getattr(u, "dt", 0.0) or 0.0)
    tol = getattr(getattr(u, "task", None), "success_tolerance", None)
    return {
        "env_id": getattr(spec, "id", None) or type(u).__name__,
        "step": int(round(float(info.get("t", 0.0)) / dt)) if dt > 0 else None,
        "distance": info.get("distance"),
        "tolerance": None if tol is None else float(tol),
        "ended": end_reason(int(info.get("status", 0)), int(info.get("domain_code", 0))),
    }


def _status_lines(t: float, status: dict | None) -> list[tuple[str, int, tuple[int, int, int]]]:
    """The text of the top-left corner: (line, size, colour)."""
    ink = tuple(int(v) for v in _INK)
    if not status:
        return [(f"t = {t:.2f}", 13, ink)]
    step = status.get("step")
    lines = [(f"t = {t:.2f}" + (f", step {step}" if step is not None else ""), 13, ink)]
    if status.get("env_id"):
        lines.append((str(status["env_id"]), 11, ink))
    d, tol = status.get("distance"), status.get("tolerance")
    if d is not None and math.isfinite(float(d)):
        if tol is not None:
            on = float(d) <= float(tol)
            lines.append(
                (
                    f"distance {float(d):.3f} {'≤' if on else '>'} tol {float(tol):g}",
                    11,
                    STATUS_INK["ok"] if on else ink,
                )
            )
        else:
            lines.append((f"distance {float(d):.3f}", 11, ink))
    if status.get("ended"):
        lines.append((f"ended: {status['ended']}", 11, STATUS_INK["ended"]))
    return lines


def render_frame(
    y: np.ndarray,
    R: np.ndarray,
    target: dict,
    t: float,
    *,
    half_width: float | None = None,
    status: dict | None = None,
) -> np.ndarray:
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
    status : dict, optional
        The episode's status (:func:`frame_status`: ``env_id``, ``step``, ``distance``, ``tolerance``, ``ended``),
        written under the time in the top left corner; without it the frame says the time only.
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
    # plate: R·diag(λ, μ)·circle, shaded darker for a thicker plate (the key in the corner)
    fill = plate_fill(rho)
    plate = px(R2 @ (np.array([[lam], [mu]]) * _CIRCLE))
    canvas.polygon(plate, aggdraw.Brush(fill))
    if target:  # the target's shape along the body's axes: wide and translucent, under the plate's edge
        lt, mt = float(target["lambda"]), float(target["mu"])
        canvas.polygon(px(R2 @ (np.array([[lt], [mt]]) * _CIRCLE)), aggdraw.Pen(COLORS["target"], 3.0))
    canvas.polygon(plate, aggdraw.Pen(COLORS["plate_edge"], 1.2))
    # principal semi-axes (columns of R, lengths λ, μ) in the colours of λ and μ
    for col, (length, name) in enumerate(((lam, "lambda"), (mu, "mu"))):
        end = R2[:, col] * length
        canvas.line(px(np.array([[0.0, end[0]], [0.0, end[1]]])), aggdraw.Pen(COLORS[name], 2.2))
    # material fibre Φe₁ = R D U(θ)⁻¹ e₁ (eqs. (23)–(24)), both halves
    fib = R2 @ np.array([lam * math.cos(theta), -mu * math.sin(theta)])
    canvas.line(px(np.array([[-fib[0], fib[0]], [-fib[1], fib[1]]])), aggdraw.Pen(COLORS["fibre"], 1.4))
    if target:  # which target axis is which: a dot in λ's colour at the end of λ*, in μ's at the end of μ*
        for col, (length, name) in enumerate(((lt, "lambda"), (mt, "mu"))):
            for sign in (1.0, -1.0):
                cx, cy = px(sign * R2[:, col : col + 1] * length)
                canvas.ellipse((cx - 3, cy - 3, cx + 3, cy + 3), aggdraw.Pen("white", 1.0), aggdraw.Brush(COLORS[name]))
    frame = np.frombuffer(canvas.tobytes(), dtype=np.uint8).reshape(SIZE, SIZE, 3).copy()
    y0 = 3
    for text, size, color in _status_lines(t, status):
        alpha = _text_alpha(text, size)
        if status:  # over the plate: a light box behind the words
            h, w = alpha.shape
            box = frame[y0 : y0 + h, 3 : 3 + min(w + 4, SIZE - 3)]
            box[:] = (box * 0.25 + np.array(_BACKGROUND) * 0.75).astype(np.uint8)
        _blend(frame, alpha, color, 5, y0)
        y0 += alpha.shape[0] - (3 if size < 13 else 2)
    # the fill's key (top right) with a mark at the current ϱ
    alpha, colors = _rho_key()
    kx = SIZE - alpha.shape[1] - 4
    _blend(frame, alpha, colors, kx, 3)
    strip_y = 3 + _text_alpha("ϱ", 12).shape[0]
    j = int(round((min(max(rho, RHO_KEY[0]), RHO_KEY[1]) - RHO_KEY[0]) / (RHO_KEY[1] - RHO_KEY[0]) * (KEY_W - 1)))
    frame[strip_y - 2 : strip_y + 10, kx + max(j - 1, 0) : kx + j + 1] = (20, 20, 20)
    value = _text_alpha(f"ϱ = {rho:.3f}", 12)
    vx, vy = SIZE - value.shape[1] - 4, strip_y + 24
    box = frame[vy : vy + value.shape[0], vx - 2 : SIZE - 2]  # over the plate: a light box behind the value
    box[:] = (box * 0.25 + np.array(_BACKGROUND) * 0.75).astype(np.uint8)
    _blend(frame, value, _INK, vx, vy)
    alpha, colors = _legend(bool(target))
    _blend(frame, alpha, colors, 4, SIZE - alpha.shape[0] - 3)
    # scale bar: one length unit, the undeformed plate's radius
    bar_px = int(round(scale))
    x1 = SIZE - 8
    frame[SIZE - 10 : SIZE - 8, x1 - bar_px : x1] = (20, 20, 20)
    frame[SIZE - 14 : SIZE - 4, x1 - bar_px : x1 - bar_px + 1] = (20, 20, 20)
    frame[SIZE - 14 : SIZE - 4, x1 - 1 : x1] = (20, 20, 20)
    alpha, colors = _scale_bar()
    _blend(frame, alpha, colors, SIZE - alpha.shape[1] - 6, SIZE - 16 - alpha.shape[0])
    return frame


FRAME_GAP = 8
"""White pixels between the frames of :func:`frame_strip`."""


def frame_strip(
    steps=(0, 120),
    *,
    seed: int = 7,
    env_id: str = "FlatBody-v1",
    gap: int = FRAME_GAP,
    policy=None,
    with_status: bool = True,
) -> np.ndarray:
    """The ``rgb_array`` frames of one episode side by side: the env reset with ``seed``, then actions
    (``policy(env, obs)``; default seeded random actions, ``env.action_space.seed(seed)``), a frame after each
    number of actions in ``steps`` (increasing, ≥ 0), ``gap`` white pixels between two frames. Each frame is the
    env's :func:`render_frame` of its state, with the episode's status (:func:`frame_status`) when ``with_status``.
    Shape (256, k·256 + (k−1)·gap, 3), uint8. The pictures of the frame in docs/recording.md are
    ``flatbody record-shots --frames 0,120`` and ``--frames 0,120,300 --policy heuristic``."""
    import gymnasium as gym

    steps = [int(s) for s in steps]
    if not steps or steps[0] < 0 or any(b <= a for a, b in zip(steps, steps[1:])):
        raise ValueError(f"frames: expected increasing step counts ≥ 0, got {steps!r}")
    validation.requirement("gap", gap, gap >= 0, "be ≥ 0")
    env = gym.make(f"flatbody_env:{env_id}", render_mode="rgb_array")  # (the prefix imports the package: the ids)
    try:
        obs, info = env.reset(seed=seed)
        env.action_space.seed(seed)
        u = env.unwrapped
        frames, done = [], 0
        for want in steps:
            while done < want:
                action = env.action_space.sample() if policy is None else policy(env, obs)
                obs, _, terminated, truncated, info = env.step(action)
                done += 1
                if (terminated or truncated) and done < want:
                    raise ValueError(f"frames: the episode (seed {seed}) ended after {done} actions, before {want}")
            R = u.rotation if u.rotation is not None else np.eye(3)
            status = frame_status(env, info) if with_status else None
            frames.append(render_frame(u.physics_state, R, u.target, u.time, status=status))
    finally:
        env.close()
    height = max(f.shape[0] for f in frames)
    out = np.full((height, sum(f.shape[1] for f in frames) + gap * (len(frames) - 1), 3), 255, dtype=np.uint8)
    x = 0
    for f in frames:
        out[: f.shape[0], x : x + f.shape[1]] = f
        x += f.shape[1] + gap
    return out
