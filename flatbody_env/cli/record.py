"""Sub-commands for rerun recordings: ``record`` (scenes, ``--agent`` episodes), ``record-env``, ``record-info``,
``record-shots``, ``bench recording``.

Heavy imports (rerun through :mod:`flatbody_env.recording.writer`, gymnasium, matplotlib) happen in
the handlers only.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from flatbody_env.cli.args import add_integration_arguments, add_scene_arguments, check_output_path, int_at_least, load_scene_arg
from flatbody_env.physics import validation
from flatbody_env.physics.validation import MAX_SAMPLES, MIN_SAMPLES
from flatbody_env.output import atomic_write, save_figure




def _rrd_path(text: str) -> str:
    try:
        check_output_path("out", text.replace("{episode}", "0"), (".rrd",))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (a rerun recording file must end in .rrd)") from None
    return text


RECORDING_BYTES_PER_STEP = 2048
"""Upper estimate of a recording's size per logged step, every tensor view included (the measured size:
``record_trajectory``'s MB in the table of ``flatbody bench recording``, docs/recording.md)."""


def check_space(path: str, steps: int, files: int = 1) -> None:
    """Refuse up front (``OSError`` ENOSPC / EFBIG: one line, exit 1) a recording the disk or the
    file-size limit cannot hold, before any work; a disk that fills during the run is one line too
    (:mod:`flatbody_env.recording.sink`), but only once the run has got that far."""
    import errno
    import os
    import resource
    import shutil

    need = (1 << 20) + RECORDING_BYTES_PER_STEP * int(steps)
    folder = os.path.dirname(os.path.abspath(path)) or "."
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if soft != resource.RLIM_INFINITY and soft < need:
        raise OSError(errno.EFBIG, f"the file-size limit ({soft} bytes) is below the ~{need} bytes this recording needs", path)
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return
    if free < need * files:
        raise OSError(errno.ENOSPC, f"{free} bytes free, the recording needs ~{need * files}", path)


def _record(args) -> int:
    if args.agent is not None:
        return _record_agent(args)
    check_space(args.out, args.samples)
    import numpy as np

    from flatbody_env.recording.reader import verify_recording
    from flatbody_env.recording.writer import record_trajectory
    from flatbody_env.simulation import simulate

    scene = load_scene_arg(args)
    t_end = args.t_end if args.t_end is not None else scene.t_end
    traj = simulate(
        scene,
        t_end=t_end,
        times=np.linspace(0.0, t_end, args.samples),
        method=args.method,
        rtol=args.rtol,
        atol=args.atol,
        step=args.step,
        model=args.model,
        with_rotation=True,
        max_nfev=args.max_nfev,
        max_wall_time=args.max_seconds,
    )
    from flatbody_env.output import atomic_path

    start = time.perf_counter()
    with atomic_path(args.out) as tmp:  # a killed run never leaves a half-written RUN.rrd
        record_trajectory(traj, scene.body, tmp, title=args.title, tensor_every=args.tensor_every)
    path = Path(args.out)
    elapsed = time.perf_counter() - start
    msg = f"wrote {path} ({traj.t.size} steps of scene {scene.name}, t = 0…{t_end:g}, {traj.method} {traj.model}; logged in {elapsed * 1e3:.0f} ms, importing rerun included)"
    if args.verify:
        verify_recording(path)
        msg += "; rerun rrd verify: ok"
    print(msg)
    print(f"play back with: rerun {path}   (viewer 0.41, the SDK's version)", file=sys.stderr)
    return 0


def _record_agent(args) -> int:
    """``flatbody record --agent [MODEL]``: one seeded episode of a trained agent, recorded through
    the env recorder (the same path as ``flatbody demo`` and ``flatbody record-env``)."""
    if args.scene_file or args.scene:
        raise ValueError("agent: --agent records an environment episode; give no scene")
    from agents.demo import format_demo, rollout
    from agents.evaluate import Agent
    from agents.numpy_policy import trust_policy

    with trust_policy(not args.trust):  # pickles only from trusted folders (docs/reliability.md, Trust model)
        agent = Agent(args.agent or None)
    if args.out:
        check_space(args.out, 1000)
    ep = rollout(agent, seed=args.seed, env_kwargs=agent.env_kwargs, record_to=args.out, title=args.title or f"agent {agent.path.name} (seed {args.seed})",
                 env_id=agent.env_id)
    print(format_demo(ep, seed=args.seed, label=f"agent {agent.path}"))
    msg = f"wrote {ep['path']} ({ep['t'].size} steps)"
    if args.verify:
        from flatbody_env.recording.reader import verify_recording

        verify_recording(ep["path"])  # raises ValueError with rerun's output on failure
        msg += "; rerun rrd verify: ok"
    print(msg)
    return 0


