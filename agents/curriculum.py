"""A curriculum over one task keyword for ``flatbody train`` (PPO): stage by stage, the environments are
rebuilt with the next value of the keyword when the training success rate holds.

Used for ``FlatBodySlow-v0`` (docs/agents.md): a curriculum over the settling-rate filter
``min_settling_rate``, from ``FlatBody-v0``'s 0.15/s (where the residual agent already beats the LQR)
down to the task's own 0 (every stable ellipse). The task definition is not changed: the last stage is
the registered task, and the model is evaluated on it.

Mechanics: :class:`CurriculumCallback` (an SB3 callback given to :func:`agents.train.train` through
``extra_callbacks``) swaps the native batch inside the innermost :class:`agents.vec_env.FlatBodySB3VecEnv`
for one built with the stage's keywords, at the end of a rollout (after the advantages are computed), and
resets the wrapper chain (residual, monitor, VecNormalize: its statistics are kept) so that the next
rollout starts fresh episodes of the new stage. Each stage's environments are seeded ``seed + 7919·(stage + 1)``.
``train_env_kwargs`` (``--train-env-kwargs``) are task keywords of the training environments only (reward
shaping, e.g. ``w_tumble=0``); ``config.yml``'s hyperparameters keep the task's own, which the model is
evaluated on.

A stage ends when at least ``min_steps`` were trained in it and either the success rate of the episodes
finished in the last ``window`` rollouts is ≥ ``advance_at`` or ``max_steps`` were trained in it; the
last stage keeps the remaining budget. The stage of every rollout is logged (``curriculum/stage``,
``curriculum/value`` in progress.csv) and the schedule is added to ``config.yml`` (``curriculum``; the
hyperparameters are those of the run, without the curriculum).

    python -m agents.curriculum --env FlatBodySlow-v0 --out runs/tasks/slow-cur \\
        --key min_settling_rate --stages 0.15,0.1,0.07,0.04,0 --n-timesteps 3000000 [--hyperparams K=V ...]
"""

from __future__ import annotations

import argparse
import sys
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flatbody_env.output import atomic_write


def _inner(venv):
    """The innermost :class:`agents.vec_env.FlatBodySB3VecEnv` of a wrapper chain."""
    from agents.vec_env import FlatBodySB3VecEnv

    v = venv
    while not isinstance(v, FlatBodySB3VecEnv):
        v = getattr(v, "venv", None)
        if v is None:
            raise ValueError("curriculum: no FlatBodySB3VecEnv inside the training environment")
    return v


