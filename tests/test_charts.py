"""The committed charts (docs/img/*.png), drawn again from their saved tables: each explains its jargon in
the figure itself (caption or legend), and no text lies under a legend, outside the figure, or outside its
axes (:func:`flatbody_env.figures.layout_problems`, measured with the renderer's window extents)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from flatbody_env.figures import add_caption, all_text, caption_text, layout_problems  # noqa: E402

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


def _gpu(out):
    from flatbody_env.bench.gpu import plot

    plot(IMG / "gpu.json", out)


def _time_to_goal(out):
    from flatbody_env.bench.time_to_goal import plot

    plot(IMG / "time_to_goal.json", out)


def _longer(out):
    from agents.benchmark import plot_longer_budgets

    plot_longer_budgets(out)


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
    "gpu": (_gpu, ["Colour: where it ran", "RK4 solid, DOP853 dashed", "dotted", "body-steps/s"]),
    "time_to_goal": (_time_to_goal, ["linear-quadratic regulator", "Goal: success", "gSDE"]),
    "rsl_ppo_longer_budgets": (_longer, ["held-out episodes", "t-interval", "LQR: the linear-quadratic", "planner"]),
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


# The charts whose defects users reported run by default; the rest with ``pytest -m slow``.
DEFAULT_CHARTS = {
    "train_benchmark",
    "bench_integrators",
    "ladder",
    "work_precision",
    "gpu",
    "time_to_goal",
    "tasks_success",
    "rsl_ppo_longer_budgets",
}


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
    assert any("100x" in t.get_text() for lg in fig.legends for t in lg.get_texts())


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
        ax2 = fig.add_axes((0.1, 0.1, 0.3, 0.3), label="second")
        ax2.plot([0, 1], [0, 1], "-", label="a curve under its legend")
        ax2.set_title("curve")
        ax2.legend(loc="center")
        problems = "\n".join(layout_problems(fig))
        for phrase in (
            "the legend of 'curve' covers data",
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


def test_every_chart_draws_through_the_one_figure_helper():
    """No chart function sets a figure up (``plt.subplots``/``plt.figure``, ``matplotlib.use``, ``tight_layout``,
    ``savefig``, a caption) on its own: every one draws inside :func:`flatbody_env.figures.chart`."""
    import ast

    root = Path(__file__).resolve().parents[1]
    banned = {"subplots", "savefig", "tight_layout", "add_caption", "save_figure", "suptitle"}
    offenders = []
    for package in ("flatbody_env", "analysis", "agents"):
        for path in sorted((root / package).rglob("*.py")):
            if path.name in ("figures.py", "output.py"):
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                name = node.attr if isinstance(node, ast.Attribute) else node.id if isinstance(node, ast.Name) else ""
                if name in banned or (
                    isinstance(node, ast.Attribute)
                    and isinstance(node.value, ast.Name)
                    and (node.value.id, node.attr) in {("matplotlib", "use"), ("plt", "figure")}
                ):
                    offenders.append(f"{path.relative_to(root)}:{node.lineno} {name}")
    assert not offenders, offenders


def test_the_tasks_chart_has_a_panel_per_task_and_its_legend_off_the_data(drawn, tmp_path):
    """``tasks_success.png``: one panel per task (the tasks told apart by their panel, not by a marker), one legend of
    the policies outside every axes, success on a 0-100 % axis."""
    fig = drawn(_tasks, tmp_path / "t.png")
    axes = [ax for ax in fig.axes if ax.get_visible() and ax.axison]
    titles = [ax.get_title() for ax in axes]
    assert len(axes) >= 3 and all(t.startswith("FlatBody") for t in titles), titles
    assert len({t.split(":")[0] for t in titles}) == len(axes)  # each task on its own panel
    assert all(ax.get_legend() is None for ax in axes) and len(fig.legends) == 1
    assert all(max(ax.get_yticks()) <= 1.0 and ax.get_ylim()[1] <= 1.05 for ax in axes)
    assert layout_problems(fig) == []


def test_time_to_goal_success_axis_stops_at_100_percent(drawn, tmp_path):
    fig = drawn(_time_to_goal, tmp_path / "t.png")
    success = next(ax for ax in fig.axes if ax.get_ylabel() == "success rate")
    assert max(success.get_yticks()) == 1.0 and success.get_ylim() == (-0.03, 1.03)
    assert [t.get_text() for t in success.get_yticklabels()][-1] == "100%"


def test_work_precision_lists_the_failed_runs_instead_of_piling_crosses(drawn, tmp_path):
    from analysis.integrator_plots import failed_runs_text
    from analysis.work_precision import read_csv

    fig = drawn(_work_precision, tmp_path / "w.png")
    assert not [ln for ax in fig.axes for ln in ax.get_lines() if ln.get_marker() == "x"]
    rows = [r for r in read_csv(IMG / "work_precision.csv") if r["scene"] == "close-approach"]
    failed = {r["method"] for r in rows if r["status"] not in ("ok", "skipped")}
    listed = failed_runs_text(rows)
    assert failed and all(f"  {m}, " in listed for m in failed)
    assert listed in all_text(fig) and "every run reached t_end" in all_text(fig)  # the regular scene: none failed


def test_bench_integrators_marks_every_missing_method(drawn, tmp_path):
    data = json.loads((IMG / "bench_integrators.json").read_text(encoding="utf-8"))
    fig = drawn(_bench, tmp_path / "b.png")
    close = fig.axes[1]
    missing = sum(1 for c in data["close_approach"] for r in c["at_target"] if not r.get("wall_time"))
    marks = [t.get_text() for t in close.texts if t.get_text().startswith("✗")]
    assert missing and len(marks) == missing and all("fails" in m or "does not reach" in m for m in marks)
    rows = len([t for t in close.get_yticklabels() if t.get_text()])
    assert rows == sum(len(c["at_target"]) for c in data["close_approach"])  # every method has its row


def test_gpu_chart_legend_names_every_backend_and_line_style(drawn, tmp_path):
    data = json.loads((IMG / "gpu.json").read_text(encoding="utf-8"))
    fig = drawn(_gpu, tmp_path / "g.png")
    (legend,) = fig.legends
    labels = [t.get_text() for t in legend.get_texts() if t.get_text()]
    for backend in {r["backend"] for r in data["rows"]}:
        assert any(lab.startswith(backend + " (") for lab in labels), labels
    assert "dynamics alone, RK4" in labels and any(lab.startswith("whole env step") for lab in labels)
    styles = {(ln.get_linestyle(), ln.get_color()) for ln in fig.axes[0].get_lines()}
    assert {s for s, _ in styles} == {"-", "--", ":"}
    lb, fb = legend.get_window_extent(), fig.bbox
    assert fb.x0 <= lb.x0 and lb.x1 <= fb.x1 and fb.y0 <= lb.y0  # the whole legend inside the figure


def test_a_family_over_decades_gets_a_log_axis(drawn, tmp_path):
    from analysis.families import CSV_COLUMNS
    from analysis.plots import plot_family

    table = tmp_path / "family.csv"
    lines = [",".join(CSV_COLUMNS)]
    for k, j in enumerate(10.0 ** np.linspace(-6, 6, 25)):
        row = dict.fromkeys(CSV_COLUMNS, "")
        row.update(branch=0, param_name="J", param=j, s3=1.0, p_theta=0.5, classification="elliptic")
        row.update({"lambda": 1.0 + 0.01 * k, "mu": 0.9, "max_real_part": 0.0})
        lines.append(",".join(str(row[c]) for c in CSV_COLUMNS))
    table.write_text("\n".join(lines) + "\n", encoding="utf-8")
    fig = drawn(lambda out: plot_family(table, out), tmp_path / "f.png")
    assert all(ax.get_xscale() == "log" for ax in fig.axes) and "log scale" in fig.axes[1].get_xlabel()
    assert layout_problems(fig) == []


def test_chart_tasks_makes_its_output_folder(tmp_path, capsys):
    """``flatbody chart --tasks --out NEWDIR`` makes the folder, as every command writing files does."""
    from flatbody_env.cli.main import main

    out = tmp_path / "new" / "dir"
    assert main(["chart", "--tasks", "--out", str(out)]) == 0
    assert (out / "tasks_success.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "wrote" in printed and ("tasks_ladder.png" in printed)
    (tmp_path / "file").write_text("x")
    with pytest.raises(SystemExit) as refused:  # a file where the folder should be: one line, exit 2
        main(["chart", "--tasks", "--out", str(tmp_path / "file")])
    assert refused.value.code == 2 and "out:" in capsys.readouterr().err


def _longer_table(runs: dict[int, dict[int, float]]) -> dict:
    """A longer-budget table (agents/data/benchmark/rsl-ppo-longer-budgets.json's layout) of one task: seed ->
    {env steps: success}, the largest step count of each seed a row, the others checkpoints."""
    rows, checkpoints = [], []
    for seed, points in runs.items():
        for n, s in points.items():
            entry = {
                "env_id": "FlatBodySlowHard-v1",
                "algo": "rsl-ppo",
                "seed": seed,
                "n_timesteps": n,
                "success_rate": s,
            }
            (rows if n == max(points) else checkpoints).append(entry)
    return {"episodes": 100, "seed": 10000, "rows": rows, "checkpoints": checkpoints}


def test_the_longer_budget_mean_is_drawn_only_where_every_seed_has_a_point(drawn, tmp_path):
    """The mean over the seeds (with its t-interval) at a mark where every seed was evaluated within a tenth of a mark,
    none where a seed lacks one; each seed its own line; the task's LQR and planner as lines from its report."""
    from agents.benchmark import MARK, longer_budget_points, mean_interval, plot_longer_budgets

    runs = {
        0: {6_021_120: 0.65, 15_015_936: 0.80, 25_018_368: 0.86},  # no point near 5e6 (6.0e6 is off by 1e6)
        1: {5_013_504: 0.59, 15_040_512: 0.70, 25_018_368: 0.81},
        2: {5_087_232: 0.64, 14_991_360: 0.75, 24_969_216: 0.84},
    }
    table = _longer_table(runs)
    variant = {"env_id": "FlatBodySlowHard-v1", "algo": "rsl-ppo", "seed": 0, "hyperparams": ["gamma=0.995"]}
    table["rows"].append({**variant, "n_timesteps": 25_018_368, "success_rate": 0.20})  # a variant: apart
    table["checkpoints"].append({**variant, "n_timesteps": 5_013_504, "success_rate": 0.10})
    task = longer_budget_points(table)["FlatBodySlowHard-v1"]
    assert [m[0] for m in task["means"]] == [6 * MARK, 10 * MARK]
    assert task["means"][1][1:] == pytest.approx(mean_interval([0.86, 0.81, 0.84]))
    assert task["seeds"][0] == sorted(runs[0].items())
    assert task["variants"] == {("gamma=0.995", 0): [(5_013_504, 0.10), (25_018_368, 0.20)]}
    two = longer_budget_points(_longer_table({0: runs[0], 1: runs[1]}))["FlatBodySlowHard-v1"]
    assert two["means"] == [] and len(two["seeds"]) == 2  # two seeds: each drawn, no mean (its interval says nothing)
    report = {"env_id": "FlatBodySlowHard-v1", "policies": {
        "zero": {"summary": {"success_rate": 0.0}}, "heuristic": {"summary": {"success_rate": 0.64}},
        "planner": {"summary": {"success_rate": 0.56}}}}  # fmt: skip
    fig = drawn(lambda out: plot_longer_budgets(out, table, [report]), tmp_path / "l.png")
    ax = fig.axes[0]
    assert len([line for line in ax.get_lines() if line.get_marker() == "o"]) == 3  # one line per seed
    (drawn_variant,) = [line for line in ax.get_lines() if line.get_linestyle() == "-."]
    assert list(drawn_variant.get_ydata()) == [0.10, 0.20] and drawn_variant.get_label() == "seed 0, gamma=0.995"
    levels = {round(line.get_ydata()[0], 2) for line in ax.get_lines() if line.get_linestyle() in ("--", ":")}
    assert levels == {0.64, 0.56}
    assert ax.get_title() == "FlatBodySlowHard-v1\nLQR 64% · planner 56%"
    assert layout_problems(fig) == []


def test_chart_longer_budgets_draws_the_shipped_table(tmp_path, capsys):
    """``flatbody chart --longer-budgets --out NEWDIR`` draws the shipped table into a new folder."""
    from flatbody_env.cli.main import main

    out = tmp_path / "new"
    assert main(["chart", "--longer-budgets", "--out", str(out)]) == 0
    assert (out / "rsl_ppo_longer_budgets.png").stat().st_size > 10_000
    assert "rsl_ppo_longer_budgets.png" in capsys.readouterr().out
