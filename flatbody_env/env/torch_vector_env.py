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

``device="cuda"``: one kernel launch per step (:func:`flatbody_env.integrators.cuda.env_step` with ``task=``) with the
controls, the dynamics, the task's observation, reward terms, termination, truncation and autoresets on the GPU
(:mod:`flatbody_env.env.device`); targets and starts are drawn there from a counter-based generator (Philox) per
body, seeded from ``reset(seed=)``: the same distributions as ``FlatBody-v0``, other draws (docs/gpu.md). The state
and every array live in torch CUDA tensors that the kernels read and write in place (``numba.cuda.as_cuda_array``,
no copies); this module is only that glue (:class:`_CudaBatch`), the kernels are tested under numba's CUDA
simulator. Without a GPU (or without numba-cuda or torch's CUDA build) it raises one
:class:`~flatbody_env.integrators.cuda.CudaUnavailableError`. Differences from the CPU device: ``reset(seed=)``
takes one int (no list); the options are ``reset_mask`` and ``stagger`` only; ``info`` carries the integer tensors
``status`` (:data:`flatbody_env.integrators.failure.KINDS`) and ``domain_code`` instead of the strings
``integrator_failure`` and ``left_domain``; ``final_obs`` rows are valid where ``_final_obs``; tasks whose draws or
terms run in Python (witness, any-body, hold-unstable's extra terms, a custom potential) raise ``ValueError``.

Non-numeric infos (``integrator_failure``, ``left_domain``: strings) stay numpy object arrays;
``info["integrator"]["method"]`` stays a str.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv

from flatbody_env.env.registration import MAX_EPISODE_STEPS
from flatbody_env.env.vector_env import FlatBodyVectorEnv, batch_arguments


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
        ``"cpu"`` or ``"cuda"`` (module docstring).
    max_episode_steps : int
    autoreset_mode : AutoresetMode
        ``SAME_STEP`` (default) or ``NEXT_STEP``.
    num_threads : int or None
        As :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`.
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
            raise ValueError(f"device: must be 'cpu' or 'cuda', got {device!r}") from None
        if dev.type not in ("cpu", "cuda"):
            raise ValueError(f"device: must be 'cpu' or 'cuda', got {device!r}")
        self.device = dev
        """The device of every tensor this env returns."""
        self._gpu: _CudaBatch | None = None
        if dev.type == "cuda":
            _cuda_ready()
            self._gpu = _CudaBatch(self, num_envs, dev, max_episode_steps, autoreset_mode, env_kwargs)
            return
        self.venv = FlatBodyVectorEnv(
            num_envs=num_envs,
            max_episode_steps=max_episode_steps,
            autoreset_mode=autoreset_mode,
            num_threads=num_threads,
            **env_kwargs,
        )
        """The batched env that steps the bodies (its arrays are the tensors' memory)."""
        self.metadata = {**self.metadata, "autoreset_mode": self.venv.metadata["autoreset_mode"]}
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.single_observation_space = self.venv.single_observation_space
        self.single_action_space = self.venv.single_action_space
        self.observation_space = self.venv.observation_space
        self.action_space = self.venv.action_space
        self.single_env = self.venv.single_env
        self.body, self.task, self.control, self.limits, self.dt = (
            self.venv.body,
            self.venv.task,
            self.venv.control,
            self.venv.limits,
            self.venv.dt,
        )
        self.reward_names = self.venv.reward_names

    # --- state ---------------------------------------------------------------------------------------------
    @property
    def states(self) -> torch.Tensor:
        """The N packed states (N, 11) float64 (a copy)."""
        if self._gpu is not None:
            return self._gpu.t["Y"].T.clone()
        return torch.from_numpy(self.venv.states)

    @property
    def target_vectors(self) -> torch.Tensor:
        """The N targets (λ*, μ*, ϱ*, s3*) (N, 4) float64 (a copy)."""
        if self._gpu is not None:
            return self._gpu.t["T"].T.clone()
        return torch.from_numpy(self.venv.target_vectors)

    @property
    def episode_steps(self) -> torch.Tensor:
        """Each body's steps into its episode (N,) int64 (a copy)."""
        if self._gpu is not None:
            return self._gpu.t["I"][0].clone()
        return torch.from_numpy(self.venv.episode_steps)

    def set_episode_steps(self, steps) -> None:
        """Set each body's episode clock (N,) integers in [0, ``max_episode_steps``) (a tensor or an array)."""
        if self._gpu is not None:
            self._gpu.set_episode_steps(steps)
            return
        self.venv.set_episode_steps(_as_numpy(steps))

    # --- VectorEnv API -------------------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        if self._gpu is not None:
            return self._gpu.reset(seed, options)
        if options and "reset_mask" in options:
            options = {**options, "reset_mask": _as_numpy(options["reset_mask"])}
        obs, info = self.venv.reset(seed=seed, options=options)
        return torch.from_numpy(obs), _to_torch(info)

    def step(self, actions):
        if self._gpu is not None:
            return self._gpu.step(actions)
        obs, rewards, terminated, truncated, info = self.venv.step(_as_numpy(actions))
        return (
            torch.from_numpy(obs),
            torch.from_numpy(rewards.astype(np.float32)),
            torch.from_numpy(terminated),
            torch.from_numpy(truncated),
            _to_torch(info),
        )

    def close_extras(self, **kwargs: Any) -> None:
        if self._gpu is None:
            self.venv.close()


def _cuda_ready() -> None:
    """One :class:`~flatbody_env.integrators.cuda.CudaUnavailableError` when the CUDA device cannot run here."""
    from flatbody_env.integrators import cuda

    if not torch.cuda.is_available():
        raise cuda.CudaUnavailableError(
            f"device: 'cuda' needs a CUDA GPU and torch's CUDA build (torch.cuda.is_available() is False); "
            f"use device='cpu', or {cuda.INSTALL_HINT}"
        )
    cuda.require()


_TORCH_DTYPES = {
    np.dtype(np.float64): torch.float64,
    np.dtype(np.float32): torch.float32,
    np.dtype(np.int64): torch.int64,
    np.dtype(np.uint8): torch.uint8,
}


class _CudaBatch:
    """The torch side of ``device="cuda"``: a :class:`~flatbody_env.env.device.DeviceBatch` whose arrays are torch CUDA tensors,
    handed to the kernels as numba views of the same memory (``numba.cuda.as_cuda_array``, zero-copy). Needs a real GPU
    (tests marked ``gpu``); the kernels themselves are tested under numba's CUDA simulator."""

    NAMES = ("Y", "T", "OBS", "FINAL", "INFO", "I", "ENDS", "FLAGS")

    def __init__(
        self, env: FlatBodyTorchVectorEnv, num_envs, dev, max_episode_steps, autoreset_mode, env_kwargs
    ) -> None:
        from gymnasium.vector.utils import batch_space

        from flatbody_env.env.device import DeviceBatch
        from flatbody_env.env.env import FlatBodyEnv
        from flatbody_env.integrators import cuda

        num_envs, max_episode_steps, mode = batch_arguments(num_envs, max_episode_steps, autoreset_mode)
        if env_kwargs.get("render_mode") is not None or env_kwargs.get("track_rotation"):
            raise ValueError("render_mode: FlatBodyTorchVectorEnv does not render; use FlatBody-v0 for frames")
        self.cuda, self.dev = cuda, dev
        p = FlatBodyEnv(**env_kwargs)
        self.p = p
        keep: list[torch.Tensor] = []

        def alloc(shape, dtype):
            t = torch.zeros(shape, dtype=_TORCH_DTYPES[np.dtype(dtype)], device=dev)
            keep.append(t)
            return cuda.cuda.as_cuda_array(t)

        with torch.cuda.device(dev):
            self.batch = DeviceBatch(
                p, num_envs, max_episode_steps, same_step=mode == AutoresetMode.SAME_STEP, backend="cuda", alloc=alloc
            )
        self._keep = keep
        self.t = {name: torch.as_tensor(getattr(self.batch, name), device=dev) for name in self.NAMES}
        """The batch's arrays as torch tensors (the same memory)."""
        env.metadata = {**env.metadata, "autoreset_mode": mode}
        env.num_envs, env.max_episode_steps = num_envs, max_episode_steps
        env.single_observation_space, env.single_action_space = p.observation_space, p.action_space
        env.observation_space, env.action_space = (
            batch_space(p.observation_space, num_envs),
            batch_space(p.action_space, num_envs),
        )
        env.single_env, env.venv = p, None
        env.body, env.task, env.control, env.limits, env.dt = p.body, p.task, p.control, p.limits, p.dt
        env.reward_names = p.reward_names
        self.reward_names = p.reward_names

    def _info(self, *, t, terms: bool) -> dict:
        INFO, I = self.t["INFO"], self.t["I"]
        info = {
            "distance": INFO[7].clone(),
            "is_success": INFO[7] <= self.p.task.success_tolerance,
            "energy": INFO[8].clone(),
            "casimir": INFO[9].clone(),
            "p_theta": self.t["Y"][3].clone(),
            "t": t,
            "integrator": {"method": self.batch.method, "nfev": I[3].clone()},
            "status": I[2].clone(),
            "domain_code": INFO[10].to(torch.int64),
        }
        if terms:
            info["reward_terms"] = {name: INFO[1 + k].clone() for k, name in enumerate(self.reward_names)}
        return info

    def _mask(self, mask):
        m = torch.as_tensor(mask, device=self.dev)
        if tuple(m.shape) != (self.batch.num_envs,) or m.dtype != torch.bool:
            raise ValueError(f"options.reset_mask: must be a bool array of shape ({self.batch.num_envs},)")
        return m

    def reset(self, seed, options):
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        stagger = bool(options.pop("stagger", False))
        if options:
            raise ValueError(
                f"options.{sorted(options)[0]}: not supported on device='cuda' (reset_mask and stagger are)"
            )
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise ValueError(
                f"seed: device='cuda' takes one int >= 0 (the bodies' generators are counters under one key), got {seed!r}"
            )
        m = None if mask is None else self._mask(mask)
        view = None if m is None else self.cuda.cuda.as_cuda_array(m.to(torch.uint8).contiguous())
        self.batch.reset(seed=seed, mask=view, stagger=stagger)
        info = self._info(t=self.t["I"][0] * self.p.dt, terms=False)
        return self.t["OBS"].clone(), info

    def step(self, actions):
        A = torch.as_tensor(actions, device=self.dev)
        if A.dtype not in (torch.float32, torch.float64):
            A = A.to(torch.float32)
        A = A.reshape((self.batch.num_envs,) + self.p.action_space.shape).contiguous()
        self.batch.step(self.cuda.cuda.as_cuda_array(A))
        t, ENDS, INFO = self.t, self.t["ENDS"], self.t["INFO"]
        terminated, truncated = ENDS[0].bool(), ENDS[1].bool()
        info = self._info(t=INFO[11].clone(), terms=True)
        if self.batch.same_step:
            done = terminated | truncated
            info["final_obs"] = t["FINAL"].clone()
            info["_final_obs"] = done
        return t["OBS"].clone(), INFO[0].to(torch.float32), terminated, truncated, info

    def set_episode_steps(self, steps) -> None:
        s = torch.as_tensor(steps, device=self.dev)
        n, top = self.batch.num_envs, self.batch.max_episode_steps
        if (
            tuple(s.shape) != (n,)
            or s.dtype.is_floating_point
            or s.dtype == torch.bool
            or bool((s < 0).any())
            or bool((s >= top).any())
        ):
            raise ValueError(f"steps: must be {n} integers in [0, {top})")
        self.t["I"][0].copy_(s)


__all__ = ["FlatBodyTorchVectorEnv"]
