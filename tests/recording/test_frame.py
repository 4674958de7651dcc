"""The ``rgb_array`` frame (``flatbody_env.env.rendering``), which shares its colours with the recordings:
geometry measured in pixels, anti-aliased edges, a view that holds the body, legend and scale bar."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from flatbody_env.env.rendering import (
    COLORS,
    HALF_WIDTH,
    SIZE,
    _text_alpha,
    nice_half_width,
    plate_fill,
    render_frame,
    view_half_width,
)


def _state(lam, mu, rho=1.0, theta=0.0):
    y = np.zeros(11)
    y[7:11] = lam, mu, rho, theta
    return y


def _Rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _near(img, rgb, tol=12):
    return np.all(np.abs(img.astype(int) - np.array(rgb)) <= tol, axis=2)


def test_nice_half_width():
    assert [nice_half_width(x) for x in (0.3, 1.0, 1.2, 2.7, 7.0, 9.5, 11.0)] == pytest.approx(
        [0.3, 1.0, 1.5, 3.0, 8.0, 10.0, 15.0]
    )
    with pytest.raises(ValueError, match="extent"):
        nice_half_width(0.0)


def test_plate_size_in_pixels_matches_its_semi_axes():
    lam, mu = 1.6, 0.7
    target = {"lambda": 1.5, "mu": 0.6}  # inside the plate: the outline does not widen it
    half = view_half_width(lam, mu, target)
    img = render_frame(_state(lam, mu), np.eye(3), target, 1.0)
    assert img.shape == (SIZE, SIZE, 3) and img.dtype == np.uint8
    px_per_unit = SIZE / (2 * half)
    row = img[SIZE // 2 + 3]  # just below the λ axis line, through the plate's centre
    inside = np.flatnonzero(np.any(np.abs(row.astype(int) - 250) > 30, axis=1))
    width = (inside.max() - inside.min() + 1) / px_per_unit
    assert width == pytest.approx(2 * lam, abs=3 / px_per_unit)
    col = img[:, SIZE // 2 + 3]
    inside = np.flatnonzero(np.any(np.abs(col[20:-50].astype(int) - 250) > 30, axis=1))
    height = (inside.max() - inside.min() + 1) / px_per_unit
    assert height == pytest.approx(2 * mu, abs=3 / px_per_unit)


def test_rotation_turns_the_plate_and_the_axes_keep_their_colours():
    img0 = render_frame(_state(1.6, 0.6, theta=1.2), np.eye(3), {}, 0.0)  # θ ≠ 0: the fibre leaves the λ axis
    img1 = render_frame(_state(1.6, 0.6, theta=1.2), _Rz(math.pi / 2), {}, 0.0)
    # λ's axis (red) lies along +x for R = 1 and along +y after a quarter turn
    red0 = np.argwhere(_near(img0[:-60], COLORS["lambda"], 40))  # above the legend
    red1 = np.argwhere(_near(img1[:-60], COLORS["lambda"], 40))
    assert red0.size and red1.size
    assert np.ptp(red0[:, 1]) > 4 * np.ptp(red0[:, 0])  # horizontal
    assert np.ptp(red1[:, 0]) > 4 * np.ptp(red1[:, 1])  # vertical


def test_edges_are_anti_aliased():
    img = render_frame(_state(1.3, 0.8, theta=0.4), _Rz(0.3), {"lambda": 1.2, "mu": 0.9}, 2.0)
    row = img[SIZE // 3].astype(int)
    # between the background (250) and the plate's fill there are intermediate shades at the rim
    fill = np.array(COLORS["plate"]) * 0.75 + 0.0
    lum = row.mean(axis=1)
    mids = np.flatnonzero((lum < 245) & (lum > fill.mean() + 15))
    assert mids.size >= 2
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 150  # a hard-edged drawing has a handful of colours


def test_view_holds_a_large_body_and_stays_fixed_through_an_episode():
    target = {"lambda": 1.4, "mu": 0.9}
    # a body far beyond the old fixed scale (which clipped semi-axes above ≈ 2.7)
    img = render_frame(_state(4.5, 0.8), np.eye(3), target, 0.0)
    body = ~_near(img, (250, 250, 250), 3)
    body[:60] = body[-65:] = False  # the time, the fill key, legend and scale bar
    cols = np.flatnonzero(body.any(axis=0))
    assert cols.min() > 2 and cols.max() < SIZE - 3  # not clipped
    # one view for every episode and target: the scale bar means the same length in every frame
    assert (
        view_half_width(1.2, 0.9, target)
        == view_half_width(1.6, 0.7, {"lambda": 2.0, "mu": 0.5})
        == view_half_width(1.0, 1.0)
        == HALF_WIDTH
    )


def test_legend_fill_key_and_scale_bar_are_drawn():
    img = render_frame(_state(1.2, 0.9), np.eye(3), {"lambda": 1.2, "mu": 0.9}, 0.0)
    legend = img[SIZE - 65 :, :20]
    for name in ("lambda", "mu", "target", "fibre"):
        assert _near(legend, COLORS[name], 10).sum() >= 10, name
    # the scale bar is one length unit: SIZE / (2 × HALF_WIDTH) pixels, the same in every episode
    row = img[SIZE - 10, SIZE // 2 :].mean(axis=1)
    dark = np.flatnonzero(row < 60)
    assert dark.size and (dark.max() - dark.min() + 1) == pytest.approx(SIZE / (2 * HALF_WIDTH), abs=2)
    # the key of the fill: the shades of ϱ = 0.5 and ϱ = 1.5 both appear in the top right corner
    corner = img[:40, SIZE // 2 :]
    for rho in (0.5, 1.5):
        assert _near(corner, plate_fill(rho), 6).sum() >= 8, rho
    assert plate_fill(1.5) != plate_fill(0.5)


def test_labels_are_greek_and_readable():
    """The labels are drawn in a font with Greek letters at ≥ 11 px (the bitmap font had ~7 px ASCII)."""
    a = _text_alpha("λ μ ϱ", 12)
    assert a.shape[0] >= 14
    rows = np.flatnonzero((a > 0.5).any(axis=1))
    assert rows.max() - rows.min() + 1 >= 9  # ascender to descender of λ, μ, ϱ
    # each letter is its own glyph, not a fallback box: the three differ
    glyphs = [_text_alpha(c, 12) for c in "λμϱ"]
    assert not np.array_equal(glyphs[0], glyphs[1]) and not np.array_equal(glyphs[1], glyphs[2])


def test_env_frames_use_it():
    env = gym.make("FlatBody-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.shape == (SIZE, SIZE, 3) and frame.dtype == np.uint8
    assert _near(frame, COLORS["target"], 40).sum() > 20  # the target outline, in the recordings' magenta
