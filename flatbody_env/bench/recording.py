"""``flatbody bench recording``: the time to log a trajectory to a finished ``.rrd`` and to draw a frame.

Not a timed test: it prints figures and writes ``recording.json``, ``recording.csv`` (the
``record_trajectory`` sizes) and ``recording.png`` (drawn from the saved JSON by :func:`plot`);
with a docs page, also its ``<!-- bench:recording -->`` table (:func:`tables`).

* ``record_trajectory``: a whole simulated trajectory of N steps to a finished file, median, min and
  max of the repeats per size; the process's first recording (importing rerun) is timed apart.
* live ``Recorder.append``: the same steps logged one by one, sent in blocks.
* a recorded FlatBody-v0 episode on the compiled path that carries R against the former path (scipy's
  DOP853), with and without the recorder, in alternation, medians; a free scene's trajectory with R by
  ``simulate``'s default against scipy's DOP853.
* ``render_frame`` (the env's ``rgb_array`` frame): median, mean and 90th percentile per frame.

:func:`measure` → the result (the JSON record); :func:`report` hands it with its table (:func:`tables`: the
terminal's text and the docs block) to :func:`flatbody_env.bench.harness.write_report`.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from pathlib import Path

from flatbody_env.bench.harness import Report, Stopwatch, Table, alternate_samples, samples
from flatbody_env.physics import validation

NAME = "recording"
"""The file stem of the saved figures, and the docs block's name."""

BUDGET_S = 1.0
"""The budget of a ``--steps`` trajectory (10 000 steps by default) to a finished ``.rrd``, in seconds."""

FRAME_BUDGET_MS = 1.0
"""The budget of one ``rgb_array`` frame, in milliseconds."""

CSV_HEADER = ("steps", "median_s", "min_s", "max_s", "us_per_step", "file_bytes")
"""The columns of ``recording.csv``: ``record_trajectory`` per size."""


def measure(
    *, scene: str, steps: int, sizes: Sequence[int], repeats: int, block: int, frames: int, episode_repeats: int
) -> dict:
    """Measure the recording paths (see the module docstring).

    Parameters
    ----------
    scene : str
        Built-in scene that supplies the trajectory.
    steps : int
        The size judged against :data:`BUDGET_S` (also the live recorder's size).
    sizes : sequence of int
        Further sizes for the scaling chart.
    repeats : int
        Runs per size (median reported).
    block : int
        Block size of the live-recorder measurement.
    frames : int
        ``rgb_array`` frames timed.
    episode_repeats : int
        Recorded env episodes per path (median).

    Returns
    -------
    dict
        The record saved as ``recording.json``.
    """
    import platform
    import tempfile

    import numpy as np

    from flatbody_env.recording.reader import sdk_version
    from flatbody_env.recording.writer import Recorder, record_trajectory
    from flatbody_env.scene import load_scene
    from flatbody_env.simulation import simulate

    sc = load_scene(scene)
    rows = []
    live = None
    with tempfile.TemporaryDirectory() as tmp:
        # the process's first recording pays for importing rerun: timed apart, not in the medians
        warm = simulate(sc, t_end=sc.t_end, times=np.linspace(0.0, sc.t_end, 1000), with_rotation=True)
        with Stopwatch() as first:
            record_trajectory(warm, sc.body, Path(tmp) / "warm-up.rrd")
        first_call = {"steps": 1000, "seconds": first.seconds}
        for n in sorted({*sizes, steps}):
            traj = simulate(sc, t_end=sc.t_end, times=np.linspace(0.0, sc.t_end, n), with_rotation=True)
            files = (Path(tmp) / f"bench-{n}-{r}.rrd" for r in itertools.count())
            made: list[Path] = []

            def once(traj=traj, files=files, made=made) -> None:
                made.append(next(files))
                record_trajectory(traj, sc.body, made[-1])

            times = samples(once, repeats, warm=False)
            size_bytes = made[-1].stat().st_size
            for path in made:
                path.unlink()
            rows.append(
                {
                    "steps": n,
                    "median_s": float(np.median(times)),
                    "min_s": float(np.min(times)),
                    "max_s": float(np.max(times)),
                    "us_per_step": float(np.median(times)) / n * 1e6,
                    "file_bytes": size_bytes,
                }
            )
            if n == steps:
                Y, R, E = traj.y, traj.rotation, traj.energy
                with Stopwatch() as live_s, Recorder(Path(tmp) / "bench-live.rrd", sc.body, block=block) as rec:
                    for k in range(n):
                        rec.append(traj.t[k], Y[:, k], R[k], energy=E[k])
                live = {"steps": n, "block": block, "seconds": live_s.seconds, "us_per_step": live_s.seconds / n * 1e6}
    episode = _episode(episode_repeats)
    frame = _frame(sc, frames)
    target = next(r for r in rows if r["steps"] == steps)
    return {
        "benchmark": "recording",
        "what": "record_trajectory(traj, body, path): whole trajectory to a finished .rrd (send_columns), wall time",
        "scene": sc.name,
        "steps": steps,
        "median_s": target["median_s"],
        "budget_s": BUDGET_S,
        "within_budget": target["median_s"] <= BUDGET_S,
        "repeats": repeats,
        "sizes": rows,
        "live": live,
        "frame": frame,
        "episode": episode,
        "first_call": {
            **first_call,
            "note": "the process's first recording: includes importing rerun and starting its batcher",
        },
        "rerun_sdk": sdk_version(),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
    }


