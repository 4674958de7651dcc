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
    from flatbody_env.bench.train import plot

    plot(IMG / "train_benchmark.csv", out)


def _env(out):
    from flatbody_env.bench.env import plot

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
    from flatbody_env.bench.recording import plot

    plot(IMG / "recording.json", out)


def _scaling(out):
    from flatbody_env.bench.sweep import plot

    plot(IMG / "scaling.json", out)


def _service(out):
    from flatbody_env.bench.service import plot

    plot(IMG / "service_benchmark.json", out)


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
    "tasks_success": (
        _tasks,
        ["LQR: the linear-quadratic regulator", "passivity:", "r: how fast", "γ: the growth rate", "Wilson"],
    ),
    "recording": (_recording, ["send_columns", "Recorder.append", "error bars"]),
    "scaling": (_scaling, ["makespan", "Simulated nodes", "break-even", "o the scheduler overhead"]),
    "service_benchmark": (_service, ["p50 / p99", "99th percentile", "concurrent clients", "error(s)"]),
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


@pytest.mark.parametrize(
    "name", [n if n in DEFAULT_CHARTS else pytest.param(n, marks=pytest.mark.slow) for n in CHARTS]
)
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
        for phrase in (
            "'under the legend' lies under a legend",
            "'cut by the frame' is cut by its axes' frame",
            "'one' and 'two' overlap",
            "'on a marker' covers a data marker",
            "'outside the figure, far to the right' reaches outside the figure",
        ):
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


def _small_scaling_table(path: Path) -> Path:
    """A scaling.json of a 2-task run, in the layout ``flatbody bench sweep`` saves."""
    rep = {
        "grid": 8,
        "chunk": 4,
        "tasks": 2,
        "points": 64,
        "serial_s": 0.2,
        "task_cost_mean_s": 0.1,
        "task_cost_max_s": 0.12,
        "cost_per_point_s": 0.003,
        "task_costs_s": [0.08, 0.12],
        "local": [
            {"workers": 1, "startup_s": 0.01, "run_s": 0.21, "speedup": 0.95, "speedup_end_to_end": 0.9},
            {"workers": 2, "startup_s": 0.5, "run_s": 0.13, "speedup": 1.5, "speedup_end_to_end": 0.3},
        ],
        "overhead_per_task_s": 0.002,
        "overhead_over_task_cost": 0.02,
        "connect_s": 0.01,
        "noop_tasks": 10,
        "simulated": {"workers": 4, "wall_s": 0.13, "model_s": 0.13, "ideal_s": 0.05, "speedup": 1.5},
        "extrapolated": [
            {
                "workers": 8,
                "grid": 8,
                "predicted_s": 0.13,
                "predicted_speedup": 1.5,
                "grid_big": 100,
                "predicted_big_s": 5.0,
                "predicted_big_speedup": 6.0,
                "break_even_grid": 3.0,
            }
        ],
        "break_even_local_2": 20.0,
        "machine": {"cpu_count": 2, "python": "3", "load_avg_1min": 0.5},
    }
    path.write_text(json.dumps(rep), encoding="utf-8")
    return path


def _small_service_table(path: Path) -> Path:
    """A service_benchmark.json of two endpoints at 1 and 4 clients, in the layout the benchmark saves."""
    rows = [
        {
            "endpoint": e,
            "clients": c,
            "requests": 20,
            "errors": 0,
            "seconds": 0.5,
            "p50_ms": p * c,
            "p99_ms": 4 * p * c,
            "requests_per_s": 100.0 / p,
        }
        for e, p in (("GET /health", 1.0), ("POST /simulate", 3.0))
        for c in (1, 4)
    ]
    path.write_text(
        json.dumps(
            {
                "workers": 1,
                "cpus": 2,
                "long_job": {
                    "kind": "stability-map",
                    "params": {"grid": 20},
                    "status_at_start": "running",
                    "status_at_end": "running",
                },
                "rows": rows,
            }
        ),
        encoding="utf-8",
    )
    return path


def test_scaling_chart_is_drawn_from_its_saved_table(drawn, tmp_path):
    """``bench.sweep.plot`` reads only the saved JSON: a small table gives a chart whose numbers come from it."""
    from flatbody_env.bench.sweep import plot as plot_scaling

    table = _small_scaling_table(tmp_path / "scaling.json")
    fig = drawn(lambda out: plot_scaling(table, out), tmp_path / "scaling.png")
    assert (tmp_path / "scaling.png").read_bytes()[:4] == b"\x89PNG"
    text = all_text(fig)
    assert "overhead 2.0 ms/task" in text and "grid 8 (2 tasks)" in text and "grid 8, 2 tasks of 4" in caption_text(fig)
    measured = [ln for ax in fig.axes for ln in ax.get_lines() if ln.get_label() == "measured, local processes"]
    assert [list(ln.get_ydata()) for ln in measured] == [[0.95, 1.5]]
    assert layout_problems(fig) == []


def test_service_chart_is_drawn_from_its_saved_table(drawn, tmp_path):
    """``bench.service.plot`` reads only the saved JSON (``flatbody bench service --plot-only``)."""
    from flatbody_env.bench.service import plot

    table = _small_service_table(tmp_path / "service_benchmark.json")
    fig = drawn(lambda out: plot(table, out), tmp_path / "service.png")
    assert (tmp_path / "service.png").read_bytes()[:4] == b"\x89PNG"
    latency, throughput = fig.axes
    p50 = next(ln for ln in latency.get_lines() if ln.get_label() == "POST /simulate, p50")
    assert list(p50.get_xdata()) == [1, 4] and list(p50.get_ydata()) == [3.0, 12.0]
    assert [ln.get_label() for ln in throughput.get_lines()] == ["GET /health", "POST /simulate"]
    assert "0 error(s)" in caption_text(fig) and "1 worker process(es) on 2 CPU(s)" in all_text(fig)
    assert layout_problems(fig) == []


def test_bench_service_plot_only_redraws_from_the_table(tmp_path):
    from flatbody_env.cli.main import main

    _small_service_table(tmp_path / "service_benchmark.json")
    assert main(["bench", "service", "--out-dir", str(tmp_path), "--plot-only"]) == 0
    assert (tmp_path / "service_benchmark.png").stat().st_size > 10_000
    assert main(["bench", "service", "--out-dir", str(tmp_path / "none"), "--plot-only"]) == 2