def _make_env(env_id: str, max_steps: int | None):
    import gymnasium as gym

    import flatbody_env  # noqa: F401  (registers the package's environments on import)

    kwargs = {"track_rotation": True}  # the recorder draws R(t): FlatBodyEnv integrates it on request
    if max_steps is not None:
        kwargs["max_episode_steps"] = max_steps
    try:
        return gym.make(env_id, **kwargs)
    except gym.error.Error as exc:
        raise ValueError(f"env-id: cannot make {env_id!r} ({exc})") from None
    except TypeError as exc:
        raise ValueError(f"env-id: {env_id!r} does not take track_rotation=True, which recording needs ({exc})") from None


def _record_env(args) -> int:
    import numpy as np

    from flatbody_env.progress import progress_bar
    from flatbody_env.recording.reader import verify_recording
    from flatbody_env.recording.wrapper import RerunRecorder

    check_space(args.out, args.max_steps or 1000, files=args.episodes)
    env = RerunRecorder(_make_env(args.env_id, args.max_steps), args.out, tensor_every=args.tensor_every)
    space = env.action_space
    space.seed(args.seed)
    zero = np.clip(np.zeros(space.shape, dtype=space.dtype), space.low, space.high) if hasattr(space, "low") else None
    if args.policy == "zero" and zero is None:
        raise ValueError("policy: 'zero' needs a Box action space; use --policy random")
    total_steps = 0
    try:
        for ep in range(args.episodes):
            env.reset(seed=args.seed + ep)
            done = False
            with progress_bar(desc=f"episode {ep}", unit="step", leave=False) as bar:
                while not done:
                    action = zero if args.policy == "zero" else space.sample()
                    _, _, terminated, truncated, _ = env.step(action)
                    done = terminated or truncated
                    total_steps += 1
                    bar.update()
    finally:
        env.close()
    for path in env.recorded_paths:
        if args.verify:
            verify_recording(path)
        print(f"wrote {path}" + ("; rerun rrd verify: ok" if args.verify else ""))
    print(f"{args.episodes} episode(s), {total_steps} steps, policy {args.policy}", file=sys.stderr)
    return 0


def _record_info(args) -> int:
    from flatbody_env.recording.reader import summarize_recording, verify_recording

    path = Path(args.file)
    if path.suffix != ".rrd":
        raise ValueError(f"file: expected a rerun recording ending in .rrd, got {args.file[:60]!r}")
    if not path.is_file():
        raise ValueError(f"file: no regular file {args.file[:60]!r}")
    try:
        summary = summarize_recording(path, rows=args.rows)
    except (RuntimeError, OSError, ValueError) as exc:  # rerun refuses a file that is no recording
        first = str(exc).strip().splitlines()[0][:120] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"file: {args.file[:60]!r} is not a readable rerun recording ({first})") from None
    print(summary)
    if not args.no_verify:
        out = verify_recording(path)
        print(f"rerun rrd verify: {out.splitlines()[-1] if out else 'ok'}")
    return 0


def _record_shots(args) -> int:
    if args.frames is not None:
        return _frame_shot(args)
    if args.file is None:
        raise ValueError("file: name a recording (RUN.rrd), or give --frames for the env's rgb_array frames")
    from flatbody_env.recording.viewer import screenshots

    shots = screenshots(args.file, args.times, args.out, size=args.size, views=args.views, prefix=args.prefix, colors=args.colors)
    for shot in shots:
        print(f"wrote {shot.path}" + (f"  ({shot.view_class} '{shot.view}')" if shot.view else ""))
    reports = sorted({r for shot in shots for r in shot.reports})
    for r in reports:
        print(f"viewer report: {r}", file=sys.stderr)
    return 0


