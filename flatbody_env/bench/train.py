"""``flatbody bench train``: PPO's wall time on ``FlatBody-v0`` against the same PPO on ``Pendulum-v1``.

Both runs use the shipped PPO configuration (``agents/hyperparams/ppo.yml``: the same network,
n_envs, n_steps, batch size, epochs, gSDE, VecNormalize, one torch thread) for the same number of
environment steps, in alternation in the same process (:func:`~flatbody_env.bench.harness.alternate`).
``FlatBody-v0`` runs exactly as training does (:func:`agents.train.make_vec_env`: the native batch, the
residual on the LQR); ``Pendulum-v1`` runs as a ``DummyVecEnv`` of ``gym.make`` envs (seeded as SB3's
``make_vec_env`` seeds them) without the FlatBody-only keys (residual, env_kwargs), under the same single
``VecMonitor`` as FlatBody's stack (``make_vec_env``'s per-env ``Monitor`` on top of it would count
every step twice and charge Pendulum for it). A timing wrapper directly around each environment
stack (below ``VecMonitor``/``VecNormalize``) measures the share of the wall time spent in the
environment and, for FlatBody, in the LQR the actions are built on. Each figure is the best of
``repeats`` runs. Writes ``train_benchmark.json``, ``.csv`` and ``.png`` (and the ``<!-- bench:train -->``
docs block when asked).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from flatbody_env.bench.harness import Report, Stopwatch, Table, alternate, best_of, write_report
from flatbody_env.physics import validation

FLATBODY_ONLY = ("residual", "residual_mode", "residual_scale", "residual_gate", "env_kwargs")
"""The PPO settings that only FlatBody-v0 takes (left out of the Pendulum-v1 run)."""


@dataclass(frozen=True, kw_only=True)
class TrainTiming:
    """One PPO run.

    Attributes
    ----------
    env_id : str
    timesteps : int
        Environment steps PPO took.
    wall_s : float
        Wall time of ``learn``.
    env_s : float
        Seconds inside the environment stack (for FlatBody: the env and the LQR of the residual).
    """

    env_id: str
    timesteps: int
    wall_s: float
    env_s: float

    @property
    def env_share(self) -> float:
        """Share of the wall time inside the environment stack."""
        return self.env_s / self.wall_s


@dataclass(frozen=True, kw_only=True)
class TrainBenchmark:
    """The two runs and the figures of the docs' table.

    Attributes
    ----------
    flatbody, pendulum : TrainTiming
        The fastest run of each.
    ratio_wall : float
        FlatBody wall time / Pendulum wall time (target ≤ 1.0).
    flatbody_env_share : float
        Share of FlatBody's wall time in the environment + LQR (target ≤ 0.15).
    pendulum_env_share : float
    lqr_us_per_body_step : float
        The LQR's vectorised action (batch of ``n_envs``, gains stored) per body-step, in µs.
    n_envs : int
    """

    flatbody: TrainTiming
    pendulum: TrainTiming
    ratio_wall: float
    flatbody_env_share: float
    pendulum_env_share: float
    lqr_us_per_body_step: float
    n_envs: int = 32


def _timed(venv):
    """``venv`` under a wrapper whose :class:`~flatbody_env.bench.harness.Stopwatch` adds up the time inside it."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    clock = Stopwatch()

    class Timed(VecEnvWrapper):
        def reset(self):
            with clock:
                return self.venv.reset()

        def step_async(self, actions):
            with clock:
                self.venv.step_async(actions)

        def step_wait(self):
            with clock:
                return self.venv.step_wait()

    return Timed(venv), clock


