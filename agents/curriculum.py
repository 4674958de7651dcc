"""A curriculum over one task keyword (``flatbody curriculum``): stage by stage, the training environments are
rebuilt with the next value of the keyword when the training success rate holds.

Used for ``FlatBodySlow-v0`` (docs/agents.md): a curriculum over the settling-rate filter
``min_settling_rate``, from ``FlatBody-v0``'s 0.15/s (where the residual agent already beats the LQR)
down to the task's own 0 (every stable ellipse). The task definition is not changed: the last stage is
the registered task, and the model is evaluated on it.

Mechanics: :func:`curriculum_callback` (an SB3 callback :func:`agents.train.train_config` adds when the run's
configuration has a ``curriculum``) swaps the native batch inside the innermost :class:`agents.vec_env.FlatBodySB3VecEnv`
for one built with the stage's keywords, at the end of a rollout (after the advantages are computed), and
resets the wrapper chain (residual, monitor, VecNormalize: its statistics are kept) so that the next
rollout starts fresh episodes of the new stage. Each stage's environments are seeded ``seed + 7919·(stage + 1)``.
``train_env_kwargs`` (``--train-env-kwargs``) are task keywords of the training environments only (reward
shaping, e.g. ``w_tumble=0``); ``config.yml``'s hyperparameters keep the task's own, which the model is
evaluated on.

A stage ends when at least ``min_steps`` were trained in it and either the success rate of the episodes
finished in the last ``window`` rollouts is ≥ ``advance_at`` or ``max_steps`` were trained in it; the
last stage keeps the remaining budget. The stage of every rollout is logged (``curriculum/stage``,
``curriculum/value`` in progress.csv); the settings are the run's ``prior.curriculum`` in ``config.yml``, with the
stages reached (``history``) added at the end, so that ``flatbody train --config`` trains the same curriculum again.
Checkpoints keep the stage (:meth:`state`), so ``--resume`` continues in it.

    flatbody curriculum --env FlatBodySlow-v0 --out runs/tasks/slow-cur \\
        --key min_settling_rate --stages 0.15,0.1,0.07,0.04,0 --n-timesteps 3000000 [--hyperparams K=V ...]
"""

from __future__ import annotations

import sys
from collections import deque
from typing import Any

import numpy as np


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
    *,
    key: str,
    stages: list[float],
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
            self._restored: dict[str, Any] | None = None

        def state(self) -> dict[str, Any]:
            """What a checkpoint keeps of the curriculum: the stage, the step it began at, the stages so far."""
            return {"stage": self.stage, "stage_start": self.stage_start, "history": list(self.history)}

        def restore(self, state: Any) -> None:
            """Continue from a checkpoint's :meth:`state` (``--resume``): the training starts in that stage."""
            from flatbody_env.physics import validation

            validation.mapping("resume.curriculum", state)
            validation.integer("resume.curriculum.stage", state.get("stage"), low=0, high=len(stages) - 1)
            validation.integer("resume.curriculum.stage_start", state.get("stage_start"), low=0)
            history = state.get("history")
            if not isinstance(history, list):
                validation.requirement("resume.curriculum.history", history, False, "be a list")
            self._restored = dict(state)

        def _switch(self, stage: int, *, resumed: bool = False) -> None:
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
            if resumed:
                self.stage_start = int(self._restored["stage_start"])
                self.history = list(self._restored["history"])
            else:
                self.history.append(
                    {"stage": stage, "value": float(stages[stage]), "from_step": int(self.model.num_timesteps)}
                )
            print(
                f"curriculum: stage {stage} ({key}={stages[stage]}) from step {self.model.num_timesteps}",
                file=sys.stderr,
            )

        def _on_training_start(self) -> None:
            if self._restored is not None:  # the loaded model has its own exploration already
                self._switch(int(self._restored["stage"]), resumed=True)
                return
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
