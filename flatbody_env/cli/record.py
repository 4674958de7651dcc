"""Sub-commands for rerun recordings: ``record`` (scenes, ``--agent`` episodes), ``record-env``, ``record-info``,
``record-shots`` (``bench recording``: :mod:`flatbody_env.cli.bench`).

Heavy imports (rerun through :mod:`flatbody_env.recording.writer`, gymnasium, matplotlib) happen in
the handlers only.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from flatbody_env.cli.args import (
    add_integration_arguments,
    add_scene_arguments,
    check_output_path,
    int_at_least,
    load_scene_arg,
)
from flatbody_env.physics import validation
from flatbody_env.physics.validation import MAX_SAMPLES, MIN_SAMPLES


def _rrd_path(text: str) -> str:
    try:
        check_output_path("out", text.replace("{episode}", "0"), (".rrd",))
    except ValueError as exc:  # "expected a file ending in .rrd" or the folder that is missing: said once
        raise argparse.ArgumentTypeError(str(exc)) from None
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
        raise OSError(
            errno.EFBIG, f"the file-size limit ({soft} bytes) is below the ~{need} bytes this recording needs", path
        )
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
    ep = rollout(
        agent,
        seed=args.seed,
        env_kwargs=agent.env_kwargs,
        record_to=args.out,
        title=args.title or f"agent {agent.path.name} (seed {args.seed})",
        env_id=agent.env_id,
    )
    print(format_demo(ep, seed=args.seed, label=f"agent {agent.path}", command="flatbody record"))
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
        raise ValueError(
            f"env-id: {env_id!r} does not take track_rotation=True, which recording needs ({exc})"
        ) from None


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
    heuristic = _heuristic_policy() if args.policy == "heuristic" else None
    total_steps = 0
    try:
        for ep in range(args.episodes):
            obs, _ = env.reset(seed=args.seed + ep)
            done = False
            with progress_bar(desc=f"episode {ep}", unit="step", leave=False) as bar:
                while not done:
                    if heuristic is not None:
                        action = heuristic(env, obs)
                    else:
                        action = zero if args.policy == "zero" else space.sample()
                    obs, _, terminated, truncated, _ = env.step(action)
                    done = terminated or truncated
                    total_steps += 1
                    bar.update()
    finally:
        env.close()
    for path, outcome in zip(env.recorded_paths, env.outcomes):
        if args.verify:
            verify_recording(path)
        print(f"wrote {path}" + (f": {outcome}" if outcome else "") + ("; rerun rrd verify: ok" if args.verify else ""))
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

    shots = screenshots(
        args.file, args.times, args.out, size=args.size, views=args.views, prefix=args.prefix, colors=args.colors
    )
    for shot in shots:
        print(f"wrote {shot.path}" + (f"  ({shot.view_class} '{shot.view}')" if shot.view else ""))
    reports = sorted({r for shot in shots for r in shot.reports})
    for r in reports:
        print(f"viewer report: {r}", file=sys.stderr)
    return 0


def _heuristic_policy():
    """The LQR baseline (:class:`agents.heuristic.HeuristicController`) as ``policy(env, obs)`` (record-env, and
    frame_strip for record-shots --frames)."""
    import numpy as np

    from agents.heuristic import HeuristicController

    made: dict = {}

    def policy(env, obs):
        u = env.unwrapped
        key = (id(u), u.body)  # a task that draws its body per episode gets its controller anew
        if made.get("key") != key:
            made["key"], made["h"] = key, HeuristicController(u.body, u.control, u.limits)
        return made["h"].act(np.asarray(obs)[None])[0]

    return policy


def _frame_shot(args) -> int:
    """``record-shots --frames 0,120``: the env's rgb_array frames after 0 and 120 actions (seeded random ones, or
    the LQR baseline's with ``--policy heuristic``), side by side with the episode's status
    (:func:`flatbody_env.env.rendering.frame_strip`), written to OUT/PREFIX.png."""
    from PIL import Image

    from flatbody_env.env.rendering import frame_strip
    from flatbody_env.output import atomic_path
    from flatbody_env.recording.viewer import _compact_png

    if args.file is not None:
        raise ValueError("file: --frames draws the env's rgb_array frames; give a recording or --frames, not both")
    policy = _heuristic_policy() if args.policy == "heuristic" else None
    strip = frame_strip(args.frames, seed=args.seed, env_id=args.env_id, policy=policy)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{args.prefix or 'frame-rgb_array'}.png"
    with atomic_path(path) as tmp:
        Image.fromarray(strip).save(tmp, format="PNG", optimize=True)
    _compact_png(path, args.colors)
    actions = "random actions" if args.policy == "random" else "actions of the LQR baseline"
    print(
        f"wrote {path}  ({strip.shape[1]}x{strip.shape[0]}: {args.env_id}, seed {args.seed}, after "
        f"{', '.join(map(str, args.frames))} {actions})"
    )
    return 0


def _step_list(text: str) -> list[int]:
    try:
        values = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"frames: expected comma-separated step counts, got {text!r}") from None
    if (
        not values
        or values[0] < 0
        or any(b <= a for a, b in zip(values, values[1:]))
        or values[-1] > validation.MAX_EPISODE_STEPS
    ):
        raise argparse.ArgumentTypeError(
            f"frames: expected increasing step counts in [0, {validation.MAX_EPISODE_STEPS}], got {text!r}"
        )
    return values


def _float_list(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"times: expected comma-separated seconds, got {text!r}") from None
    if not values or any(not (v >= 0.0) for v in values):
        raise validation.refusal("times", "each be a number ≥ 0", text, error=argparse.ArgumentTypeError)
    return values


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size: expected WIDTHxHEIGHT, got {text!r}") from None
    if not (320 <= w <= 4096 and 320 <= h <= 4096):
        raise validation.refusal("size", "have width and height in [320, 4096]", text, error=argparse.ArgumentTypeError)
    return w, h


def register(sub) -> None:
    p = sub.add_parser("record", help="simulate a scene and write a rerun recording (.rrd) for offline playback")
    add_scene_arguments(p)
    add_integration_arguments(p)
    p.add_argument("--out", required=True, type=_rrd_path, metavar="RUN.rrd", help="the recording file")
    p.add_argument(
        "--samples",
        type=int_at_least("samples", MIN_SAMPLES, MAX_SAMPLES),
        default=1001,
        metavar="N",
        help="recorded steps, evenly spaced in [0, t_end] (default 1001)",
    )
    p.add_argument(
        "--tensor-every",
        type=int_at_least("tensor_every", 1, validation.MAX_SAMPLES),
        default=1,
        metavar="K",
        help="log the G and C tensor views every K steps (default 1)",
    )
    p.add_argument("--title", default=None, help="recording name shown in the viewer")
    p.add_argument("--verify", action="store_true", help="check the file with 'rerun rrd verify' afterwards")
    p.add_argument(
        "--agent",
        nargs="?",
        const="",
        default=None,
        metavar="MODEL",
        help="record an episode of a trained agent instead of a scene (no MODEL: the shipped agent)",
    )
    p.add_argument(
        "--seed",
        type=int_at_least("seed", 0, validation.MAX_SEED),
        default=7,
        help="with --agent: the episode's seed (default 7)",
    )
    p.add_argument(
        "--trust",
        action="store_true",
        help="with --agent: allow unpickling a model from outside the shipped agent and your own runs",
    )
    p.set_defaults(handler=_record)

    p = sub.add_parser("record-env", help="run episodes of a flat-body environment and record them (.rrd)")
    p.add_argument("--env-id", default="FlatBody-v1", help="gymnasium id (default FlatBody-v1)")
    p.add_argument(
        "--episodes",
        type=int_at_least("episodes", 1, validation.MAX_EPISODES),
        default=1,
        metavar="N",
        help="episodes to run (default 1)",
    )
    p.add_argument(
        "--policy",
        choices=("zero", "random", "heuristic"),
        default="zero",
        help="actions: zero control, uniform random or the LQR baseline (agents.heuristic) (default zero)",
    )
    p.add_argument(
        "--seed",
        type=int_at_least("seed", 0, validation.MAX_SEED),
        default=0,
        help="seed of the first episode (then seed+1, ...)",
    )
    p.add_argument(
        "--max-steps",
        type=int_at_least("max_steps", 1, validation.MAX_EPISODE_STEPS),
        default=None,
        metavar="N",
        help="truncate episodes after N steps (default: the env's limit)",
    )
    p.add_argument(
        "--tensor-every",
        type=int_at_least("tensor_every", 1, validation.MAX_SAMPLES),
        default=1,
        metavar="K",
        help="log the G and C tensor views every K steps",
    )
    p.add_argument(
        "--out",
        required=True,
        type=_rrd_path,
        metavar="RUN.rrd",
        help="episode 0's file; episode k ≥ 1 goes to RUN-k.rrd ({episode} in the name formats it)",
    )
    p.add_argument("--verify", action="store_true", help="check each file with 'rerun rrd verify'")
    p.set_defaults(handler=_record_env)

    p = sub.add_parser(
        "record-info", help="read a recording back offline and summarize it (entities, rows, first values)"
    )
    p.add_argument("file", metavar="RUN.rrd")
    p.add_argument(
        "--rows",
        type=int_at_least("rows", 1, validation.MAX_SAMPLES),
        default=3,
        help="values shown per series (default 3)",
    )
    p.add_argument("--no-verify", action="store_true", help="skip 'rerun rrd verify'")
    p.set_defaults(handler=_record_info)

    p = sub.add_parser(
        "record-shots",
        help="screenshots of a recording in the real rerun viewer (Xvfb + software Vulkan), at given times; "
        "with --frames, the env's rgb_array frames side by side",
    )
    p.add_argument("file", metavar="RUN.rrd", nargs="?", default=None, help="the recording (not with --frames)")
    p.add_argument(
        "--times",
        type=_float_list,
        default=[0.0, 5.0, 10.0],
        metavar="T1,T2,...",
        help="sim_time values in seconds (default 0,5,10)",
    )
    p.add_argument("--out", default="shots", metavar="DIR", help="folder of the PNGs (default shots)")
    p.add_argument("--size", type=_size, default=(1600, 1000), metavar="WxH", help="window size (default 1600x1000)")
    p.add_argument("--views", action="store_true", help="also save each visible view on its own")
    p.add_argument("--prefix", default=None, help="file-name prefix (default: the recording's stem)")
    p.add_argument(
        "--colors",
        type=int_at_least("colors", 0, 256),
        default=0,
        metavar="N",
        help="reduce PNGs to N palette colours (small files for docs; default 0: full colour)",
    )
    p.add_argument(
        "--frames",
        type=_step_list,
        default=None,
        metavar="K1,K2,...",
        help="instead of a recording: FlatBody-v1's rgb_array frames after K1, K2, ... seeded random actions, side by side, "
        "in OUT/PREFIX.png (default prefix frame-rgb_array)",
    )
    p.add_argument(
        "--seed",
        type=int_at_least("seed", 0, validation.MAX_SEED),
        default=7,
        help="with --frames: the episode's seed (default 7)",
    )
    p.add_argument(
        "--policy",
        choices=("random", "heuristic"),
        default="random",
        help="with --frames: seeded random actions or the LQR baseline's, which reaches the target (default random)",
    )
    p.add_argument("--env-id", default="FlatBody-v1", help="with --frames: the task (default FlatBody-v1)")
    p.set_defaults(handler=_record_shots)