def _frame_shot(args) -> int:
    """``record-shots --frames 0,120``: FlatBody-v0's rgb_array frames after 0 and 120 seeded random actions,
    side by side (:func:`flatbody_env.env.rendering.frame_strip`), written to OUT/PREFIX.png."""
    from PIL import Image

    from flatbody_env.env.rendering import frame_strip
    from flatbody_env.output import atomic_path
    from flatbody_env.recording.viewer import _compact_png

    if args.file is not None:
        raise ValueError("file: --frames draws the env's rgb_array frames; give a recording or --frames, not both")
    strip = frame_strip(args.frames, seed=args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{args.prefix or 'frame-rgb_array'}.png"
    with atomic_path(path) as tmp:
        Image.fromarray(strip).save(tmp, format="PNG", optimize=True)
    _compact_png(path, args.colors)
    print(f"wrote {path}  ({strip.shape[1]}x{strip.shape[0]}: FlatBody-v0, seed {args.seed}, after {', '.join(map(str, args.frames))} random actions)")
    return 0


def _step_list(text: str) -> list[int]:
    try:
        values = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"frames: expected comma-separated step counts, got {text!r}") from None
    if not values or values[0] < 0 or any(b <= a for a, b in zip(values, values[1:])) or values[-1] > validation.MAX_EPISODE_STEPS:
        raise argparse.ArgumentTypeError(f"frames: expected increasing step counts in [0, {validation.MAX_EPISODE_STEPS}], got {text!r}")
    return values


def _float_list(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"times: expected comma-separated seconds, got {text!r}") from None
    if not values or any(not (v >= 0.0) for v in values):
        raise argparse.ArgumentTypeError("times: every time must be a number ≥ 0")
    return values


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size: expected WIDTHxHEIGHT, got {text!r}") from None
    if not (320 <= w <= 4096 and 320 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"size: width and height must be in [320, 4096], got {text!r}")
    return w, h


