"""``flatbody bench train --to-goal``: wall time until the residual agent is good, SB3's PPO against rsl_rl's PPO.

Both trainers run one after the other in the same process, each with its default configuration for
``FlatBody-v0`` (SB3: the shipped entry of ``agents/hyperparams/ppo.yml``, 32 envs, gSDE; rsl_rl:
``FlatBody-v0``'s entry of ``agents/hyperparams/rsl-ppo.yml``, the torch vector env), one torch thread, the same training seed. Every
``eval_every`` environment steps (rounded up to whole rollouts/iterations) the current policy, deterministic,
is evaluated on ``episodes`` held-out episodes (seeds ``eval_seed`` …, apart from training and from
``flatbody evaluate``'s) — the time spent evaluating is left out of the wall time. A trainer reaches the goal
at the first evaluation with success ≥ ``success_goal`` and mean final distance ≤ ``distance_goal``, and beats
the LQR at the first with success ≥ ``success_goal`` and a mean final distance below the LQR's on the same
episodes; it stops when it has done both, or at ``max_timesteps``. Writes ``time_to_goal.json``, ``.csv`` (one
row per evaluation) and ``.png`` (success and final distance against wall time; the LQR's final distance on the
same seeds as a line), and the ``<!-- bench:time-to-goal -->`` docs block when asked.
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from flatbody_env.bench.harness import Report, Stopwatch, Table, write_report
from flatbody_env.physics import validation

ENV_ID = "FlatBody-v0"
"""The task both trainers race on (the residual agents of docs/agents.md)."""

TRAINERS = ("sb3-ppo", "rsl-ppo")


@dataclass(frozen=True, kw_only=True)
class Curve:
    """One trainer's evaluations.

    Attributes
    ----------
    trainer : str
        One of :data:`TRAINERS`.
    points : list of (int, float, float, float)
        (timesteps, wall s without the evaluations, success rate, mean final distance) per evaluation.
    goal_s : float or None
        Wall time of the first evaluation at the goal (None: not reached).
    goal_timesteps : int or None
    lqr_s : float or None
        Wall time of the first evaluation that beats the LQR (None: not reached).
    lqr_timesteps : int or None
    """

    trainer: str
    points: list[tuple[int, float, float, float]] = field(default_factory=list)
    goal_s: float | None = None
    goal_timesteps: int | None = None
    lqr_s: float | None = None
    lqr_timesteps: int | None = None


@dataclass(frozen=True, kw_only=True)
class GoalBenchmark:
    """Both curves, the LQR on the same episodes and the settings of the race.

    Attributes
    ----------
    sb3, rsl : Curve
    lqr_final_distance, lqr_success : float
        The LQR's mean final distance and success rate on the evaluation episodes.
    episodes, eval_seed : int
        The evaluation episodes (seeds ``eval_seed`` …).
    success_goal, distance_goal : float
        The goal.
    seed : int
        The training seed.
    """

    sb3: Curve
    rsl: Curve
    lqr_final_distance: float
    lqr_success: float
    episodes: int
    eval_seed: int
    success_goal: float
    distance_goal: float
    seed: int

    @property
    def ratio(self) -> float | None:
        """rsl-ppo's time to the goal / SB3's (None when either missed it)."""
        if self.sb3.goal_s is None or self.rsl.goal_s is None:
            return None
        return self.rsl.goal_s / self.sb3.goal_s

    @property
    def ratio_lqr(self) -> float | None:
        """rsl-ppo's time to beat the LQR / SB3's (None when either did not)."""
        if self.sb3.lqr_s is None or self.rsl.lqr_s is None:
            return None
        return self.rsl.lqr_s / self.sb3.lqr_s


@dataclass(frozen=True)
class _Reached:
    """The two criteria; called after each evaluation with all points so far: true (stop) once both were met."""

    success_goal: float
    distance_goal: float
    lqr_distance: float

    def goal(self, s: float, d: float) -> bool:
        return s >= self.success_goal and d <= self.distance_goal

    def lqr(self, s: float, d: float) -> bool:
        return s >= self.success_goal and d < self.lqr_distance

    def __call__(self, s: float, d: float, points) -> bool:
        return any(self.goal(p[2], p[3]) for p in points) and any(self.lqr(p[2], p[3]) for p in points)


def _summary(records) -> tuple[float, float]:
    return float(np.mean([r["success"] for r in records])), float(np.mean([r["final_distance"] for r in records]))


def _sb3_curve(seed: int, max_timesteps: int, eval_every: int, episodes: int, eval_seed: int, goal) -> Curve:
    from stable_baselines3.common.callbacks import BaseCallback

    from agents.evaluate import run_episodes
    from agents.heuristic import ResidualAction
    from agents.config import load_hyperparams
    from agents.train import train

    hp = load_hyperparams("ppo", ENV_ID)
    base = ResidualAction(
        hp.get("env_kwargs") or {},
        float(hp.get("residual_scale", 1.0)),
        float(hp.get("residual_gate", 0.0)),
        str(hp.get("residual_mode", "additive")),
    )
    points: list[tuple[int, float, float, float]] = []

    class Evaluate(BaseCallback):
        def _on_training_start(self) -> None:
            self.clock, self.next_at, self.done = Stopwatch.started(), eval_every, False

        def _on_step(self) -> bool:
            return not self.done

        def _on_rollout_start(self) -> None:  # the previous rollout's update has run
            if self.num_timesteps >= self.next_at:
                self.next_at += eval_every * (1 + (self.num_timesteps - self.next_at) // eval_every)
                self._evaluate()

        def _on_training_end(self) -> None:  # the last update: evaluated unless it already was
            if not self.done and (not points or points[-1][0] != self.num_timesteps):
                self._evaluate()

        def _evaluate(self) -> None:
            wall = self.clock.seconds
            with self.clock.paused():  # the evaluations are left out of the training's wall time
                vn = self.model.get_vec_normalize_env()

                def policy(obs):
                    o = vn.normalize_obs(obs) if vn is not None else obs
                    return base(obs, self.model.predict(o, deterministic=True)[0])

                s, d = _summary(run_episodes(policy, episodes=episodes, seed=eval_seed, env_id=ENV_ID))
                points.append((int(self.num_timesteps), round(wall, 2), s, d))
                self.done = goal(s, d, points)

    cb = Evaluate()
    with tempfile.TemporaryDirectory() as tmp:
        train(
            "ppo",
            Path(tmp) / "run",
            env_id=ENV_ID,
            seed=seed,
            n_timesteps=max_timesteps,
            checkpoint_freq=0,
            threads=1,
            progress=False,
            extra_callbacks=[cb],
            force=True,
            notes=False,
        )
    return _curve("sb3-ppo", points, goal)


def _rsl_curve(seed: int, max_timesteps: int, eval_every: int, episodes: int, eval_seed: int, goal) -> Curve:
    from agents.evaluate import run_episodes
    from agents.config import load_hyperparams
    from agents.rsl import TorchResidual, live_policy
    from agents.train import train

    hp = load_hyperparams("rsl-ppo", ENV_ID)
    res = TorchResidual(hp["env_kwargs"], float(hp["residual_scale"]), str(hp["residual_mode"]), "cpu")
    points: list[tuple[int, float, float, float]] = []
    next_at = [eval_every]

    last = -(-max_timesteps // (int(hp["n_envs"]) * int(hp["num_steps_per_env"])))

    def callback(runner, row) -> bool:
        if row["timesteps"] < next_at[0] and row["iteration"] < last:  # the last iteration is always evaluated
            return False
        next_at[0] += eval_every * (1 + max(0, row["timesteps"] - next_at[0]) // eval_every)
        s, d = _summary(
            run_episodes(live_policy(runner.alg.actor, res), episodes=episodes, seed=eval_seed, env_id=ENV_ID)
        )
        points.append((int(row["timesteps"]), round(float(row["time_s"]), 2), s, d))
        return goal(s, d, points)

    with tempfile.TemporaryDirectory() as tmp:
        train(
            "rsl-ppo",
            Path(tmp) / "run",
            env_id=ENV_ID,
            seed=seed,
            n_timesteps=max_timesteps,
            checkpoint_freq=0,
            progress=False,
            callback=callback,
        )
    return _curve("rsl-ppo", points, goal)


def _curve(name: str, points, reached) -> Curve:
    hit = next((p for p in points if reached.goal(p[2], p[3])), None)
    lqr = next((p for p in points if reached.lqr(p[2], p[3])), None)
    return Curve(
        trainer=name,
        points=points,
        goal_s=hit[1] if hit else None,
        goal_timesteps=hit[0] if hit else None,
        lqr_s=lqr[1] if lqr else None,
        lqr_timesteps=lqr[0] if lqr else None,
    )


def run(
    *,
    seed: int = 0,
    max_timesteps: int = 3_000_000,
    eval_every: int = 50_000,
    episodes: int = 20,
    eval_seed: int = 50_000,
    success_goal: float = 0.99,
    distance_goal: float = 0.002,
    out_dir: str | Path = ".",
    docs: str | Path | None = None,
) -> GoalBenchmark:
    """Race both trainers to the goal and write the files into ``out_dir`` (module docstring); with ``docs`` (a Markdown
    page) also its ``<!-- bench:time-to-goal -->`` block."""
    from agents.evaluate import run_episodes

    for name, v, low in (
        ("max_timesteps", max_timesteps, 1),
        ("eval_every", eval_every, 1),
        ("episodes", episodes, 1),
        ("seed", seed, 0),
        ("eval_seed", eval_seed, 0),
    ):
        validation.integer(name, v, low=low)
    validation.requirement("success_goal", success_goal, 0.0 <= success_goal <= 1.0, "lie in [0, 1]")
    validation.requirement("distance_goal", distance_goal, distance_goal > 0.0, "be > 0")

    lqr_s, lqr_d = _summary(run_episodes("heuristic", episodes=episodes, seed=eval_seed, env_id=ENV_ID))

    goal = _Reached(success_goal, distance_goal, lqr_d)

    sb3 = _sb3_curve(seed, max_timesteps, eval_every, episodes, eval_seed, goal)
    rsl = _rsl_curve(seed, max_timesteps, eval_every, episodes, eval_seed, goal)
    bench = GoalBenchmark(
        sb3=sb3,
        rsl=rsl,
        lqr_final_distance=lqr_d,
        lqr_success=lqr_s,
        episodes=episodes,
        eval_seed=eval_seed,
        success_goal=success_goal,
        distance_goal=distance_goal,
        seed=seed,
    )
    write_report(report(bench), out_dir, docs=docs)
    return bench


def report(bench: GoalBenchmark) -> Report:
    """``time_to_goal``'s files: the record (with both ratios), one CSV row per evaluation, the chart drawn from the JSON,
    the docs block ``time-to-goal``."""
    return Report(
        name="time_to_goal",
        record={**asdict(bench), "ratio": bench.ratio, "ratio_lqr": bench.ratio_lqr},
        header=["trainer", "timesteps", "wall_s", "success", "final_distance"],
        rows=[
            [c.trainer, t, f"{w:.2f}", f"{s:.3f}", f"{d:.6f}"]
            for c in (bench.sb3, bench.rsl)
            for t, w, s, d in c.points
        ],
        chart=plot,
        chart_from="json",
        tables=tables(bench),
        block="time-to-goal",
    )


CAPTION = (
    "Each point: the policy at that moment (deterministic) on {episodes} held-out episodes (seeds {eval_seed}…); the wall time\n"
    "leaves the evaluations out. Goal: success ≥ {success:.0%} and mean final distance ≤ {distance:g} (dotted); vertical lines: when\n"
    "each trainer reached it and when it first beat the LQR (below the dashed line). sb3-ppo: the shipped\n"
    "SB3 configuration (32 envs, gSDE); rsl-ppo: rsl_rl's PPO with rsl-ppo.yml's FlatBody-v0 entry on the torch vector env. Both: residual\n"
    "on the LQR (linear-quadratic regulator; dashed: its final distance on the same seeds), one torch thread, same process."
)


def load(json_path: str | Path) -> GoalBenchmark:
    """A :class:`GoalBenchmark` from its saved ``time_to_goal.json``."""
    data = validation.read_json("--plot-only", json_path)
    curves = {k: Curve(**{**data[k], "points": [tuple(p) for p in data[k]["points"]]}) for k in ("sb3", "rsl")}
    return GoalBenchmark(
        **{k: v for k, v in data.items() if k not in ("ratio", "ratio_lqr", "machine", "sb3", "rsl")}, **curves
    )


def plot(json_path: Path, png_path: Path) -> None:
    """Final distance and success against wall time, redrawn from the saved ``time_to_goal.json``."""
    from flatbody_env.figures import PALETTE, chart, fraction_axis

    bench = load(json_path)
    with chart(png_path, size=(9.0, 4.9), ncols=2) as c:
        ax_d, ax_s = c.axes[0]
        for cv, colour in zip((bench.sb3, bench.rsl), ("tab:blue", "tab:orange"), strict=True):
            w = [p[1] for p in cv.points]
            ax_d.plot(w, [p[3] for p in cv.points], "o-", ms=3, color=colour, label=cv.trainer)
            ax_s.plot(w, [p[2] for p in cv.points], "o-", ms=3, color=colour)
        ax_d.axhline(bench.lqr_final_distance, color=PALETTE["reference"], ls="--", lw=1, label="LQR")
        ax_d.axhline(bench.distance_goal, color=PALETTE["goal"], ls=":", lw=1, label="goal")
        for cv, colour in zip((bench.sb3, bench.rsl), ("tab:blue", "tab:orange"), strict=True):
            for w in (cv.goal_s, cv.lqr_s):
                if w is not None:
                    ax_d.axvline(w, color=colour, ls=":", lw=0.8)
        ax_s.axhline(bench.success_goal, color=PALETTE["goal"], ls=":", lw=1)
        ax_d.set_yscale("log")
        ax_d.set_xlabel("wall time (s)")
        ax_s.set_xlabel("wall time (s)")
        ax_d.set_ylabel("mean final distance")
        fraction_axis(ax_s, "success rate")
        c.legend(where="below", ncol=4)
        c.title("flatbody bench train --to-goal (same run)")
        c.caption(
            CAPTION.format(
                episodes=bench.episodes,
                eval_seed=bench.eval_seed,
                success=bench.success_goal,
                distance=bench.distance_goal,
            ),
            fontsize=7,
        )


def tables(bench: GoalBenchmark) -> list[Table]:
    """The race of this run (the terminal's text and the docs' ``time-to-goal`` block; ``flatbody bench train --to-goal
    --docs docs/agents.md`` writes it there)."""

    def at(w: float | None, t: int | None) -> str:
        return f"{w:.1f} s ({t} steps)" if w is not None else "not reached"

    def last(c: Curve) -> str:
        t, w, s, d = c.points[-1] if c.points else (0, 0.0, float("nan"), float("nan"))
        return f"{s:.0%} / {d:.4f} after {t} steps, {w:.1f} s"

    def ratio(r: float | None, bound: float | None) -> str:
        if r is None:
            return "— (not reached by both)"
        return f"**{r:.2f}**" + (f" (goal ≤ {bound}: {'met' if r <= bound else 'missed'})" if bound is not None else "")

    rows = [
        [c.trainer, at(c.goal_s, c.goal_timesteps), at(c.lqr_s, c.lqr_timesteps), last(c)]
        for c in (bench.sb3, bench.rsl)
    ]
    rows.append(["rsl-ppo / sb3-ppo wall time", ratio(bench.ratio, 0.5), ratio(bench.ratio_lqr, None), ""])
    return [
        Table(
            columns=[
                f"trainer (seed {bench.seed})",
                "to the goal",
                "to beat the LQR",
                "last evaluation: success / final distance",
            ],
            rows=rows,
            notes=[
                f"Goal: success ≥ {bench.success_goal:.0%} and mean final distance ≤ {bench.distance_goal:g}; beat the "
                f"LQR: success ≥ {bench.success_goal:.0%} and mean final distance below the LQR's "
                f"({bench.lqr_success:.0%} / {bench.lqr_final_distance:.4f}); both on {bench.episodes} held-out "
                f"episodes (seeds {bench.eval_seed}…)."
            ],
        )
    ]


__all__ = ["Curve", "GoalBenchmark", "TRAINERS", "load", "plot", "report", "run", "tables"]