def _episode(repeats: int) -> dict:
    """A recorded FlatBody-v0 episode on the compiled path that carries R against the former path
    (the whole episode re-run on scipy's DOP853 at the env's tolerance), same run; and a free
    scene's trajectory with R by ``simulate``'s default (auto) against scipy's DOP853."""
    import tempfile

    import gymnasium as gym
    import numpy as np

    import flatbody_env  # noqa: F401  (registers FlatBody-v0)
    from flatbody_env.recording.wrapper import RerunRecorder
    from flatbody_env.scene import load_scene
    from flatbody_env.simulation import simulate

    def episode(path, **kwargs):
        env = gym.make("FlatBody-v0", track_rotation=True, **kwargs)
        env = RerunRecorder(env, str(path)) if path is not None else env
        rng = np.random.default_rng(0)
        with Stopwatch() as sw:
            env.reset(seed=0)
            done = False
            while not done:
                _, _, term, trunc, info = env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
                done = term or trunc
            env.close()
        return sw.seconds, info["integrator"]["method"]

    with tempfile.TemporaryDirectory() as tmp:
        method = episode(Path(tmp) / "warm.rrd")[1]  # compiled kernels loaded, rerun imported
        files = itertools.count()
        times = alternate_samples(
            {
                "fast": lambda: episode(Path(tmp) / f"fast-{next(files)}.rrd")[0],
                "slow": lambda: episode(Path(tmp) / f"slow-{next(files)}.rrd", integrator="DOP853")[0],
                "fast_steps": lambda: episode(None)[0],  # the same episode carrying R, nothing recorded
                "slow_steps": lambda: episode(None, integrator="DOP853")[0],
            },
            repeats,
            warm=False,
        )
    fast, slow, fast_steps, slow_steps = (times[k] for k in ("fast", "slow", "fast_steps", "slow_steps"))
    scene = load_scene("default")
    grid = np.linspace(0.0, scene.t_end, 1001)
    auto = simulate(scene, t_end=scene.t_end, times=grid, with_rotation=True)
    free = alternate_samples(
        {
            "auto": lambda: simulate(scene, t_end=scene.t_end, times=grid, with_rotation=True) and None,
            "scipy": lambda: (
                simulate(scene, t_end=scene.t_end, times=grid, with_rotation=True, method="DOP853") and None
            ),
        },
        max(1, repeats // 2),
        warm=False,
        mirror=True,
    )
    auto_s, scipy_s = min(free["auto"]), min(free["scipy"])
    return {
        "compiled_method": method,
        "compiled_s": float(np.median(fast)),
        "former_s": float(np.median(slow)),
        "speedup": float(np.median(slow) / np.median(fast)),
        "repeats": repeats,
        "stepping_compiled_s": float(np.median(fast_steps)),
        "stepping_former_s": float(np.median(slow_steps)),
        "stepping_speedup": float(np.median(slow_steps) / np.median(fast_steps)),
        "scene": scene.name,
        "scene_samples": int(grid.size),
        "scene_auto_method": auto.method,
        "scene_auto_s": float(auto_s),
        "scene_scipy_s": float(scipy_s),
        "scene_speedup": float(scipy_s / auto_s),
    }


def _frame(scene, frames: int) -> dict:
    """Time ``render_frame`` (the env's ``rgb_array`` frame) on the states of a simulated trajectory."""
    import numpy as np

    from flatbody_env.env.rendering import render_frame
    from flatbody_env.simulation import simulate

    traj = simulate(scene, t_end=scene.t_end, times=np.linspace(0.0, scene.t_end, frames), with_rotation=True)
    target = {"lambda": float(traj.state["lambda"][0]), "mu": float(traj.state["mu"][0])}
    Y, R, t = traj.y, traj.rotation, traj.t
    for k in range(min(20, frames)):  # warm-up (font and legend caches)
        render_frame(Y[:, k], R[k], target, t[k])
    at = iter(range(frames))

    def one_frame() -> None:
        k = next(at)
        render_frame(Y[:, k], R[k], target, t[k])

    times = np.array(samples(one_frame, frames, warm=False))
    median_ms = float(np.median(times)) * 1e3
    return {
        "frames": frames,
        "median_ms": median_ms,
        "mean_ms": float(times.mean()) * 1e3,
        "p90_ms": float(np.percentile(times, 90)) * 1e3,
        "budget_ms": FRAME_BUDGET_MS,
        "within_budget": median_ms <= FRAME_BUDGET_MS,
    }


def tables(result: dict) -> list[Table]:
    """The figures of a ``recording.json`` result: the terminal's text and the docs' ``recording`` block."""
    sizes = {r["steps"]: r for r in result["sizes"]}
    target = sizes[result["steps"]]
    others = [r for n, r in sorted(sizes.items()) if n != result["steps"]]
    ep, fr, lv, fc = result["episode"], result["frame"], result["live"], result["first_call"]
    within = lambda ok: "within" if ok else "OVER"  # noqa: E731
    rows = [
        [
            f"recorded env episode, 400 steps ({ep['compiled_method']} carrying R, compiled)",
            f"**{ep['compiled_s']:.3f} s** (median of {ep['repeats']})",
        ],
        [
            "the same episode on the former path (scipy DOP853 integrating R)",
            f"{ep['former_s']:.3f} s: **{ep['speedup']:.1f}× slower** (same run)",
        ],
        [
            "its stepping alone (the env carrying R, nothing recorded): compiled vs the former path",
            f"{ep['stepping_compiled_s'] * 1e3:.0f} ms vs {ep['stepping_former_s'] * 1e3:.0f} ms: "
            f"**{ep['stepping_speedup']:.0f}×**",
        ],
        [
            f"free scene with R, {ep['scene_samples']} samples: `simulate` method auto ({ep['scene_auto_method']}) vs "
            "scipy DOP853",
            f"{ep['scene_auto_s'] * 1e3:.1f} ms vs {ep['scene_scipy_s'] * 1e3:.0f} ms ({ep['scene_speedup']:.0f}×)",
        ],
        [
            f"`record_trajectory`, {result['steps']} steps (budget ≤ {result['budget_s']:g} s)",
            f"**{target['median_s']:.2f} s** (min {target['min_s']:.2f} s; {target['file_bytes'] / 1e6:.1f} MB): "
            f"{within(result['within_budget'])} the budget",
        ],
    ]
    if others:
        counts = " / ".join(str(r["steps"]) for r in others)
        rows.append([f"`record_trajectory`, {counts} steps", " / ".join(f"{r['median_s']:.3f}" for r in others) + " s"])
    if lv:
        rows.append(
            [
                f"live `Recorder.append`, {lv['steps']} steps in blocks of {lv['block']}",
                f"{lv['seconds']:.2f} s ({lv['us_per_step']:.0f} µs per step)",
            ]
        )
    rows.append(
        [f"the process's first recording ({fc['steps']} steps), including `import rerun`", f"{fc['seconds']:.2f} s"]
    )
    rows.append(
        [
            f"`rgb_array` frame, {fr['frames']} frames (budget ≤ {fr['budget_ms']:g} ms)",
            f"**{fr['median_ms']:.2f} ms** median ({fr['mean_ms']:.2f} ms mean, 90th percentile {fr['p90_ms']:.2f} ms): "
            f"{within(fr['within_budget'])} the budget",
        ]
    )
    return [Table(columns=["what", "result"], rows=rows)]


RECORDING_CAPTION = (
    "record_trajectory: a whole simulated trajectory written at once (rerun's send_columns: one call per series);\n"
    "live Recorder.append: the same steps logged while they are simulated, in blocks. .rrd: rerun's recording file.\n"
    "Points: median of {repeats} repeats; error bars: the fastest and the slowest. Steps: time samples of the trajectory."
)
"""The chart's caption (``{repeats}`` filled in)."""


def plot(json_path: str | os.PathLike, png_path: str | os.PathLike) -> Path:
    """Draw the chart of a saved ``recording.json`` (never from a fresh run) to ``png_path``."""
    from flatbody_env.figures import PALETTE, chart

    result = validation.read_json("--plot-only", json_path)
    steps = [r["steps"] for r in result["sizes"]]
    med = [r["median_s"] for r in result["sizes"]]
    lo = [r["median_s"] - r["min_s"] for r in result["sizes"]]
    hi = [r["max_s"] - r["median_s"] for r in result["sizes"]]
    with chart(png_path, size=(6.4, 5.2)) as c:
        ax = c.ax
        ax.errorbar(steps, med, yerr=[lo, hi], marker="o", capsize=3, label="record_trajectory (whole, send_columns)")
        if result.get("live"):
            lv = result["live"]
            ax.plot(
                [lv["steps"]], [lv["seconds"]], "s", color="C1", label=f"live Recorder.append (blocks of {lv['block']})"
            )
        ax.axhline(result["budget_s"], color=PALETTE["bad"], ls="--", lw=1, label="budget 1 s at 10 000 steps")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("steps")
        ax.set_ylabel("wall time to a finished .rrd [s]")
        ax.set_title(f"flatbody recording, rerun-sdk {result['rerun_sdk']} ({result['cpus']} CPUs)")
        ax.grid(True, which="both", alpha=0.3)
        c.legend(where="below", ncol=1)
        c.caption(RECORDING_CAPTION.format(repeats=result.get("repeats", "the")), fontsize=7)
    return Path(png_path)


def report(result: dict) -> Report:
    """``result`` for :func:`flatbody_env.bench.harness.write_report`: ``recording.json``, ``recording.csv``
    (the sizes), ``recording.png`` (:func:`plot`) and the table (:func:`tables`, the ``<!-- bench:recording -->``
    block)."""
    return Report(
        name=NAME,
        record=result,
        header=CSV_HEADER,
        rows=[[r[c] for c in CSV_HEADER] for r in result["sizes"]],
        chart=plot,
        tables=tables(result),
    )


__all__ = [
    "BUDGET_S",
    "CSV_HEADER",
    "FRAME_BUDGET_MS",
    "NAME",
    "RECORDING_CAPTION",
    "measure",
    "plot",
    "report",
    "tables",
]