def _record_bench(args) -> int:
    import platform
    import tempfile

    import numpy as np

    from flatbody_env.recording.reader import sdk_version
    from flatbody_env.recording.writer import Recorder, record_trajectory
    from flatbody_env.scene import load_scene
    from flatbody_env.simulation import simulate

    scene = load_scene(args.scene)
    sizes = sorted({*args.sizes, args.steps})
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    live = None
    first_call = None
    with tempfile.TemporaryDirectory() as tmp:
        # the process's first recording pays for importing rerun: timed apart, not in the medians
        warm = simulate(scene, t_end=scene.t_end, times=np.linspace(0.0, scene.t_end, 1000), with_rotation=True)
        start = time.perf_counter()
        record_trajectory(warm, scene.body, Path(tmp) / "warm-up.rrd")
        first_call = {"steps": 1000, "seconds": time.perf_counter() - start}
        for n in sizes:
            traj = simulate(scene, t_end=scene.t_end, times=np.linspace(0.0, scene.t_end, n), with_rotation=True)
            times = []
            size_bytes = 0
            for r in range(args.repeats):
                path = Path(tmp) / f"bench-{n}-{r}.rrd"
                start = time.perf_counter()
                record_trajectory(traj, scene.body, path)
                times.append(time.perf_counter() - start)
                size_bytes = path.stat().st_size
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
            print(f"whole trajectory, {n:>6} steps: median {np.median(times):.3f} s (min {np.min(times):.3f}, max {np.max(times):.3f}) over {args.repeats} runs, {size_bytes / 1e6:.1f} MB")
            if n == args.steps:
                Y, R, E = traj.y, traj.rotation, traj.energy
                path = Path(tmp) / "bench-live.rrd"
                start = time.perf_counter()
                with Recorder(path, scene.body, block=args.block) as rec:
                    for k in range(n):
                        rec.append(traj.t[k], Y[:, k], R[k], energy=E[k])
                live_s = time.perf_counter() - start
                live = {"steps": n, "block": args.block, "seconds": live_s, "us_per_step": live_s / n * 1e6}
                print(f"live Recorder.append, {n} steps in blocks of {args.block}: {live_s:.3f} s ({live_s / n * 1e6:.1f} µs/step)")
    episode = _episode_bench(args.episode_repeats)
    print(f"recorded env episode (400 steps, random policy): {episode['compiled_method']} carrying R {episode['compiled_s']:.3f} s, "
          f"the former path (scipy DOP853 stepping R) {episode['former_s']:.3f} s: {episode['speedup']:.1f}x faster (same run)")
    print(f"  its stepping alone (nothing recorded): {episode['stepping_compiled_s']:.3f} s vs {episode['stepping_former_s']:.3f} s: "
          f"{episode['stepping_speedup']:.1f}x; the rest of a recorded episode is the recorder")
    print(f"free scene trajectory with R (scene {scene.name}, t = {scene.t_end:g}, 1001 samples): method auto ({episode['scene_auto_method']}) "
          f"{episode['scene_auto_s'] * 1e3:.1f} ms, scipy DOP853 {episode['scene_scipy_s'] * 1e3:.1f} ms: {episode['scene_speedup']:.1f}x")
    frame = _frame_bench(scene, args.frames)
    print(f"rgb_array frame ({frame['frames']} frames of scene {scene.name}): median {frame['median_ms']:.3f} ms, mean {frame['mean_ms']:.3f} ms — "
          + ("within" if frame["within_budget"] else "OVER") + " the 1 ms budget")
    target = next(r for r in rows if r["steps"] == args.steps)
    result = {
        "benchmark": "recording",
        "what": "record_trajectory(traj, body, path): whole trajectory to a finished .rrd (send_columns), wall time",
        "scene": scene.name,
        "steps": args.steps,
        "median_s": target["median_s"],
        "budget_s": 1.0,
        "within_budget": target["median_s"] <= 1.0,
        "repeats": args.repeats,
        "sizes": rows,
        "live": live,
        "frame": frame,
        "episode": episode,
        "first_call": {**first_call, "note": "the process's first recording: includes importing rerun and starting its batcher"},
        "rerun_sdk": sdk_version(),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpus": __import__("os").cpu_count(),
    }
    json_path = out_dir / "recording.json"
    atomic_write(json_path, json.dumps(result, indent=2) + "\n")
    png_path = out_dir / "recording.png"
    _bench_chart(result, png_path)
    print(f"first call of the process ({first_call['steps']} steps, includes importing rerun): {first_call['seconds']:.3f} s")
    verdict = "within" if result["within_budget"] else "OVER"
    print(f"logging a {args.steps}-step trajectory: {target['median_s']:.3f} s (median of {args.repeats}) — {verdict} the 1 s budget")
    print(f"wrote {json_path} and {png_path}")
    if args.docs:
        from flatbody_env.output import replace_marked_block

        replace_marked_block(args.docs, "recording", recording_table(result))
        print(f"regenerated the table in {args.docs}")
    return 0


def recording_table(result: dict) -> str:
    """The Markdown table of docs/recording.md, from a ``recording.json`` result."""
    sizes = {r["steps"]: r for r in result["sizes"]}
    target = sizes[result["steps"]]
    others = [r for n, r in sorted(sizes.items()) if n != result["steps"]]
    ep, fr, lv, fc = result["episode"], result["frame"], result["live"], result["first_call"]
    lines = [
        "| what | result |",
        "|---|---|",
        f"| recorded env episode, 400 steps ({ep['compiled_method']} carrying R, compiled) | **{ep['compiled_s']:.3f} s** "
        f"(median of {ep['repeats']}) |",
        f"| the same episode on the former path (scipy DOP853 integrating R) | {ep['former_s']:.3f} s: "
        f"**{ep['speedup']:.1f}× slower** (same run) |",
        f"| its stepping alone (the env carrying R, nothing recorded): compiled vs the former path | {ep['stepping_compiled_s'] * 1e3:.0f} ms vs "
        f"{ep['stepping_former_s'] * 1e3:.0f} ms: **{ep['stepping_speedup']:.0f}×** |",
        f"| free scene with R, {ep['scene_samples']} samples: `simulate` method auto ({ep['scene_auto_method']}) vs scipy DOP853 | "
        f"{ep['scene_auto_s'] * 1e3:.1f} ms vs {ep['scene_scipy_s'] * 1e3:.0f} ms ({ep['scene_speedup']:.0f}×) |",
        f"| `record_trajectory`, {result['steps']} steps (budget ≤ 1 s) | **{target['median_s']:.2f} s** (min {target['min_s']:.2f} s; "
        f"{target['file_bytes'] / 1e6:.1f} MB) |",
    ]
    if others:
        counts = " / ".join(str(r["steps"]) for r in others)
        medians = " / ".join(f"{r['median_s']:.3f}" for r in others)
        lines.append(f"| `record_trajectory`, {counts} steps | {medians} s |")
    if lv:
        lines.append(f"| live `Recorder.append`, {lv['steps']} steps in blocks of {lv['block']} | {lv['seconds']:.2f} s "
                     f"({lv['us_per_step']:.0f} µs per step) |")
    lines.append(f"| the process's first recording ({fc['steps']} steps), including `import rerun` | {fc['seconds']:.2f} s |")
    lines.append(f"| `rgb_array` frame, {fr['frames']} frames (budget ≤ 1 ms) | **{fr['median_ms']:.2f} ms** median "
                 f"({fr['mean_ms']:.2f} ms mean) |")
    return "\n".join(lines)


