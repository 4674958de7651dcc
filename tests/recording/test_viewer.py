"""The demo recording rendered by the real rerun viewer (Xvfb + software Vulkan), looked at in pixels.

Skipped, with the reason, where the viewer cannot run (needs the ``xvfb`` and ``mesa-vulkan-drivers``
packages); the screenshots come from :func:`flatbody_env.recording.viewer.screenshots`, the helper
behind ``flatbody record-shots``.
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from flatbody_env.recording.viewer import screenshots, viewer_unavailable

TIMES = (0.0, 10.0)
"""Model times of the screenshots: the first frame and one well into the episode (each costs the viewer ~5 s)."""


def _cells(img: np.ndarray) -> np.ndarray:
    """Colours at the centres of the 3×3 cells of a tensor view's picture (9, 3)."""
    h, w = img.shape[:2]
    ys = [int(h * (2 * i + 1) / 6) for i in range(3)]
    xs = [int(w * (2 * j + 1) / 6) for j in range(3)]
    return np.array([img[y, x, :3] for y in ys for x in xs], dtype=int)


@pytest.fixture(scope="module")
def demo_shots(tmp_path_factory):
    reason = viewer_unavailable()
    if reason:
        pytest.skip(f"the real rerun viewer cannot run here: {reason}")
    from agents.demo import run_demo

    tmp = tmp_path_factory.mktemp("viewer")
    assert run_demo(seed=7, out=str(tmp / "demo.rrd")) == 0
    return screenshots(tmp / "demo.rrd", list(TIMES), tmp / "shots", size=(1280, 800), views=("TextDocument", "Tensor"))


def test_demo_window_is_not_blank(demo_shots):
    windows = [s for s in demo_shots if s.view is None]
    assert [s.t for s in windows] == list(TIMES)
    for shot in windows:
        img = np.asarray(Image.open(shot.path).convert("RGB"))
        assert img.shape[:2] == (800, 1280)
        assert img.std() > 20  # not one flat colour
        assert len(np.unique(img.reshape(-1, 3)[::7], axis=0)) > 200  # views, text and curves drawn
        assert not shot.reports, shot.reports  # no view says it failed to visualize


def test_description_is_on_screen_and_no_heat_map_is_left(demo_shots):
    """The description is a view on screen at first open (a view in a hidden tab has no screenshot),
    beside the numbers of G and C; G and C are no longer rerun heat maps (unreadable in 0.41)."""
    texts = [s for s in demo_shots if s.view_class == "TextDocument"]
    assert sorted({s.view for s in texts}) == ["G, C: numbers and eigenvalues", "description: what each view shows"]
    assert sorted({s.t for s in texts}) == list(TIMES)
    for shot in texts:
        img = np.asarray(Image.open(shot.path).convert("RGB"))
        assert img.shape[0] > 200 and img.shape[1] > 200 and img.std() > 10  # text drawn, a readable size
    assert not any(s.view_class == "Tensor" for s in demo_shots)
