"""``FlatBodyTorchVectorEnv``: the batched env with torch tensors at its boundary (ManiSkill3 / Isaac Lab style).

Actions, observations, rewards, ``terminated``/``truncated`` and the numeric entries of ``info`` are torch tensors on
``device``: float32 observations, float32 rewards, bool ends; the state inside stays float64. Autoreset is SAME_STEP
by default (a body whose episode ends is reset within the step that ended it, its last observation in
``info["final_obs"]``, rows flagged by ``info["_final_obs"]``), so a trainer never sees a transition from one episode
into the next. It runs every id of docs/tasks.md on the CPU and every v1 id on CUDA, from the one transition
(:mod:`flatbody_env.env.transition`):

* ``device="cpu"``: Gymnasium's ``NumpyToTorch`` over :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` —
  the action tensor's memory handed to it as a numpy array (no copy), its arrays wrapped as tensors (no copy). It
  equals ``FlatBodyVectorEnv`` step for step, bit for bit.
* ``device="cuda"``: one kernel launch per step (:func:`~flatbody_env.env.transition.step_body`, one thread per
  body) on arrays that are torch CUDA tensors (``numba.cuda.as_cuda_array``, no copies); the same draws for a seed as
  the CPU (counter-based, per body), the same ``info`` schema (:func:`~flatbody_env.env.vector_env.episode_info` on
  tensors). Without a GPU (or without numba-cuda or torch's CUDA build) it raises one
  :class:`~flatbody_env.integrators.cuda.CudaUnavailableError`. Tested under numba's CUDA simulator.

The contract on both devices: actions of exactly shape (N, n) and a real floating dtype (float16, bfloat16, float32,
float64; anything else is refused naming ``actions``), finite, clipped to [−1, 1]; ``reset`` before ``step``; after
``close()`` every call is refused; ``options`` booleans are booleans.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from flatbody_env.env import transition as tr
from flatbody_env.env.core import EnvCore, configure
from flatbody_env.env.registration import MAX_EPISODE_STEPS
from flatbody_env.env.vector_env import FlatBodyVectorEnv, batch_arguments, episode_info, seed_list
from flatbody_env.physics import validation

_FLOATS = (torch.float16, torch.bfloat16, torch.float32, torch.float64)
MAX_DEVICE_BATCH = 1 << 22
"""Largest ``num_envs`` on CUDA (4,194,304 bodies: ≈ 2.5 GB of arrays)."""


def _to_torch(x: Any) -> Any:
    """Numeric numpy arrays as tensors sharing their memory (dicts recursively); anything else as it is."""
    if isinstance(x, np.ndarray):
        return x if x.dtype == object else torch.from_numpy(x)
    if isinstance(x, np.generic):
        return torch.as_tensor(x)
    if isinstance(x, dict):
        return {k: _to_torch(v) for k, v in x.items()}
    return x


class FlatBodyTorchVectorEnv(VectorEnv):
    """N bodies of any id of docs/tasks.md with torch tensors at the boundary (module docstring).

    Parameters
    ----------
    num_envs : int
    device : str or torch.device
        ``"cpu"`` or ``"cuda"`` (module docstring).
    max_episode_steps : int
    autoreset_mode : AutoresetMode
        ``SAME_STEP`` (default) or ``NEXT_STEP``.
    num_threads : int or None
        As :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` (CPU only).
    **env_kwargs
        The keyword arguments of :class:`~flatbody_env.env.env.FlatBodyEnv` (a task's, e.g. ``task="hold-unstable"``).
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        device: str | torch.device = "cpu",
        max_episode_steps: int = MAX_EPISODE_STEPS,
        autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
        num_threads: int | None = 1,
        **env_kwargs: Any,
    ) -> None:
        try:
            dev = torch.device(device)
        except (RuntimeError, TypeError):
            dev = None  # not a device at all: refused below, without torch's error as context
        validation.requirement("device", device, dev is not None and dev.type in ("cpu", "cuda"), "be 'cpu' or 'cuda'")
        self.device = dev
        """The device of every tensor this env returns."""
        self._closed = False
        self._started = False
        if dev.type == "cuda":
            self._gpu = _CudaBatch(self, num_envs, dev, max_episode_steps, autoreset_mode, env_kwargs)
            self.venv = None
            return
        self._gpu = None
        self.venv = FlatBodyVectorEnv(
            num_envs=num_envs,
            max_episode_steps=max_episode_steps,
            autoreset_mode=autoreset_mode,
            num_threads=num_threads,
            **env_kwargs,
        )
        """The batched env that steps the bodies (its arrays are the tensors' memory)."""
        self.config = self.venv.config
        self.metadata = {**self.metadata, "autoreset_mode": self.venv.metadata["autoreset_mode"]}
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.single_observation_space = self.venv.single_observation_space
        self.single_action_space = self.venv.single_action_space
        self.observation_space = self.venv.observation_space
        self.action_space = self.venv.action_space
        self.reward_names = self.venv.reward_names

    body = property(lambda self: self.config.body)
    task = property(lambda self: self.config.task)
    control = property(lambda self: self.config.control)
    limits = property(lambda self: self.config.limits)
    dt = property(lambda self: self.config.dt)

    def _open(self) -> None:
        if self._closed:
            raise RuntimeError("FlatBodyTorchVectorEnv: the env is closed")

    # --- state ---------------------------------------------------------------------------------------------
    @property
    def states(self) -> torch.Tensor:
        """The N packed states (N, 11) float64 (a copy)."""
        self._open()
        if self._gpu is not None:
            return self._gpu.t["S"][tr.Y0 : tr.Y0 + 11].T.clone()
        return torch.from_numpy(self.venv.states)

    @property
    def target_vectors(self) -> torch.Tensor:
        """The N targets (λ*, μ*, ϱ*, s3*) (N, 4) float64 (a copy)."""
        self._open()
        if self._gpu is not None:
            return self._gpu.t["S"][tr.TG0 : tr.TG0 + 4].T.clone()
        return torch.from_numpy(self.venv.target_vectors)

    @property
    def observations(self) -> torch.Tensor:
        """The N current observations (N, d) (a copy; :attr:`FlatBodyVectorEnv.observations`)."""
        self._open()
        if self._gpu is not None:
            return self._gpu.t["OBS"].clone()
        return torch.from_numpy(self.venv.observations)

    @property
    def episode_steps(self) -> torch.Tensor:
        """Each body's steps into its episode (N,) int64 (a copy)."""
        self._open()
        if self._gpu is not None:
            return self._gpu.t["K"][tr.K_CLOCK].clone()
        return torch.from_numpy(self.venv.episode_steps)

    def set_episode_steps(self, steps) -> None:
        """Set each body's episode clock (N,) integers in [0, ``max_episode_steps``) (a tensor or an array)."""
        self._open()
        s = torch.as_tensor(steps)
        n, top = self.num_envs, self.max_episode_steps
        if (
            tuple(s.shape) != (n,)
            or s.dtype.is_floating_point
            or s.dtype.is_complex
            or s.dtype == torch.bool
            or bool((s < 0).any())
            or bool((s >= top).any())
        ):
            raise validation.refusal("steps", f"be {n} integers in [0, {top})")
        if self._gpu is not None:
            self._gpu.t["K"][tr.K_CLOCK].copy_(s.to(self.device))
            t = self._gpu.core.observed_time(s.to(self.device, torch.float64))
            if t is not None:  # the observed time, as a step would have written it
                self._gpu.t["OBS"][:, -1] = t
        else:
            self.venv.set_episode_steps(s.cpu().numpy())

    # --- VectorEnv API -------------------------------------------------------------------------------------
    def _actions(self, actions) -> torch.Tensor:
        """``actions`` as a tensor of exactly (N, n) with a real floating dtype (module docstring), or ValueError."""
        shape = (self.num_envs, *self.single_action_space.shape)
        try:
            a = torch.as_tensor(actions)
        except (TypeError, ValueError, RuntimeError, OverflowError):
            raise validation.refusal(
                "actions", f"be a tensor of shape {shape} with a real floating dtype", actions
            ) from None
        if tuple(a.shape) != shape:
            raise ValueError(f"actions: must have shape {shape}, got {tuple(a.shape)}")
        if a.dtype not in _FLOATS:
            raise ValueError(
                f"actions: must have a real floating dtype (float16, bfloat16, float32, float64), got {a.dtype}"
            )
        return a

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        self._open()
        options = {} if options is None else dict(validation.mapping("options", options))
        if "stagger" in options:
            validation.boolean("options.stagger", options["stagger"])
        if "reset_mask" in options:
            m = torch.as_tensor(options["reset_mask"])
            if tuple(m.shape) != (self.num_envs,) or m.dtype != torch.bool:
                raise validation.refusal("options.reset_mask", f"be a bool array of shape ({self.num_envs},)")
            options["reset_mask"] = m
        self._started = True
        if self._gpu is not None:
            return self._gpu.reset(seed, options)
        if "reset_mask" in options:
            options["reset_mask"] = options["reset_mask"].cpu().numpy()
        obs, info = self.venv.reset(seed=seed, options=options or None)
        return torch.from_numpy(obs), _to_torch(info)

    def step(self, actions):
        self._open()
        if not self._started:
            raise RuntimeError("FlatBodyTorchVectorEnv: call reset() before step()")
        a = self._actions(actions)
        if self._gpu is not None:
            return self._gpu.step(a)
        a = a.detach().cpu()
        if a.dtype not in (torch.float32, torch.float64):
            a = a.to(torch.float64)
        obs, rewards, terminated, truncated, info = self.venv.step(a.numpy())
        return (
            torch.from_numpy(obs),
            torch.from_numpy(rewards.astype(np.float32)),
            torch.from_numpy(terminated),
            torch.from_numpy(truncated),
            _to_torch(info),
        )

    def close_extras(self, **kwargs: Any) -> None:
        if self.venv is not None and not self._closed:
            self.venv.close()
        self._closed = True


_TORCH_DTYPES = {
    np.dtype(np.float64): torch.float64,
    np.dtype(np.float32): torch.float32,
    np.dtype(np.int64): torch.int64,
    np.dtype(np.uint8): torch.uint8,
}


class _CudaBatch:
    """The torch side of ``device="cuda"``: an :class:`~flatbody_env.env.core.EnvCore` on CUDA whose arrays are torch
    CUDA tensors, handed to the kernels as numba views of the same memory (``numba.cuda.as_cuda_array``, zero-copy).
    Needs a real GPU (tests marked ``gpu``); the kernels are tested under numba's CUDA simulator."""

    NAMES = ("S", "K", "OBS", "FINAL", "FLAGS")

    def __init__(
        self, env: FlatBodyTorchVectorEnv, num_envs, dev, max_episode_steps, autoreset_mode, env_kwargs
    ) -> None:
        from flatbody_env.integrators import cuda

        num_envs, max_episode_steps, mode = batch_arguments(
            num_envs, max_episode_steps, autoreset_mode, max_batch=MAX_DEVICE_BATCH
        )
        if env_kwargs.get("render_mode") is not None or env_kwargs.get("track_rotation"):
            raise ValueError("render_mode: FlatBodyTorchVectorEnv does not render; use FlatBody-v1 for frames")
        config = configure(**env_kwargs)
        if not torch.cuda.is_available():
            raise cuda.CudaUnavailableError(
                "device: 'cuda' needs a CUDA GPU and torch's CUDA build (torch.cuda.is_available() is False); "
                f"use device='cpu', or {cuda.INSTALL_HINT}"
            )
        cuda.require()
        self.cuda, self.dev = cuda, dev
        keep: list[torch.Tensor] = []

        def alloc(shape, dtype):
            t = torch.zeros(shape, dtype=_TORCH_DTYPES[np.dtype(dtype)], device=dev)
            keep.append(t)
            return cuda.cuda.as_cuda_array(t)

        with torch.cuda.device(dev):
            reset = "same" if mode == AutoresetMode.SAME_STEP else "next"
            self.core = EnvCore(
                config, num_envs, max_episode_steps=max_episode_steps, autoreset=reset, backend="cuda", alloc=alloc
            )
        self._keep = keep
        self.t = {name: torch.as_tensor(getattr(self.core, name), device=dev) for name in self.NAMES}
        """The core's arrays as torch tensors (the same memory)."""
        self.config = config
        env.config = config
        env.metadata = {**env.metadata, "autoreset_mode": mode}
        env.num_envs, env.max_episode_steps = num_envs, max_episode_steps
        env.single_observation_space, env.single_action_space = config.observation_space, config.action_space
        env.observation_space = batch_space(config.observation_space, num_envs)
        env.action_space = batch_space(config.action_space, num_envs)
        env.reward_names = config.reward_names

    def _info(self, *, step: bool) -> dict:
        c = self.config
        return episode_info(
            self.t["S"],
            self.t["K"],
            dt=c.dt,
            tol=c.task.success_tolerance,
            method=c.stepper.method,
            names=c.reward_names,
            step=step,
            xp=torch,
        )

    def reset(self, seed, options):
        options = dict(options)
        mask = options.pop("reset_mask", None)
        stagger = bool(options.pop("stagger", False))
        if options:
            raise ValueError(
                f"options.{sorted(options)[0]}: not supported on device='cuda' (reset_mask and stagger are)"
            )
        n = self.core.num_envs
        m = np.ones(n, dtype=bool) if mask is None else mask.cpu().numpy()
        self.core.reset(seeds=seed_list(seed, n), mask=m, stagger=stagger)
        return self.t["OBS"].clone(), self._info(step=False)

    def step(self, actions):
        A = actions.to(self.dev)
        if A.dtype not in (torch.float32, torch.float64):
            A = A.to(torch.float32)
        A = A.contiguous()
        self.core.step(self.cuda.cuda.as_cuda_array(A))
        K = self.t["K"]
        terminated, truncated = K[tr.K_TERMINATED] != 0, K[tr.K_TRUNCATED] != 0
        info = self._info(step=True)
        if self.core.autoreset == "same":
            info["final_obs"] = self.t["FINAL"].clone()
            info["_final_obs"] = terminated | truncated
        return self.t["OBS"].clone(), self.t["S"][tr.R_REWARD].to(torch.float32), terminated, truncated, info


__all__ = ["FlatBodyTorchVectorEnv", "MAX_DEVICE_BATCH"]