def _run(env_id: str, hp: dict, timesteps: int, seed: int) -> TrainTiming:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor, VecNormalize

    from agents.train import algo_kwargs_of, normalize_of

    torch.set_num_threads(1)
    n = int(hp.get("n_envs", 1))
    if env_id == "FlatBody-v0":
        from agents.vec_env import FlatBodySB3VecEnv

        inner = FlatBodySB3VecEnv(n, seed=seed, **(hp.get("env_kwargs") or {}))
        if hp.get("residual"):
            from agents.heuristic import residual_vec_env

            inner = residual_vec_env(
                inner,
                hp.get("env_kwargs"),
                float(hp.get("residual_scale", 1.0)),
                float(hp.get("residual_gate", 0.0)),
                str(hp.get("residual_mode", "additive")),
            )
        venv, clock = _timed(inner)  # the stack of agents.train.make_vec_env, with the clock inside VecMonitor
        venv = VecMonitor(venv)
    else:  # gym.make envs in SB3's DummyVecEnv, seeded as make_vec_env seeds them, monitored as FlatBody's stack is
        import gymnasium as gym

        base = DummyVecEnv([lambda: gym.make(env_id) for _ in range(n)])
        base.seed(seed)
        venv, clock = _timed(base)
        venv = VecMonitor(venv)
    norm = normalize_of(hp)
    if norm:
        venv = VecNormalize(venv, gamma=float(hp.get("gamma", 0.99)), **norm)
    model = PPO(hp.get("policy", "MlpPolicy"), venv, seed=seed, device="cpu", verbose=0, **algo_kwargs_of(hp))
    with Stopwatch() as learning:
        model.learn(total_timesteps=timesteps, progress_bar=False)
    venv.close()
    return TrainTiming(
        env_id=env_id, timesteps=int(model.num_timesteps), wall_s=learning.seconds, env_s=float(clock.seconds)
    )


def lqr_us_per_body_step(n_envs: int = 32, steps: int = 400, seed: int = 0) -> float:
    """µs per body-step of the LQR's vectorised action on observations of the batched env (gains stored), best of 3."""
    from agents.heuristic import HeuristicController
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    env = FlatBodyVectorEnv(num_envs=n_envs)
    obs, _ = env.reset(seed=seed)
    ctl = HeuristicController(env.body, env.control, env.limits)
    ctl.act(obs)
    observations = []
    for _ in range(steps):
        obs, *_ = env.step(ctl.act(obs))
        observations.append(obs)

    def act_all() -> None:
        for o in observations:
            ctl.act(o)

    return best_of(act_all, 3, warm=False) / (steps * n_envs) * 1e6


def run(
    *,
    timesteps: int = 64_000,
    repeats: int = 1,
    seed: int = 0,
    out_dir: str | Path = ".",
    overrides: list[str] | None = None,
    docs: str | Path | None = None,
) -> TrainBenchmark:
    """Measure and write ``train_benchmark.json``, ``.csv``, ``.png`` into ``out_dir`` (module docstring).

    Parameters
    ----------
    overrides : list of str, optional
        ``key=value`` changes of the PPO settings of both runs.
    docs : path, optional
        A Markdown page whose ``<!-- bench:train -->`` block gets this run's table.
    """
    from agents.config import apply_overrides, check_hyperparams, load_hyperparams

    hp = apply_overrides(load_hyperparams("ppo", "FlatBody-v0"), overrides or [])
    hp = check_hyperparams("ppo", hp, "FlatBody-v0")  # the one validator set: a bad override names its field
    settings = {"FlatBody-v0": hp, "Pendulum-v1": {k: v for k, v in hp.items() if k not in FLATBODY_ONLY}}
    runs: dict[str, list[TrainTiming]] = {env_id: [] for env_id in settings}

    def case(env_id: str):
        def once() -> float:
            runs[env_id].append(_run(env_id, settings[env_id], timesteps, seed))
            return runs[env_id][-1].wall_s

        return once

    alternate({env_id: case(env_id) for env_id in settings}, repeats, warm=False)
    fb, pd = (min(runs[env_id], key=lambda r: r.wall_s) for env_id in settings)
    n_envs = int(hp.get("n_envs", 32))
    bench = TrainBenchmark(
        flatbody=fb,
        pendulum=pd,
        ratio_wall=fb.wall_s / pd.wall_s,
        flatbody_env_share=fb.env_share,
        pendulum_env_share=pd.env_share,
        lqr_us_per_body_step=lqr_us_per_body_step(n_envs),
        n_envs=n_envs,
    )
    write_report(report(bench), out_dir, docs=docs)
    return bench


