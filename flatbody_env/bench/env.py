"""``flatbody bench env``: environment step rates, measured side by side in one run.

Single environments (``gym.make``, so each carries the same PassiveEnvChecker, OrderEnforcing and
TimeLimit wrappers): ``FlatBody-v1`` against gymnasium's ``Pendulum-v1`` and ``Acrobot-v1`` — the
figure of merit is the ratio of ``env.step`` rates, the three timed in alternation (resets are timed
apart and reported, since ``FlatBody-v1``'s reset samples a reachable target; the machine is noisy,
absolute times vary with load, the ratios are the reliable part; the figures: docs/env.md, "Benchmark").
Batched: ``FlatBodyVectorEnv`` against gymnasium's ``CartPoleVectorEnv`` at N = 1024 in env-steps per
second (the vector env as constructed by default and with one thread per core, timed in alternation
with CartPole), plus the batched env's episode error against a tight reference (scipy DOP853,
rtol = atol = 1e-13, restarted every step with the same actions). Each rate is the best of ``repeats``
timed blocks (:mod:`.harness`). The batched FlatBody figure includes resets: a timed block is one whole
episode of every body at the registered length plus the step that autoresets them (CartPole's
random-action episodes end and autoreset within its blocks). :func:`report` gives the JSON, CSV, PNG
chart and the tables (:func:`tables`: the terminal's text and the ``<!-- bench:env -->`` docs block).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from flatbody_env.bench.harness import Report, Stopwatch, Table, alternate
from flatbody_env.physics import validation

SINGLE = ("FlatBody-v1", "Pendulum-v1", "Acrobot-v1")
"""The single environments, timed in alternation."""


@dataclass(frozen=True, kw_only=True)
class StepRate:
    """One row: the step rate of an environment (``batch`` bodies per step)."""

    name: str
    batch: int
    us_per_env_step: float
    env_steps_per_s: float
    ms_per_reset: float | None = None


@dataclass(frozen=True, kw_only=True)
class EnvBenchmark:
    """The rates and ratios of one run (the JSON record)."""

    single: list[StepRate]
    batched: list[StepRate]
    ratio_vs_pendulum: float
    ratio_vs_acrobot: float
    ratio_batched_vs_cartpole: float
    episode_error: float
    integrator: str
    reset_ratio_vs_pendulum: float = float("nan")
    """ms per ``FlatBody-v1`` reset / ms per ``Pendulum-v1`` reset (target ≤ 5)."""
    ratio_batched_threads_vs_cartpole: float = float("nan")
    """The batched ratio with ``num_threads=None`` (one thread per available core)."""
    threads: int = 1
    """Threads that ``num_threads=None`` gave (one per available core, at most one per 256 bodies)."""


def _time_single(env_ids, steps: int, repeats: int, progress) -> dict[str, tuple[float, float]]:
    """``{env_id: (seconds per env.step, seconds per env.reset)}``, the envs timed in alternation; resets are
    timed apart, not in the step rate."""
    import gymnasium as gym

    envs = {env_id: gym.make(env_id) for env_id in env_ids}
    resets: dict[str, list[float]] = {env_id: [] for env_id in env_ids}

    def block(env_id):
        env = envs[env_id]
        env.reset(seed=0)
        action = env.action_space.sample()
        if isinstance(action, np.ndarray):
            action = np.zeros_like(action)

        def run() -> float:
            in_resets = 0.0
            with Stopwatch() as block_time:
                for _ in range(steps):
                    _, _, term, trunc, _ = env.step(action)
                    if term or trunc:
                        with Stopwatch() as one:
                            env.reset()
                        resets[env_id].append(one.seconds)
                        in_resets += one.seconds
            return block_time.seconds - in_resets

        return run

    best = alternate({env_id: block(env_id) for env_id in env_ids}, repeats, warm=False, progress=progress)
    out = {}
    for env_id, env in envs.items():
        if not resets[env_id]:
            for k in range(3):
                with Stopwatch() as one:
                    env.reset(seed=k)
                resets[env_id].append(one.seconds)
        env.close()
        out[env_id] = (best[env_id] / steps, float(np.median(resets[env_id])))
    return out


def _time_batched(
    n: int, episode_steps: int, cartpole_steps: int, rounds: int, progress
) -> tuple[float, float, float, int]:
    """(s per env-step of FlatBodyVectorEnv as constructed by default (one thread), with ``num_threads=None``
    (one per available core), of CartPoleVectorEnv; the thread count of the second), timed in alternation.
    A FlatBody block is ``max_episode_steps + 1`` steps: one whole episode from an autoreset plus the step
    that autoresets every body (the untimed warm-up round compiles and ends at an autoreset)."""
    from gymnasium.envs.classic_control.cartpole import CartPoleVectorEnv

    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    rng = np.random.default_rng(0)
    from flatbody_env.env.registration import task_spec

    kw = dict(task_spec("FlatBody-v1").kwargs)
    fb = FlatBodyVectorEnv(num_envs=n, max_episode_steps=episode_steps, **kw)
    fbt = FlatBodyVectorEnv(num_envs=n, max_episode_steps=episode_steps, num_threads=None, **kw)
    cp = CartPoleVectorEnv(num_envs=n)
    actions = rng.uniform(-1, 1, size=fb.action_space.shape).astype(np.float32)
    cp_actions = cp.action_space.sample()
    blocks = {
        "fb": (fb, actions, fb.max_episode_steps + 1),
        "fbt": (fbt, actions, fbt.max_episode_steps + 1),
        "cp": (cp, cp_actions, cartpole_steps),
    }
    for env, _, _ in blocks.values():
        env.reset(seed=0)

    def block(env, a, steps):
        def run() -> None:
            for _ in range(steps):
                env.step(a)

        return run

    best = alternate({key: block(*b) for key, b in blocks.items()}, rounds, progress=progress)
    per_step = {key: best[key] / (steps * env.num_envs) for key, (env, _, steps) in blocks.items()}
    threads = fbt.num_threads
    for env, _, _ in blocks.values():
        env.close()
    return per_step["fb"], per_step["fbt"], per_step["cp"], threads


def episode_error(num_envs: int = 16, steps: int = 400, seed: int = 0, **env_kwargs) -> float:
    """Max |y − y_ref| over an episode of the batched env with random actions (reference: tight scipy)."""
    from flatbody_env.env.vector_env import FlatBodyVectorEnv
    from flatbody_env.integrators import Tolerances
    from flatbody_env.integrators.steppers import make_env_step
    from flatbody_env.physics.body import default_body

    env = FlatBodyVectorEnv(num_envs=num_envs, max_episode_steps=steps + 1, **env_kwargs)
    env.reset(seed=seed)
    ref = make_env_step(
        "DOP853", env.body if env.body is not None else default_body(), Tolerances(rtol=1e-13, atol=1e-13)
    )
    Yref = env.states
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(steps):
        A = rng.uniform(-1, 1, size=(num_envs,) + env.single_action_space.shape)
        U = env.controls(A)
        _, _, term, _, _ = env.step(A)
        for i in range(num_envs):
            out = Yref[i].copy()  # a failed step keeps the old state
            ref.advance(Yref[i].copy(), U[i], env.dt, out, np.zeros(3, np.int64))
            Yref[i] = out
        alive = ~term
        if alive.any():
            worst = max(worst, float(np.max(np.abs(env.states[alive] - Yref[alive]))))
        if term.all():
            break
    return worst


def run(
    *,
    steps: int = 2000,
    batch: int = 1024,
    batch_steps: int = 50,
    repeats: int = 5,
    progress: bool = True,
    episode_steps: int | None = None,
) -> EnvBenchmark:
    """Measure (module docstring); ``episode_steps`` (default: the registered 400) is the batched env's episode length."""
    from flatbody_env.env.env import DEFAULT_INTEGRATOR
    from flatbody_env.env.registration import MAX_EPISODE_STEPS
    from flatbody_env.progress import progress_bar

    episode_steps = episode_steps or MAX_EPISODE_STEPS
    tasks = ["single envs", "batched FlatBody vs CartPole", "episode error"]
    bar = progress_bar(tasks, desc="bench env", unit="task", enabled=progress)
    results = {}
    for task in bar:
        bar.set_postfix_str(task)
        if task == "single envs":
            results["single"] = _time_single(
                SINGLE, steps, repeats, lambda k, task=task: bar.set_postfix_str(f"{task} ({k}/{repeats})")
            )
        elif task == "batched FlatBody vs CartPole":
            rounds = max(2, repeats // 2 + 1)
            results["fb"], results["fbt"], results["cp"], results["threads"] = _time_batched(
                batch,
                episode_steps,
                batch_steps * 10,
                rounds,
                lambda k, task=task, rounds=rounds: bar.set_postfix_str(f"{task} ({k}/{rounds})"),
            )
        else:
            results["err"] = episode_error()
    single = [
        StepRate(name=name, batch=1, us_per_env_step=s * 1e6, env_steps_per_s=1.0 / s, ms_per_reset=r * 1e3)
        for name, (s, r) in results["single"].items()
    ]
    t = results["threads"]
    batched = [
        StepRate(
            name=f"FlatBodyVectorEnv (N={batch})",
            batch=batch,
            us_per_env_step=results["fb"] * 1e6,
            env_steps_per_s=1.0 / results["fb"],
        ),
        StepRate(
            name=f"FlatBodyVectorEnv (N={batch}, {t} thread{'s' if t > 1 else ''})",
            batch=batch,
            us_per_env_step=results["fbt"] * 1e6,
            env_steps_per_s=1.0 / results["fbt"],
        ),
        StepRate(
            name=f"CartPoleVectorEnv (N={batch})",
            batch=batch,
            us_per_env_step=results["cp"] * 1e6,
            env_steps_per_s=1.0 / results["cp"],
        ),
    ]
    by = {r.name: r for r in single}
    return EnvBenchmark(
        single=single,
        batched=batched,
        ratio_vs_pendulum=by["Pendulum-v1"].us_per_env_step / by["FlatBody-v1"].us_per_env_step,
        ratio_vs_acrobot=by["Acrobot-v1"].us_per_env_step / by["FlatBody-v1"].us_per_env_step,
        ratio_batched_vs_cartpole=batched[0].env_steps_per_s / batched[2].env_steps_per_s,
        ratio_batched_threads_vs_cartpole=batched[1].env_steps_per_s / batched[2].env_steps_per_s,
        threads=t,
        episode_error=results["err"],
        integrator=DEFAULT_INTEGRATOR,
        reset_ratio_vs_pendulum=by["FlatBody-v1"].ms_per_reset / by["Pendulum-v1"].ms_per_reset,
    )


def load(json_path: str | Path) -> EnvBenchmark:
    """An :class:`EnvBenchmark` from its saved ``env_benchmark.json``."""
    data = validation.read_json("--plot-only", json_path)
    fields = set(EnvBenchmark.__dataclass_fields__)
    rows = {k: [StepRate(**r) for r in data[k]] for k in ("single", "batched")}
    return EnvBenchmark(**{k: v for k, v in data.items() if k in fields and k not in rows}, **rows)


def report(bench: EnvBenchmark) -> Report:
    """``env_benchmark.json``, ``.csv``, ``.png`` (drawn from the CSV) and the tables (:func:`tables`, the
    ``<!-- bench:env -->`` block)."""
    return Report(
        name="env_benchmark",
        record=asdict(bench),
        header=["name", "batch", "us_per_env_step", "env_steps_per_s"],
        rows=[
            [r.name, r.batch, f"{r.us_per_env_step:.6g}", f"{r.env_steps_per_s:.6g}"]
            for r in bench.single + bench.batched
        ],
        chart=plot,
        chart_from="csv",
        tables=tables(bench),
        block="env",
    )


ENV_CAPTION = (
    "Blue: flatbody's environments; grey: the yardsticks from Gymnasium (Pendulum-v1, Acrobot-v1 one env at a time;\n"
    "CartPoleVectorEnv: Gymnasium's vectorised CartPole). N = 1024: bodies stepped together as one batch per call;\n"
    "2 threads: the batch split over one thread per core (num_threads=None). Bar labels: env-steps per second."
)
"""The chart's caption: the colours, N, threads."""


def plot(csv_path: Path, png_path: Path) -> None:
    """Bar chart of env-steps/s from the saved CSV (log scale), with :data:`ENV_CAPTION` under it."""
    from flatbody_env.figures import PALETTE, chart

    rows = validation.read_csv("--plot-only", csv_path)  # the one reading door
    names = [r["name"] for r in rows]
    rates = [float(r["env_steps_per_s"]) for r in rows]
    colours = [PALETTE["ours"] if "FlatBody" in n else PALETTE["yardstick"] for n in names]
    with chart(png_path, size=(7.6, 4.4)) as c:
        ax = c.ax
        ax.barh(names, rates, color=colours)
        ax.set_xscale("log")
        ax.set_xlim(min(rates) / 3, max(rates) * 8)
        ax.set_xlabel("env-steps per second (higher is better)")
        for y, r in enumerate(rates):
            ax.text(r, y, f" {r:,.0f}", va="center", fontsize=8)
        ax.set_title("flatbody bench env (same run)")
        c.caption(ENV_CAPTION, fontsize=7)


BATCHED_TARGET = 0.3
"""The v1 suite's target for ``FlatBodyVectorEnv`` / ``CartPoleVectorEnv`` at N = 1024 (env-steps per second)."""


def _met(x: float, bound: float, *, at_most: bool = False) -> str:
    return "met" if (x <= bound if at_most else x >= bound) else "missed"


def tables(bench: EnvBenchmark) -> list[Table]:
    """The rates and the ratios of this run (the terminal's text and the docs' ``env`` block)."""
    rates = [
        [r.name, f"{r.us_per_env_step:.3g}", f"{r.env_steps_per_s:,.0f}", f"{r.ms_per_reset:.3g}"] for r in bench.single
    ]
    for r in bench.batched:
        name = r.name[:-1] + ", resets included)" if r.name.startswith("FlatBody") else r.name
        rates.append([name, f"{r.us_per_env_step:.3g}", f"{r.env_steps_per_s:,.0f}", "—"])
    first = bench.single[0].name if bench.single else "FlatBody-v1"
    t = f"{bench.threads} thread{'s' if bench.threads > 1 else ''}"
    ratios = [
        [
            f"`{first}` step rate / `Pendulum-v1`",
            f"**{bench.ratio_vs_pendulum:.2f}**",
            f"≥ 1.0 ({_met(bench.ratio_vs_pendulum, 1.0)})",
        ],
        [f"`{first}` step rate / `Acrobot-v1`", f"{bench.ratio_vs_acrobot:.2f}", "—"],
        [
            f"`{first}` reset time / `Pendulum-v1`",
            f"**{bench.reset_ratio_vs_pendulum:.2f}**",
            f"≤ 5 ({_met(bench.reset_ratio_vs_pendulum, 5.0, at_most=True)})",
        ],
        [
            f"`FlatBodyVectorEnv` / `CartPoleVectorEnv` (N = {bench.batched[0].batch}, resets included)",
            f"**{bench.ratio_batched_vs_cartpole:.2f}**",
            f"≥ {BATCHED_TARGET} ({_met(bench.ratio_batched_vs_cartpole, BATCHED_TARGET)})",
        ],
        [f"the same with `num_threads=None` ({t})", f"{bench.ratio_batched_threads_vs_cartpole:.2f}", "—"],
        [
            "batched episode error vs tight reference",
            f"{bench.episode_error:.1e}",
            f"≤ 1e-8 ({_met(bench.episode_error, 1e-8, at_most=True)})",
        ],
    ]
    return [
        Table(columns=["what", "µs per env step", "env-steps/s", "ms per reset"], rows=rates),
        Table(
            columns=["ratio (same run)", "measured", "target"],
            rows=ratios,
            notes=[f"integrator of the FlatBody envs: {bench.integrator}"],
        ),
    ]


__all__ = [
    "ENV_CAPTION",
    "EnvBenchmark",
    "SINGLE",
    "StepRate",
    "episode_error",
    "load",
    "plot",
    "report",
    "run",
    "tables",
]