def curriculum_callback(
    env_id: str,
    key: str,
    stages: list[float],
    *,
    seed: int,
    env_kwargs: dict[str, Any] | None = None,
    advance_at: float = 0.8,
    min_steps: int = 100_000,
    max_steps: int = 500_000,
    window: int = 2,
    train_env_kwargs: dict[str, Any] | None = None,
    log_std_per_action: list[float] | None = None,
):
    from gymnasium.vector import AutoresetMode
    from stable_baselines3.common.callbacks import BaseCallback

    from agents.evaluate import env_kwargs_for
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    class CurriculumCallback(BaseCallback):
        """The curriculum of the module docstring."""

        def __init__(self) -> None:
            super().__init__()
            self.stage = -1
            self.stage_start = 0
            self.recent: deque[list[bool]] = deque(maxlen=window)
            self.current: list[bool] = []
            self.history: list[dict[str, Any]] = []

        def _switch(self, stage: int) -> None:
            inner = _inner(self.training_env)
            kw = env_kwargs_for(env_id, {**(env_kwargs or {}), **(train_env_kwargs or {}), key: stages[stage]})
            old = inner.venv
            inner.venv = FlatBodyVectorEnv(num_envs=inner.num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **kw)
            old.close()
            inner._seed = seed + 7919 * (stage + 1)
            self.model._last_obs = self.training_env.reset()
            self.model._last_episode_starts = np.ones((inner.num_envs,), dtype=bool)
            self.stage, self.stage_start = stage, int(self.model.num_timesteps)
            self.recent.clear()
            self.current = []
            self.history.append(
                {"stage": stage, "value": float(stages[stage]), "from_step": int(self.model.num_timesteps)}
            )
            print(
                f"curriculum: stage {stage} ({key}={stages[stage]}) from step {self.model.num_timesteps}",
                file=sys.stderr,
            )

        def _on_training_start(self) -> None:
            if log_std_per_action:  # exploration per action component (gSDE: columns of the log_std matrix)
                import torch

                with torch.no_grad():
                    ls = self.model.policy.log_std
                    ls[..., :] = torch.as_tensor(log_std_per_action, dtype=ls.dtype)
            self._switch(0)

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"]):
                if done:
                    self.current.append(bool(info.get("is_success")))
            return True

        def _on_rollout_end(self) -> None:
            self.recent.append(self.current)
            self.current = []
            eps = [s for r in self.recent for s in r]
            rate = float(np.mean(eps)) if eps else 0.0
            self.logger.record("curriculum/stage", self.stage)
            self.logger.record("curriculum/value", float(stages[self.stage]))
            self.logger.record("curriculum/success", rate)
            trained = int(self.model.num_timesteps) - self.stage_start
            if (
                self.stage < len(stages) - 1
                and trained >= min_steps
                and ((len(self.recent) == window and rate >= advance_at) or trained >= max_steps)
            ):
                self.history[-1]["success_at_end"] = rate
                self._switch(self.stage + 1)

    return CurriculumCallback()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.curriculum", description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--key", default="min_settling_rate")
    ap.add_argument("--stages", required=True, help="comma-separated values of the keyword, the last the task's own")
    ap.add_argument("--advance-at", type=float, default=0.8)
    ap.add_argument("--min-stage-steps", type=int, default=100_000)
    ap.add_argument("--max-stage-steps", type=int, default=500_000)
    ap.add_argument("--window", type=int, default=2, help="rollouts whose finished episodes decide the success rate")
    ap.add_argument(
        "--train-env-kwargs",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="task keywords of the training environments only (reward shaping, e.g. w_tumble=0); "
        "the model is evaluated on the task's own",
    )
    ap.add_argument(
        "--log-std-per-action",
        help="comma-separated initial log std of each action component "
        "(overrides policy_kwargs.log_std_init per component)",
    )
    ap.add_argument("--n-timesteps", type=int)
    ap.add_argument("--hyperparams", nargs="*", default=[])
    ap.add_argument("--force", action="store_true")
    ap.add_argument(
        "--trained-agent", metavar="RUN", help="fine-tune this run's model (flatbody train --trained-agent)"
    )
    ap.add_argument(
        "--trust",
        action="store_true",
        help="allow unpickling --trained-agent from outside the shipped agent and your own runs (docs/reliability.md)",
    )
    args = ap.parse_args(argv)
    from agents.numpy_policy import trust_policy

    try:
        with trust_policy(not args.trust):  # pickles only from trusted folders, as flatbody's commands
            return _main(args, argv)
    except ValueError as exc:
        print(f"python -m agents.curriculum: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


def _main(args, argv) -> int:
    from agents.train import train
    from flatbody_env.physics import validation

    stages = [float(s) for s in args.stages.split(",")]
    from agents.train import apply_overrides, load_hyperparams

    hp = apply_overrides(load_hyperparams("ppo", args.env), args.hyperparams)
    per_action = [float(x) for x in args.log_std_per_action.split(",")] if args.log_std_per_action else None
    train_kw = {
        k: validation.parse_yaml(f"train_env_kwargs.{k[:60]}", v)
        for k, v in (item.split("=", 1) for item in args.train_env_kwargs)
    }
    cb = curriculum_callback(
        args.env,
        args.key,
        stages,
        seed=args.seed,
        env_kwargs=hp.get("env_kwargs"),
        advance_at=args.advance_at,
        min_steps=args.min_stage_steps,
        max_steps=args.max_stage_steps,
        window=args.window,
        train_env_kwargs=train_kw,
        log_std_per_action=per_action,
    )
    command = ["python", "-m", "agents.curriculum", *(argv if argv is not None else sys.argv[1:])]
    res = train(
        "ppo",
        args.out,
        seed=args.seed,
        n_timesteps=args.n_timesteps,
        overrides=args.hyperparams,
        env_id=args.env,
        progress=False,
        command=command,
        extra_callbacks=[cb],
        force=args.force,
        checkpoint_freq=0,
        trained_agent=args.trained_agent,
    )
    from agents.numpy_policy import read_run_config

    cfg_file = Path(res.out) / "config.yml"
    cfg = read_run_config(res.out)  # the one reading door
    cfg["curriculum"] = {
        "key": args.key,
        "stages": stages,
        "advance_at": args.advance_at,
        "min_stage_steps": args.min_stage_steps,
        "max_stage_steps": args.max_stage_steps,
        "window": args.window,
        "train_env_kwargs": train_kw,
        "log_std_per_action": per_action,
        "history": cb.history,
    }
    atomic_write(cfg_file, yaml.safe_dump(cfg, sort_keys=False))
    print(f"trained {res.timesteps} steps in {res.wall_time_s:.0f} s; stages: {cb.history}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
