"""``FlatBodyTorchVectorEnv``: the batched env with torch tensors at its boundary (ManiSkill3 / Isaac Lab style).

Actions, observations, rewards, ``terminated``/``truncated`` and the numeric arrays of ``info`` are torch
tensors on ``device``: float32 observations and actions, float32 rewards, bool ends; the state inside stays
float64. Autoreset is SAME_STEP by default (a body whose episode ends is reset within the step that ended
it, its last observation in ``info["final_obs"]``, rows flagged by ``info["_final_obs"]``), so a trainer
never sees a transition from one episode into the next.

On the CPU (``device="cpu"``) a step *is* :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`'s fused
batch step: the action tensor's memory is handed to it as a numpy array (``Tensor.numpy()``, no copy) and
the arrays it returns are wrapped as tensors (``torch.from_numpy``, no copy). It therefore equals
``FlatBodyVectorEnv`` step for step, bit for bit, for every task of the task suite (tested), with its
episode clocks (``reset(options={"stagger": True})``, :meth:`set_episode_steps`) and partial resets
(``reset(options={"reset_mask": m})``, ``m`` a bool tensor or array).

``device="cuda"`` (one kernel launch per step with the observation, rewards, termination and resets on the
device) is not built yet: it raises :class:`NotImplementedError` naming the CPU device (docs/gpu.md).

Non-numeric infos (``integrator_failure``, ``left_domain``: strings) stay numpy object arrays;
``info["integrator"]["method"]`` stays a str.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv

from flatbody_env.env.registration import MAX_EPISODE_STEPS
from flatbody_env.env.vector_env import FlatBodyVectorEnv


def _to_torch(x: Any) -> Any:
    """Numeric numpy arrays as tensors sharing their memory (dicts recursively); anything else as it is."""
    if isinstance(x, np.ndarray):
        return x if x.dtype == object else torch.from_numpy(x)
    if isinstance(x, dict):
        return {k: _to_torch(v) for k, v in x.items()}
    return x


def _as_numpy(x: Any, dtype=None) -> np.ndarray:
    """A tensor's memory as a numpy array (no copy for a CPU tensor), or ``np.asarray`` of anything else."""
    if isinstance(x, torch.Tensor):
        x = x.detach()
        if x.device.type != "cpu":
            x = x.cpu()
        x = x.numpy()
    return np.asarray(x) if dtype is None else np.asarray(x, dtype=dtype)


class FlatBodyTorchVectorEnv(VectorEnv):
    """N bodies of ``FlatBody-v0`` (or any task of docs/tasks.md) with torch tensors at the boundary.

    Parameters
    ----------
    num_envs : int
    device : str or torch.device
        ``"cpu"`` (module docstring); ``"cuda"`` raises :class:`NotImplementedError` (not built yet).
    max_episode_steps : int
    autoreset_mode : AutoresetMode
        ``SAME_STEP`` (default) or ``NEXT_STEP``.
    num_threads : int or None
        As :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`.
    **env_kwargs
        The keyword arguments of :class:`~flatbody_env.env.env.FlatBodyEnv` (a task's, e.g. ``task="hold-unstable"``).
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, device: str | torch.device = "cpu", max_episode_steps: int = MAX_EPISODE_STEPS,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP, num_threads: int | None = 1, **env_kwargs: Any) -> None:
        try:
            dev = torch.device(device)
        except (RuntimeError, TypeError):
            raise ValueError(f"device: must be 'cpu' or 'cuda', got {device!r}") from None
        if dev.type == "cuda":
            raise NotImplementedError("device: 'cuda' (the step, observation, rewards and resets on the GPU) is not built yet; "
                                      "use device='cpu' (docs/gpu.md)")
        if dev.type != "cpu":
            raise ValueError(f"device: must be 'cpu' or 'cuda', got {device!r}")
        self.device = dev
        """The device of every tensor this env returns."""
        self.venv = FlatBodyVectorEnv(num_envs=num_envs, max_episode_steps=max_episode_steps, autoreset_mode=autoreset_mode,
                                      num_threads=num_threads, **env_kwargs)
        """The batched env that steps the bodies (its arrays are the tensors' memory)."""
        self.metadata = {**self.metadata, "autoreset_mode": self.venv.metadata["autoreset_mode"]}
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.single_observation_space = self.venv.single_observation_space
        self.single_action_space = self.venv.single_action_space
        self.observation_space = self.venv.observation_space
        self.action_space = self.venv.action_space
        self.single_env = self.venv.single_env
        self.body, self.task, self.control, self.limits, self.dt = self.venv.body, self.venv.task, self.venv.control, self.venv.limits, self.venv.dt
        self.reward_names = self.venv.reward_names

    # --- state ---------------------------------------------------------------------------------------------
    @property
    def states(self) -> torch.Tensor:
        """The N packed states (N, 11) float64 (a copy)."""
        return torch.from_numpy(self.venv.states)

    @property
    def target_vectors(self) -> torch.Tensor:
        """The N targets (λ*, μ*, ϱ*, s3*) (N, 4) float64 (a copy)."""
        return torch.from_numpy(self.venv.target_vectors)

    @property
    def episode_steps(self) -> torch.Tensor:
        """Each body's steps into its episode (N,) int64 (a copy)."""
        return torch.from_numpy(self.venv.episode_steps)

    def set_episode_steps(self, steps) -> None:
        """Set each body's episode clock (N,) integers in [0, ``max_episode_steps``) (a tensor or an array)."""
        self.venv.set_episode_steps(_as_numpy(steps))

    # --- VectorEnv API -------------------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        if options and "reset_mask" in options:
            options = {**options, "reset_mask": _as_numpy(options["reset_mask"])}
        obs, info = self.venv.reset(seed=seed, options=options)
        return torch.from_numpy(obs), _to_torch(info)

    def step(self, actions):
        obs, rewards, terminated, truncated, info = self.venv.step(_as_numpy(actions))
        return (torch.from_numpy(obs), torch.from_numpy(rewards.astype(np.float32)), torch.from_numpy(terminated),
                torch.from_numpy(truncated), _to_torch(info))

    def close_extras(self, **kwargs: Any) -> None:
        self.venv.close()


__all__ = ["FlatBodyTorchVectorEnv"]