def _episode_bench(repeats: int) -> dict:
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
        start = time.perf_counter()
        env.reset(seed=0)
        done = False
        while not done:
            _, _, term, trunc, info = env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
            done = term or trunc
        env.close()
        return time.perf_counter() - start, info["integrator"]["method"]

    fast, slow, fast_steps, slow_steps = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        episode(Path(tmp) / "warm.rrd")  # compiled kernels loaded, rerun imported
        for r in range(repeats):
            s, method = episode(Path(tmp) / f"fast-{r}.rrd")
            fast.append(s)
            s, _ = episode(Path(tmp) / f"slow-{r}.rrd", integrator="DOP853")
            slow.append(s)
            fast_steps.append(episode(None)[0])  # the same episode carrying R, nothing recorded
            slow_steps.append(episode(None, integrator="DOP853")[0])
    scene = load_scene("default")
    times = np.linspace(0.0, scene.t_end, 1001)
    auto = simulate(scene, t_end=scene.t_end, times=times, with_rotation=True)
    auto_s = min(simulate(scene, t_end=scene.t_end, times=times, with_rotation=True).wall_time for _ in range(repeats))
    scipy_s = min(simulate(scene, t_end=scene.t_end, times=times, with_rotation=True, method="DOP853").wall_time for _ in range(max(1, repeats // 2)))
    return {
        "compiled_method": method, "compiled_s": float(np.median(fast)), "former_s": float(np.median(slow)),
        "speedup": float(np.median(slow) / np.median(fast)), "repeats": repeats,
        "stepping_compiled_s": float(np.median(fast_steps)), "stepping_former_s": float(np.median(slow_steps)),
        "stepping_speedup": float(np.median(slow_steps) / np.median(fast_steps)),
        "scene": scene.name, "scene_samples": int(times.size), "scene_auto_method": auto.method, "scene_auto_s": float(auto_s),
        "scene_scipy_s": float(scipy_s), "scene_speedup": float(scipy_s / auto_s),
    }


def _frame_bench(scene, frames: int) -> dict:
    """Time ``render_frame`` (the env's ``rgb_array`` frame) on the states of a simulated trajectory."""
    import numpy as np

    from flatbody_env.env.rendering import render_frame
    from flatbody_env.simulation import simulate

    traj = simulate(scene, t_end=scene.t_end, times=np.linspace(0.0, scene.t_end, frames), with_rotation=True)
    target = {"lambda": float(traj.state["lambda"][0]), "mu": float(traj.state["mu"][0])}
    Y, R, t = traj.y, traj.rotation, traj.t
    for k in range(min(20, frames)):  # warm-up (font and legend caches)
        render_frame(Y[:, k], R[k], target, t[k])
    times = np.empty(frames)
    for k in range(frames):
        start = time.perf_counter()
        render_frame(Y[:, k], R[k], target, t[k])
        times[k] = time.perf_counter() - start
    median_ms = float(np.median(times)) * 1e3
    return {
        "frames": frames,
        "median_ms": median_ms,
        "mean_ms": float(times.mean()) * 1e3,
        "p90_ms": float(np.percentile(times, 90)) * 1e3,
        "budget_ms": 1.0,
        "within_budget": median_ms <= 1.0,
    }


RECORDING_CAPTION = (
    "record_trajectory: a whole simulated trajectory written at once (rerun's send_columns: one call per series);\n"
    "live Recorder.append: the same steps logged while they are simulated, in blocks. .rrd: rerun's recording file.\n"
    "Points: median of {repeats} repeats; error bars: the fastest and the slowest. Steps: time samples of the trajectory."
)
"""The recording benchmark chart's caption (``{repeats}`` filled in)."""


def _bench_chart(result: dict, path: Path) -> None:
    """The chart of ``recording.json``'s ``result`` (drawn from the saved table, never from a fresh run)."""
    import matplotlib

    from flatbody_env.chart_text import add_caption

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [r["steps"] for r in result["sizes"]]
    med = [r["median_s"] for r in result["sizes"]]
    lo = [r["median_s"] - r["min_s"] for r in result["sizes"]]
    hi = [r["max_s"] - r["median_s"] for r in result["sizes"]]
    fig, ax = plt.subplots(figsize=(6, 4.7))
    ax.errorbar(steps, med, yerr=[lo, hi], marker="o", capsize=3, label="record_trajectory (whole, send_columns)")
    if result.get("live"):
        lv = result["live"]
        ax.plot([lv["steps"]], [lv["seconds"]], "s", color="C1", label=f"live Recorder.append (blocks of {lv['block']})")
    ax.axhline(result["budget_s"], color="C3", ls="--", lw=1, label="budget 1 s at 10 000 steps")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("steps")
    ax.set_ylabel("wall time to a finished .rrd [s]")
    ax.set_title(f"flatbody recording, rerun-sdk {result['rerun_sdk']} ({result['cpus']} CPUs)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    bottom = add_caption(fig, RECORDING_CAPTION.format(repeats=result.get("repeats", "the")), fontsize=7)
    fig.tight_layout(rect=(0, bottom, 1, 1))
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def _int_list(text: str) -> list[int]:
    try:
        values = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"sizes: expected comma-separated integers, got {text!r}") from None
    if not values or min(values) < 2:
        raise argparse.ArgumentTypeError("sizes: every size must be an integer ≥ 2")
    return values


def register(sub) -> None:
    p = sub.add_parser("record", help="simulate a scene and write a rerun recording (.rrd) for offline playback")
    add_scene_arguments(p)
    add_integration_arguments(p)
    p.add_argument("--out", required=True, type=_rrd_path, metavar="RUN.rrd", help="the recording file")
    p.add_argument("--samples", type=int_at_least("samples", MIN_SAMPLES, MAX_SAMPLES), default=1001, metavar="N", help="recorded steps, evenly spaced in [0, t_end] (default 1001)")
    p.add_argument("--tensor-every", type=int_at_least("tensor_every", 1, validation.MAX_SAMPLES), default=1, metavar="K", help="log the G and C tensor views every K steps (default 1)")
    p.add_argument("--title", default=None, help="recording name shown in the viewer")
    p.add_argument("--verify", action="store_true", help="check the file with 'rerun rrd verify' afterwards")
    p.add_argument("--agent", nargs="?", const="", default=None, metavar="MODEL",
                   help="record an episode of a trained agent instead of a scene (no MODEL: the shipped agent)")
    p.add_argument("--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=7, help="with --agent: the episode's seed (default 7)")
    p.add_argument("--trust", action="store_true", help="with --agent: allow unpickling a model from outside the shipped agent and your own runs")
    p.set_defaults(handler=_record)

    p = sub.add_parser("record-env", help="run episodes of a flat-body environment and record them (.rrd)")
    p.add_argument("--env-id", default="FlatBody-v0", help="gymnasium id (default FlatBody-v0)")
    p.add_argument("--episodes", type=int_at_least("episodes", 1, validation.MAX_EPISODES), default=1, metavar="N", help="episodes to run (default 1)")
    p.add_argument("--policy", choices=("zero", "random"), default="zero", help="actions: zero control or uniform random (default zero)")
    p.add_argument("--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=0, help="seed of the first episode (then seed+1, ...)")
    p.add_argument("--max-steps", type=int_at_least("max_steps", 1, validation.MAX_EPISODE_STEPS), default=None, metavar="N", help="truncate episodes after N steps (default: the env's limit)")
    p.add_argument("--tensor-every", type=int_at_least("tensor_every", 1, validation.MAX_SAMPLES), default=1, metavar="K", help="log the G and C tensor views every K steps")
    p.add_argument("--out", required=True, type=_rrd_path, metavar="RUN.rrd", help="episode 0's file; episode k ≥ 1 goes to RUN-k.rrd ({episode} in the name formats it)")
    p.add_argument("--verify", action="store_true", help="check each file with 'rerun rrd verify'")
    p.set_defaults(handler=_record_env)

    p = sub.add_parser("record-info", help="read a recording back offline and summarize it (entities, rows, first values)")
    p.add_argument("file", metavar="RUN.rrd")
    p.add_argument("--rows", type=int_at_least("rows", 1, validation.MAX_SAMPLES), default=3, help="values shown per series (default 3)")
    p.add_argument("--no-verify", action="store_true", help="skip 'rerun rrd verify'")
    p.set_defaults(handler=_record_info)

    p = sub.add_parser("record-shots", help="screenshots of a recording in the real rerun viewer (Xvfb + software Vulkan), at given times; "
                                             "with --frames, the env's rgb_array frames side by side")
    p.add_argument("file", metavar="RUN.rrd", nargs="?", default=None, help="the recording (not with --frames)")
    p.add_argument("--times", type=_float_list, default=[0.0, 5.0, 10.0], metavar="T1,T2,...", help="sim_time values in seconds (default 0,5,10)")
    p.add_argument("--out", default="shots", metavar="DIR", help="folder of the PNGs (default shots)")
    p.add_argument("--size", type=_size, default=(1600, 1000), metavar="WxH", help="window size (default 1600x1000)")
    p.add_argument("--views", action="store_true", help="also save each visible view on its own")
    p.add_argument("--prefix", default=None, help="file-name prefix (default: the recording's stem)")
    p.add_argument("--colors", type=int_at_least("colors", 0, 256), default=0, metavar="N", help="reduce PNGs to N palette colours (small files for docs; default 0: full colour)")
    p.add_argument("--frames", type=_step_list, default=None, metavar="K1,K2,...",
                   help="instead of a recording: FlatBody-v0's rgb_array frames after K1, K2, ... seeded random actions, side by side, "
                        "in OUT/PREFIX.png (default prefix frame-rgb_array)")
    p.add_argument("--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=7, help="with --frames: the episode's seed (default 7)")
    p.set_defaults(handler=_record_shots)



def register_bench(bench_sub) -> None:
    p = bench_sub.add_parser("recording", help="time to log an N-step trajectory to a finished .rrd (budget 1 s for 10 000) and to draw an rgb_array frame (budget 1 ms)")
    p.add_argument("--steps", type=int_at_least("steps", 2, validation.MAX_EPISODE_STEPS), default=10000, help="the size judged against the 1 s budget (default 10000)")
    p.add_argument("--sizes", type=_int_list, default=[1000, 3000, 30000], metavar="N1,N2,...", help="further sizes for the scaling chart")
    p.add_argument("--repeats", type=int_at_least("repeats", 1, validation.MAX_REPEATS), default=5, help="runs per size (median reported; default 5)")
    p.add_argument("--block", type=int_at_least("block", 1, validation.MAX_SAMPLES), default=256, help="block size of the live-recorder measurement")
    p.add_argument("--frames", type=int_at_least("frames", 2, validation.MAX_SAMPLES), default=2000, help="rgb_array frames timed (budget 1 ms each; default 2000)")
    p.add_argument("--scene", default="default", help="built-in scene that supplies the trajectory")
    p.add_argument("--out-dir", default="bench", metavar="DIR", help="where recording.json and recording.png go (default bench)")
    p.add_argument("--episode-repeats", type=int_at_least("episode_repeats", 1, validation.MAX_REPEATS), default=3,
                   help="recorded env episodes per path (compiled vs the former scipy path; median; default 3)")
    p.add_argument("--docs", metavar="FILE.md", help="also regenerate the table between <!-- bench:recording --> markers in FILE.md")
    p.set_defaults(handler=_record_bench)
