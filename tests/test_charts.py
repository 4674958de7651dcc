"""The committed charts (docs/img/*.png), drawn again from their saved tables: each explains its jargon in
the figure itself (caption or legend), and no text lies under a legend, outside the figure, or outside its
axes (:func:`flatbody_env.chart_text.layout_problems`, measured with the renderer's window extents)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from flatbody_env.chart_text import add_caption, all_text, caption_text, layout_problems  # noqa: E402

IMG = Path(__file__).resolve().parents[1] / "docs" / "img"


def _train(out):
    from agents.benchmark import plot

    plot(IMG / "train_benchmark.csv", out)


def _env(out):
    from flatbody_env.env.benchmark import plot

    plot(IMG / "env_benchmark.csv", out)


def _bench(out):
    from analysis.integrator_plots import plot_bench

    plot_bench(IMG / "bench_integrators.json", out)


def _work_precision(out):
    from analysis.integrator_plots import plot_work_precision

    plot_work_precision(IMG / "work_precision.csv", out, IMG / "references.json")


def _failure(out):
    from analysis.integrator_plots import plot_failure_study

    plot_failure_study(IMG / "failure_study.csv", out)


def _ladder(out):
    from analysis.ladder_plots import plot_ladder

    plot_ladder(IMG / "ladder.csv", IMG / "ladder_scenes.csv", out)


def _family(out):
    from analysis.plots import plot_family

    plot_family(IMG / "family-v3-s3.csv", out)


def _shape_map(out):
    from analysis.plots import plot_shape_map

    plot_shape_map(IMG / "stability-map-default.csv", out, title="Stationary ellipses by shape")


def _tasks(out):
    from agents.reference_chart import plot_task_success

    plot_task_success(out)


def _recording(out):
    from flatbody_env.cli.record import _bench_chart

    _bench_chart(json.loads((IMG / "recording.json").read_text(encoding="utf-8")), out)


CHARTS = {
    # chart: (drawing function, phrases its caption or legend must hold: the jargon explained)
    "train_benchmark": (_train, ["LQR", "linear-quadratic regulator", "PPO", "Proximal Policy Optimization"]),
    "env_benchmark": (_env, ["Blue: flatbody", "grey", "N = 1024", "2 threads"]),
    "bench_integrators": (_bench, ["100x", "speed-up =", "δ = σ₋", "(env)", "(integrate)", "DOP853-numba"]),
    "work_precision": (_work_precision, ["ref. floor", "RHS / force evaluations", "RATTLE-*", "splitting-*"]),
    "failure_study": (_failure, ["gap:", "rho:", "horizon:", "rtol:", "h:"]),
    "ladder": (_ladder, ["Rung:", "auto:", "two-polar:", "planar-V1:", "floor"]),
    "family-v3-s3": (_family, ["Branch N", "plate's\nnormal", "Elliptic:", "hyperbolic:"]),
    "stability-map-default": (_shape_map, ["energy-Casimir:", "Lyapunov", "hollow", "rigid-like", "circulating"]),
    "tasks_success": (_tasks, ["LQR: the linear-quadratic regulator", "passivity:", "r: how fast", "γ: the growth rate", "Wilson"]),
    "recording": (_recording, ["send_columns", "Recorder.append", "error bars"]),
}


@pytest.fixture
def drawn(monkeypatch):
    """Draw a chart and keep its figure open (the chart functions close theirs); closed afterwards."""
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    figures = []

    def draw(fn, out):
        before = set(plt.get_fignums())
        fn(out)
        new = sorted(set(plt.get_fignums()) - before)
        assert len(new) == 1, new
        fig = plt.figure(new[0])
        figures.append(fig)
        return fig

    yield draw
    monkeypatch.undo()
    for fig in figures:
        plt.close(fig)


# The three charts whose defects users reported run by default; the rest with ``pytest -m slow``.
DEFAULT_CHARTS = {"train_benchmark", "bench_integrators", "ladder"}


@pytest.mark.parametrize("name", [n if n in DEFAULT_CHARTS else pytest.param(n, marks=pytest.mark.slow) for n in CHARTS])
def test_chart_explains_its_jargon_and_nothing_overlaps(name, drawn, tmp_path):
    fn, phrases = CHARTS[name]
    fig = drawn(fn, tmp_path / f"{name}.png")
    assert (tmp_path / f"{name}.png").stat().st_size > 10_000
    assert caption_text(fig), f"{name}: no caption"
    text = all_text(fig)
    missing = [p for p in phrases if p not in text]
    assert not missing, f"{name}: the figure does not explain {missing}"
    assert layout_problems(fig) == [], name


def test_bench_integrators_labels_every_x_axis(drawn, tmp_path):
    fig = drawn(_bench, tmp_path / "b.png")
    assert all(ax.get_xlabel() for ax in fig.axes)
    legend = fig.axes[0].get_legend()
    assert legend is not None and any("100x" in t.get_text() for t in legend.get_texts())


def test_layout_problems_finds_the_defects():
    """The checker itself: a label under the legend, a label cut by the frame, two labels on each other,
    a label on a marker, a caption outside the figure."""
    fig, ax = plt.subplots(figsize=(4, 3))
    try:
        ax.plot([0, 1], [0, 1], "o", label="points")
        ax.set_xlim(0, 1.2)
        ax.set_ylim(-0.2, 1.2)
        legend = ax.legend(loc="lower right")
        fig.canvas.draw()
        lb = legend.get_window_extent().transformed(ax.transData.inverted())
        ax.text((lb.x0 + lb.x1) / 2, (lb.y0 + lb.y1) / 2, "under the legend", ha="center", va="center")
        ax.text(1.15, 0.5, "cut by the frame")
        ax.text(0.3, 0.6, "one")
        ax.text(0.3, 0.6, "two")
        ax.text(1.0, 1.0, "on a marker", ha="center", va="center")
        fig.text(0.9, 0.5, "outside the figure, far to the right")
        problems = "\n".join(layout_problems(fig))
        for phrase in ("'under the legend' lies under a legend", "'cut by the frame' is cut by its axes' frame",
                       "'one' and 'two' overlap", "'on a marker' covers a data marker",
                       "'outside the figure, far to the right' reaches outside the figure"):
            assert phrase in problems, problems
    finally:
        plt.close(fig)


def test_caption_is_found_and_clean_layout_passes():
    fig, ax = plt.subplots(figsize=(4, 3))
    try:
        ax.plot([0, 1], [0, 1], label="a line")
        ax.legend(loc="upper left")
        bottom = add_caption(fig, "a line: what it means\nsecond line")
        fig.tight_layout(rect=(0, bottom, 1, 1))
        assert caption_text(fig) == "a line: what it means\nsecond line"
        assert layout_problems(fig) == []
    finally:
        plt.close(fig)