def report(bench: TrainBenchmark) -> Report:
    """``train_benchmark``'s files: the record, one CSV row per run, the chart drawn from the CSV, the docs block ``train``."""
    return Report(
        name="train_benchmark",
        record=asdict(bench),
        header=["env_id", "timesteps", "wall_s", "env_s", "env_share"],
        rows=[
            [r.env_id, r.timesteps, f"{r.wall_s:.4g}", f"{r.env_s:.4g}", f"{r.env_share:.4f}"]
            for r in (bench.flatbody, bench.pendulum)
        ],
        chart=plot,
        chart_from="csv",
        tables=tables(bench),
        block="train",
    )


CAPTION = (
    "environment: time spent inside the environment stack's step/reset; for FlatBody-v0 it includes the LQR\n"
    "(linear-quadratic regulator: the baseline controller whose action the agent's output is added to, as in training).\n"
    "PPO: Proximal Policy Optimization (stable-baselines3, agents/hyperparams/ppo.yml): the rest of the wall time,\n"
    "i.e. the policy's forward passes while collecting rollouts and the gradient updates. Pendulum-v1 (Gymnasium) is the yardstick.\n"
    "Bar labels: total wall time (share of it in the environment). Best of the repeats, one process."
)
"""The chart's caption: what each colour and the bar labels mean."""


def plot(csv_path: Path, png_path: Path) -> None:
    """Stacked bars (environment vs the rest of PPO) from the saved CSV; legend and caption below the axes."""
    from flatbody_env.figures import PALETTE, chart

    rows = validation.read_csv("--plot-only", csv_path)  # the one reading door
    names = [r["env_id"] for r in rows]
    env = [float(r["env_s"]) for r in rows]
    rest = [float(r["wall_s"]) - e for r, e in zip(rows, env, strict=True)]
    with chart(png_path, size=(7.6, 4.4)) as c:
        ax = c.ax
        ax.barh(names, env, color=PALETTE["ours"], label="environment (+ LQR)")
        ax.barh(names, rest, left=env, color=PALETTE["yardstick"], label="PPO (rollout policy, updates)")
        for y, (e, r) in enumerate(zip(env, rest, strict=True)):
            ax.text(e + r, y, f" {e + r:.1f} s ({e / (e + r):.0%} env)", va="center", fontsize=8)
        ax.set_xlim(0, 1.3 * max(e + r for e, r in zip(env, rest, strict=True)))
        ax.set_xlabel(f"wall time for {rows[0]['timesteps']} steps, same PPO settings (s)")
        ax.set_title("flatbody bench train (same run)")
        c.legend(where="below", ncol=2)
        c.caption(CAPTION, fontsize=7)


def tables(bench: TrainBenchmark) -> list[Table]:
    """The runs and the figures of this run (the terminal's text and the docs' ``train`` block; ``flatbody bench train
    --docs docs/agents.md`` writes it there)."""
    fb, pd = bench.flatbody, bench.pendulum

    def ok(x: float, bound: float) -> str:
        return "met" if x <= bound else "missed"

    return [
        Table(
            columns=[f"same PPO settings, {fb.timesteps} env steps", "wall time (s)", "in the environment (+ LQR)"],
            rows=[
                ["FlatBody-v0 (residual on the LQR)", f"{fb.wall_s:.1f}", f"{fb.env_s:.1f} s ({fb.env_share:.0%})"],
                ["Pendulum-v1", f"{pd.wall_s:.1f}", f"{pd.env_s:.1f} s ({pd.env_share:.0%})"],
            ],
        ),
        Table(
            columns=["figure (same run)", "measured", "target"],
            rows=[
                [
                    "PPO wall time FlatBody-v0 / Pendulum-v1",
                    f"**{bench.ratio_wall:.2f}**",
                    f"≤ 1.0 ({ok(bench.ratio_wall, 1.0)})",
                ],
                [
                    "share of FlatBody's wall time in env + LQR",
                    f"**{bench.flatbody_env_share:.1%}**",
                    f"≤ 15 % ({ok(bench.flatbody_env_share, 0.15)})",
                ],
                [
                    f"LQR action per body-step (batch of {bench.n_envs}, gains stored)",
                    f"{bench.lqr_us_per_body_step:.3f} µs",
                    f"≤ 1 µs ({ok(bench.lqr_us_per_body_step, 1.0)})",
                ],
            ],
        ),
    ]


__all__ = ["TrainBenchmark", "TrainTiming", "lqr_us_per_body_step", "plot", "report", "run", "tables"]
